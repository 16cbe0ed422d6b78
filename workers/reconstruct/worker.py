"""The reconstruction worker: a process pool around core_cy, serving the shared pool keys.

A request's attachment is a ReconstructRequest; its payload the views' JPEGs,
concatenated in order, each followed by its background where it has one (each
view says their lengths). The reply's attachment is a
ReconstructReply; its payload the silhouettes (PNG) and the carved points
(float32), as the reply describes them. Errors of the core (an empty
silhouette, say) are answered as a ReconstructReply with ``error``, so the job
fails with the core's own message; a malformed request gets an error reply
naming the field.

The worker tells every cell what it can take: its capacity (the pool's size)
and its load (requests in flight, with their tickets), in a heartbeat and on
its info key; see ``wire/keys.py`` for the pool's contract.
"""

from __future__ import annotations

import asyncio
import ctypes
import gc
import itertools
import logging
import os
import signal
import socket
import sys
import time
from collections.abc import Awaitable, Callable
from concurrent.futures import ProcessPoolExecutor

import cv2
import numpy as np

from robocell.wire import keys
from robocell.wire.segmentation import core_segmentation
from robocell.wire.config import CellConfig
from robocell.wire.errors import TransportError
from robocell.wire.messages import (POINTS_ENCODING, Blob, Grasp, NextViewAnswer, Reconstruction, ReconstructReply,
                           ReconstructRequest, Superquadric, WorkerLoad, parse)
from robocell.wire.transport import Request, RequestError, Response, Transport
from robocell.core_cy.camera import Camera
from robocell.core_cy.errors import CoreError, ImageError
from robocell.core_cy.grasp import plan_grasps
from robocell.core_cy.gripper import Gripper
from robocell.core_cy.images import check_calibrated_size, checked_size
from robocell.core_cy.next_view import choose_next_view
from robocell.core_cy.reconstruct import Options, View, reconstruct
from robocell.wire.process import open_transport, run_until_stopped

__all__ = ["reconstruct_request", "ReconstructWorker", "Job", "Run", "main", "default_worker_id"]

log = logging.getLogger(__name__)
_PR_SET_PDEATHSIG = 1
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3     # glibc's mallopt parameters


def default_worker_id() -> str:
    """``<host>-<pid>``, with anything a Zenoh key chunk cannot hold made "_"."""
    return keys.safe_worker_id(f"{socket.gethostname()}-{os.getpid()}")


def reconstruct_request(request_json: str, payload: bytes, worker: str = "") -> tuple[str, bytes]:
    """Run one reconstruction (in a pool process): the ReconstructReply as JSON, and its payload.

    The reply names ``worker`` and echoes the request's ticket.
    """
    request = ReconstructRequest.model_validate_json(request_json)
    try:
        views, offset = [], 0
        for index, view in enumerate(request.views):
            camera = Camera(K=view.camera.K, T_world_cam=view.T_world_cam, dist=view.camera.dist, view=index)
            image = payload[offset:offset + view.length]
            offset += view.length
            size = checked_size(image, what="the picture", view=index)
            check_calibrated_size(camera, *size, what="the picture")
            background = None
            if view.background_length:
                background = payload[offset:offset + view.background_length]
                offset += view.background_length
                if checked_size(background, what="the background", view=index) != size:
                    raise ImageError("the background is not the size of its picture", view=index)
            views.append(View(camera, image=image, background=background))
        result = reconstruct(views, segmentation=core_segmentation(request.segmentation),
                             support_plane=request.support_plane, options=Options(**request.options))
    except (CoreError, ValueError) as exc:
        return ReconstructReply(job_id=request.job_id, error=str(exc), error_kind=type(exc).__name__, worker=worker,
                                ticket=request.ticket).model_dump_json(), b""
    grasps = []
    summary = result.to_dict()
    if request.gripper is not None:
        began = time.perf_counter()
        try:
            planned = plan_grasps(result.parts, request.support_plane, Gripper.from_dict(request.gripper),
                                  residual=result.residual, silhouette_iou=result.silhouette_iou, points=result.points,
                                  max_grasps=request.max_grasps)
        except CoreError as exc:
            return ReconstructReply(job_id=request.job_id, error=f"grasps: {exc}", error_kind=type(exc).__name__,
                                    worker=worker, ticket=request.ticket).model_dump_json(), b""
        grasps = [Grasp(T_world_grasp=g.T_world_grasp.tolist(), width=g.width, score=g.score, approach=g.approach)
                  for g in planned]
        summary["timings_ms"]["grasp"] = round(1000 * (time.perf_counter() - began), 3)
    next_view = _next_view(request, result, [view.camera for view in views]) if request.next_view else None
    silhouettes = [cv2.imencode(".png", s)[1].tobytes() for s in result.silhouettes]
    points = np.ascontiguousarray(result.points, dtype="<f4").tobytes()
    reply = ReconstructReply(
        job_id=request.job_id, worker=worker, ticket=request.ticket,
        result=Reconstruction(superquadric=Superquadric.model_validate(summary["superquadric"]),
                              silhouette_iou=summary["silhouette_iou"], residual=summary["residual"],
                              timings_ms=summary["timings_ms"], centre=np.asarray(result.centre).tolist(),
                              radius=float(result.radius), grasps=grasps,
                              parts=[Superquadric.model_validate(part) for part in summary["parts"]],
                              next_view=next_view),
        silhouettes=[Blob(encoding="image/png", length=len(png)) for png in silhouettes],
        points=Blob(encoding=POINTS_ENCODING, length=len(points)))
    return reply.model_dump_json(), b"".join(silhouettes) + points


