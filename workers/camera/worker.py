"""The camera worker: grabs a JPEG from the cell's Axis camera on request.

The JPEG goes back unchanged as the reply's payload (encoding image/jpeg),
described by a CaptureInfo in the attachment. A camera failure is answered
as an error naming the camera and the reason.
"""

from __future__ import annotations

import asyncio
import logging
import time

from wire import keys
from wire.config import CellConfig
from wire.errors import CameraError
from wire.messages import CaptureInfo
from wire.transport import Request, RequestError, Response, Transport

from .axis import AxisCamera
from wire.process import open_transport, run_until_stopped

__all__ = ["serve_camera", "main"]

log = logging.getLogger(__name__)


def serve_camera(transport: Transport, config: CellConfig, camera: AxisCamera) -> None:
    width, height = config.camera.resolution
    lock = asyncio.Lock()  # one camera: one snapshot at a time

    async def on_capture(request: Request) -> Response:
        async with lock:
            began = time.monotonic()
            try:
                jpeg = await camera.snapshot()
            except CameraError as exc:
                raise RequestError(str(exc)) from None
        info = CaptureInfo(width=width, height=height, source=camera.source, time=time.time(),
                           duration_s=time.monotonic() - began)
        return Response(jpeg, encoding="image/jpeg", attachment=info.model_dump_json())

    transport.serve(keys.camera_capture(config.cell_id), on_capture)


def main(config: CellConfig) -> int:
    settings = config.camera

    async def run(stop: asyncio.Event) -> None:
        camera = AxisCamera.from_config(settings)  # a bad setting is named before anything connects
        transport = await open_transport(config)
        try:
            async with camera:
                serve_camera(transport, config, camera)
                transport.declare_token(keys.alive(config.cell_id, "camera"))
                log.info("camera worker of cell %s ready: %s", config.cell_id, camera.source)
                await stop.wait()
        finally:
            await transport.close()

    return run_until_stopped(run, "camera worker")
