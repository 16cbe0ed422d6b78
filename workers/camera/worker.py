"""The camera worker: takes a picture with the cell's camera on request.

The picture goes back unchanged as the reply's payload, with its encoding,
described by a CaptureInfo in the attachment (its real width and height). A
camera failure is answered as an error naming the camera and the reason.
"""

from __future__ import annotations

import asyncio
import logging
import time

from robocell.wire import keys
from robocell.wire.backends import load_backend
from robocell.wire.config import CellConfig
from robocell.wire.messages import CaptureInfo
from robocell.wire.process import open_transport, run_until_stopped
from robocell.wire.transport import BaseTransport, Request, Response

from .backend import Camera

__all__ = ["make_camera", "serve_camera", "main"]

log = logging.getLogger(__name__)


def make_camera(config: CellConfig, transport: BaseTransport) -> Camera:
    """The camera the ``[camera]`` section names (``wire.backends.BACKENDS``), not yet opened.

    Raises
    ------
    ConfigError
        If a setting cannot be used (a CA bundle that cannot be read, a user without a password).
    """
    return load_backend("camera", config.camera.backend)(config, transport)


def serve_camera(transport: BaseTransport, config: CellConfig, camera: Camera) -> None:
    lock = asyncio.Lock()  # one camera: one snapshot at a time

    async def on_capture(request: Request) -> Response:
        async with lock:
            began = time.monotonic()
            picture = await camera.snapshot()  # a CameraError goes back with its kind
        info = CaptureInfo(encoding=picture.encoding, width=picture.width, height=picture.height,
                           source=camera.source, time=time.time(), duration_s=time.monotonic() - began)
        return Response(picture.data, encoding=picture.encoding, attachment=info.model_dump_json())

    transport.serve(keys.camera_capture(config.cell_id), on_capture)


def main(config: CellConfig) -> int:
    async def run(stop: asyncio.Event) -> None:
        transport = await open_transport(config)
        try:
            async with make_camera(config, transport) as camera:
                serve_camera(transport, config, camera)
                transport.declare_token(keys.alive(config.cell_id, "camera"))
                log.info("camera worker of cell %s ready: %s", config.cell_id, camera.source)
                await stop.wait()
        finally:
            await transport.close()

    return run_until_stopped(run, "camera worker")