def _next_view(request: ReconstructRequest, result, cameras: list[Camera]) -> NextViewAnswer | None:
    """The best of the request's candidate next views (``core_cy.next_view``), or None when the core
    can choose none (none of them is in the workspace, say): the scan then ends with what it has."""
    assert request.next_view is not None
    candidates = [Camera(K=c.K, T_world_cam=c.T_world_cam, view=len(cameras) + k)
                  for k, c in enumerate(request.next_view.candidates)]
    try:
        chosen = choose_next_view(result, cameras, candidates, support_plane=request.support_plane)
    except CoreError as exc:
        log.warning("job %s: no next view: %s", request.job_id, exc)
        return None
    return NextViewAnswer(candidate=chosen.candidate, T_world_cam=np.asarray(chosen.T_world_cam).tolist(),
                          expected_gain=float(chosen.expected_gain), uncertainty=float(chosen.uncertainty),
                          sure=bool(chosen.sure))


#: What a worker runs for each request, in a pool process: (ReconstructRequest JSON, payload,
#: worker id) -> (ReconstructReply JSON, its payload). A module-level function, so that the pool
#: can pickle it.
Job = Callable[[str, bytes, str], tuple[str, bytes]]
#: What :class:`ReconstructWorker` awaits for each request: (ReconstructRequest JSON, payload) ->
#: (ReconstructReply JSON, its payload).
Run = Callable[[str, bytes], Awaitable[tuple[str, bytes]]]


class ReconstructWorker:
    """One worker's face on the pool keys (``wire/keys.py``): the work, its load, its token.

    ``run`` does one reconstruction; ``capacity`` is how many the worker does at
    a time (more wait in its queue, and count in ``in_flight``). The heartbeat
    is sent from the event loop, so a hung loop falls silent even while
    Zenoh's own threads keep the liveliness token alive. Use ``async with``,
    or :meth:`start` and :meth:`close`.
    """

    def __init__(self, transport: Transport, worker_id: str, capacity: int, run: Run, *,
                 period_s: float = keys.HEARTBEAT_PERIOD_S) -> None:
        self.transport = transport
        self.worker_id = worker_id
        self.capacity = capacity
        self.period_s = period_s
        self._run = run
        self._in_flight: dict[int, str | None] = {}    # request number -> its ticket
        self._numbers = itertools.count()
        self._answered = 0
        self._started = time.time()
        self._token = None
        self._heartbeat: asyncio.Task | None = None
        self._last_beat = float("-inf")                 # loop time of the last heartbeat sent
        self._beat_due: asyncio.TimerHandle | None = None   # a heartbeat held back (see _load_changed)

    async def start(self) -> None:
        """Serve, start the heartbeat, then announce the worker (its token comes last)."""
        self.transport.serve(keys.reconstructor(self.worker_id), self._on_request)
        self.transport.serve(keys.reconstructor_info(self.worker_id), self._on_info)
        self._heartbeat = asyncio.create_task(self._beat())
        self.announce()

    async def close(self) -> None:
        """Stop the heartbeat and withdraw the token; the transport stays open."""
        if self._heartbeat is not None:
            self._heartbeat.cancel()
            await asyncio.gather(self._heartbeat, return_exceptions=True)
            self._heartbeat = None
        if self._beat_due is not None:
            self._beat_due.cancel()
            self._beat_due = None
        self.withdraw()

    async def __aenter__(self) -> "ReconstructWorker":
        await self.start()
        return self

    async def __aexit__(self, *exc_info) -> None:
        await self.close()

    def announce(self) -> None:
        """Declare the liveliness token: daemons send work from now on."""
        if self._token is None:
            self._token = self.transport.declare_token(keys.reconstructor_alive(self.worker_id))

    def withdraw(self) -> None:
        """Take the token back: daemons send no more work (the heartbeat goes on)."""
        token, self._token = self._token, None
        if token is not None:
            token.undeclare()

    def load(self) -> WorkerLoad:
        tickets = [t for t in self._in_flight.values() if t is not None]
        return WorkerLoad(worker=self.worker_id, capacity=self.capacity, in_flight=len(self._in_flight),
                          tickets=tickets, answered=self._answered, period_s=self.period_s, time=time.time(),
                          started=self._started)

    def _publish(self) -> None:
        self._last_beat = asyncio.get_running_loop().time()
        if self._beat_due is not None:
            self._beat_due.cancel()
            self._beat_due = None
        try:
            self.transport.put(keys.reconstructor_heartbeat(self.worker_id), self.load().model_dump_json())
        except TransportError as exc:
            log.warning("heartbeat not sent: %s", exc)

    def _load_changed(self) -> None:
        """Tell the cells at once, or, if a heartbeat went out less than CHANGE_GAP_S ago, that
        much later, with whatever else changed meanwhile (a job's start and end, say)."""
        if self._beat_due is not None:
            return
        loop = asyncio.get_running_loop()
        wait = self._last_beat + keys.HEARTBEAT_CHANGE_GAP_S - loop.time()
        if wait <= 0:
            self._publish()
        else:
            self._beat_due = loop.call_later(wait, self._publish)

    async def _beat(self) -> None:
        while True:
            self._publish()
            await asyncio.sleep(self.period_s)

    async def _on_info(self, request: Request) -> Response:
        return Response(self.load().model_dump_json())

    async def _on_request(self, request: Request) -> Response:
        if request.attachment is None:
            raise RequestError("missing attachment: expected a ReconstructRequest")
        try:
            parsed = parse(ReconstructRequest, request.attachment)
        except ValueError as exc:
            raise RequestError(str(exc)) from None
        expected = sum(view.length + view.background_length for view in parsed.views)
        received = len(request.payload or b"")
        if received != expected:
            raise RequestError(f"payload has {received} bytes, the views say {expected}")
        number = next(self._numbers)
        self._in_flight[number] = parsed.ticket
        self._load_changed()
        began = time.perf_counter()
        try:
            reply_json, reply_payload = await self._run(request.attachment.decode(), request.payload or b"")
        finally:
            del self._in_flight[number]
            self._answered += 1
            self._load_changed()
        log.info("job %s (%s) answered in %.1f ms", parsed.job_id, parsed.ticket or "no ticket",
                 1000 * (time.perf_counter() - began))
        return Response(reply_payload, encoding="application/octet-stream", attachment=reply_json)


