"""The reconstruction worker: a process pool around core_cy, serving the shared pool key.

A request's attachment is a ReconstructRequest; its payload the views' JPEGs,
concatenated in order (each view says its length). Errors of the core (an
empty silhouette, say) are answered as a ReconstructReply with ``error``, so
the job fails with the core's own message; a malformed request gets an error
reply naming the field.
"""

from __future__ import annotations

import asyncio
import base64
import logging
import os
import socket
from concurrent.futures import ProcessPoolExecutor

import cv2
import numpy as np

from cell import keys
from cell.config import CellConfig
from cell.messages import ReconstructReply, ReconstructRequest, parse
from cell.transport import Request, RequestError, Response, Transport
from core_cy.camera import Camera
from core_cy.errors import CoreError
from core_cy.reconstruct import Options, View, reconstruct
from core_cy.segment import RED_HSV, Segmentation

from cell.process import open_transport, run_until_stopped

__all__ = ["reconstruct_request", "serve_reconstructor", "main", "default_worker_id"]

log = logging.getLogger(__name__)


def default_worker_id() -> str:
    return f"{socket.gethostname()}-{os.getpid()}".replace("/", "_").replace("*", "_")


def _segmentation(spec: dict | None) -> Segmentation:
    if spec is None:
        return RED_HSV
    method = spec.get("method")
    if method == "hsv":
        return Segmentation("hsv", lower=tuple(spec["lower"]), upper=tuple(spec["upper"]))
    return Segmentation("threshold", value=spec["value"], invert=spec.get("invert", False))


def reconstruct_request(request_json: str, payload: bytes) -> str:
    """Run one reconstruction (in a pool process); returns the ReconstructReply as JSON."""
    request = ReconstructRequest.model_validate_json(request_json)
    try:
        views, offset = [], 0
        for index, view in enumerate(request.views):
            camera = Camera(K=view.camera.K, T_world_cam=view.T_world_cam, dist=view.camera.dist, view=index)
            views.append(View(camera, image=payload[offset:offset + view.length]))
            offset += view.length
        result = reconstruct(views, segmentation=_segmentation(request.segmentation),
                             support_plane=request.support_plane, options=Options(**request.options))
    except (CoreError, ValueError, KeyError) as exc:
        return ReconstructReply(job_id=request.job_id, error=str(exc)).model_dump_json()
    silhouettes = [base64.b64encode(cv2.imencode(".png", s)[1].tobytes()).decode("ascii")
                   for s in result.silhouettes]
    return ReconstructReply(job_id=request.job_id, result=result.to_dict(points=True),
                            centre=np.asarray(result.centre).tolist(), radius=float(result.radius),
                            silhouettes_png=silhouettes).model_dump_json()


def _single_threaded() -> None:
    # One reconstruction per process: OpenCV's own threads would only fight the pool's.
    cv2.setNumThreads(1)


def serve_reconstructor(transport: Transport, pool: ProcessPoolExecutor, worker_id: str) -> None:
    loop = asyncio.get_running_loop()

    async def on_request(request: Request) -> Response:
        if request.attachment is None:
            raise RequestError("missing attachment: expected a ReconstructRequest")
        try:
            parsed = parse(ReconstructRequest, request.attachment)
        except ValueError as exc:
            raise RequestError(str(exc)) from None
        expected = sum(view.length for view in parsed.views)
        received = len(request.payload or b"")
        if received != expected:
            raise RequestError(f"payload has {received} bytes, the views say {expected}")
        reply_json = await loop.run_in_executor(pool, reconstruct_request, request.attachment.decode(),
                                                request.payload)
        reply = ReconstructReply.model_validate_json(reply_json)
        reply.worker = worker_id
        log.info("job %s: %s", parsed.job_id, reply.error or f"{reply.result['timings_ms']['total']:.1f} ms")
        return Response(reply.model_dump_json())

    transport.serve(keys.reconstructor(worker_id), on_request)


def main(config: CellConfig, worker_id: str | None = None) -> int:
    worker_id = worker_id or default_worker_id()

    async def run(stop: asyncio.Event) -> None:
        pool = ProcessPoolExecutor(config.reconstruct.processes, initializer=_single_threaded)
        transport = await open_transport(config)
        try:
            serve_reconstructor(transport, pool, worker_id)
            transport.declare_token(keys.reconstructor_alive(worker_id))
            log.info("reconstruction worker %s ready with %d processes", worker_id, config.reconstruct.processes)
            await stop.wait()
        finally:
            await transport.close()
            pool.shutdown(wait=False, cancel_futures=True)

    return run_until_stopped(run, "reconstruction worker")