def _pool_process() -> None:
    """Set up a pool process: one reconstruction per process, and it dies with the worker."""
    # OpenCV's own threads would only fight the pool's.
    cv2.setNumThreads(1)
    # What the worker had made before the fork stays put: the garbage collector need not look at
    # it again (nor copy the pages it would touch).
    gc.freeze()
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        # A worker killed with SIGKILL cannot stop its pool; the kernel does it for us.
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
        mallopt = getattr(libc, "mallopt", None)   # glibc
        if mallopt is not None:
            # A reconstruction allocates and frees some 7 MB of images. With glibc's defaults the
            # process gave them back and faulted them in again every job: 1,700 page faults, 3.5 ms
            # of a 20 ms job (measured). Keeping freed memory costs a few tens of MB.
            mallopt(_M_MMAP_THRESHOLD, 64 << 20)
            mallopt(_M_TRIM_THRESHOLD, 256 << 20)


def _ready() -> int:
    return os.getpid()


def main(config: CellConfig, worker_id: str | None = None, *, job: Job = reconstruct_request) -> int:
    """Run a reconstruction worker until SIGTERM/SIGINT; ``job`` is what its pool runs per request.

    Without ``worker_id``, a worker with a Zenoh user takes its user name as its id: under the
    router's access control that is the only id it may serve under (``wire/access.py``)."""
    user = config.zenoh.user
    worker_id = worker_id or (user if user and keys.WORKER_ID.fullmatch(user) else default_worker_id())
    processes = config.reconstruct.processes

    async def run(stop: asyncio.Event) -> None:
        loop = asyncio.get_running_loop()
        pool = ProcessPoolExecutor(processes, initializer=_pool_process)
        try:
            # The pool's processes fork now, before the Zenoh session has threads of its own.
            await asyncio.gather(*(loop.run_in_executor(pool, _ready) for _ in range(processes)))
            transport = await open_transport(config, role="reconstruct", worker_id=worker_id)
            try:
                async def reconstruct_in_pool(request_json: str, payload: bytes) -> tuple[str, bytes]:
                    return await loop.run_in_executor(pool, job, request_json, payload, worker_id)

                async with ReconstructWorker(transport, worker_id, processes, reconstruct_in_pool):
                    log.info("reconstruction worker %s ready with %d processes", worker_id, processes)
                    await stop.wait()
            finally:
                await transport.close()
        finally:
            # Waiting for the pool's manager thread: without it, Python's exit hook for process pools
            # may write to the pool's wake-up pipe after that thread closed it, and logs a traceback
            # (OSError: Bad file descriptor). A job in flight ends first (``robocell up`` kills a child
            # that takes too long to stop).
            pool.shutdown(wait=True, cancel_futures=True)

    return run_until_stopped(run, "reconstruction worker")
