"""The steps of a job: objects with one way in (:meth:`Step.run`) and one way out.

A job runs the steps of its plan in order and knows nothing of what each does; a
step says what the job is doing while it runs (``activity``, ``describe``),
whether it needs the robot and the camera (``needs_robot``: the daemon then runs
it in the motion lane, one job at a time), and how it is written in the job's
checkpoint (:meth:`Step.spec`, read back by ``cell.plan.step_from_spec``). A step that
fails raises :class:`StepFailed` with the reason; what it gathers it leaves on the
:class:`~cell.job.Job`; the steps that follow from what it found it returns (a
reconstruction that is unsure asks for one more view), and the daemon puts them
next in the plan. A new step is a new class (a pick's are in ``cell.pick``) and a line in ``cell.plan``.

The steps ask the cell's workers through a :class:`Cell`, which the daemon is.
"""

from __future__ import annotations

import abc
import asyncio
import logging
import time
from typing import Any, ClassVar, Protocol

import numpy as np

from robocell.core_cy.errors import CoreError
from robocell.core_cy.plan import camera_poses
from robocell.wire import keys
from robocell.wire.config import CellConfig
from robocell.wire.errors import CellError, LinkDown, StoreError
from robocell.wire.messages import (CameraModel, CaptureInfo, CaptureRequest, JobState, Message,
                           MoveReply, MoveRequest, NextViewQuery, ReconstructReply,
                           ReconstructRequest, ReconstructView, ScanResult, parse)
from robocell.wire.transport import Reply

from .backgrounds import Backgrounds
from .job import Job, Picture
from .pool import AttemptFailed, NoReconstructor, ReconstructorPool
from .verify import Evidence, Verdict, check_answer, job_evidence

__all__ = ["Step", "StepFailed", "Cell", "View", "Reconstruct", "KeepBackgrounds", "parse_reply"]

log = logging.getLogger(__name__)


class StepFailed(CellError):
    """A step failed; the message says why, ``kind`` the class of the error behind it."""

    def __init__(self, message: str, *, kind: str | None = None) -> None:
        super().__init__(message)
        self.kind = kind


class Cell(Protocol):
    """What a step may use of the daemon."""

    config: CellConfig
    pool: ReconstructorPool
    #: The backgrounds the cell keeps (``cell.backgrounds``).
    backgrounds: Backgrounds

    def clock(self) -> float: ...

    async def ask(self, job: Job, part: str, key: str, message: Message, timeout: float) -> Reply:
        """Query the cell's ``part`` worker, and repeat the query while the part is away (the link
        down, the worker gone, its camera not answering), within the outage allowance;
        :class:`StepFailed` says why not."""

    async def wait_link(self, job: Job) -> None:
        """Return once the link to the router is up, within the outage allowance; else
        :class:`StepFailed`."""

    def record(self, job: Job, method: str, *args: object) -> None:
        """Add to the job's recording (``cell.recording.JobRecording.<method>``)."""

    def record_reconstruction(self, job: Job, reply_json: bytes, payload: bytes) -> None:
        """Draw a worker's reconstruction (its reply and payload) in the job's recording."""

    async def note(self, job: Job, message: str, *, level: int = logging.WARNING) -> None:
        """Tell the job's listeners something that changes nothing (a retry, say); logged at ``level``
        (a warning unless told: news that needs no one's attention is ``logging.INFO``)."""

    async def doing(self, job: Job, activity: JobState, doing: str) -> None:
        """The step goes on to something else (a view's capture after its move)."""

    async def keep(self, job: Job, picture: Picture) -> None:
        """Keep the job's next picture on disk: a restart does not take it again."""

    def candidates(self, job: Job) -> list[np.ndarray]:
        """Flange poses of next views the robot may take (reachable, inside the workspace)."""


class Step(abc.ABC):
    """One step of a job."""

    #: How the step is named in a checkpoint (see :meth:`spec`).
    kind: ClassVar[str]
    #: What the job is doing while the step runs.
    activity: ClassVar[JobState]
    #: Whether the step needs the robot (and the camera on it): it then runs in the motion lane.
    needs_robot: ClassVar[bool] = False
    #: The view the step is about, if any.
    view: int | None = None

    @abc.abstractmethod
    def describe(self) -> str:
        """What the job is doing, for its event: "moving to view 0"."""

    def spec(self) -> dict[str, Any]:
        """The step as JSON, for the job's checkpoint: ``step_from_spec(step.spec())`` is the step."""
        return {"kind": self.kind, **self._fields()}

    def _fields(self) -> dict[str, Any]:
        return {}

    @abc.abstractmethod
    async def run(self, job: Job, cell: Cell) -> list[Step] | None:
        """Do the step; the steps that follow from what it found (to come next), if any. Raise
        :class:`StepFailed` if it cannot be done."""


class View(Step):
    """Move the flange to a view's pose, and take the picture there."""

    kind = "view"
    activity = JobState.MOVING
    needs_robot = True

    def __init__(self, view: int, pose: np.ndarray) -> None:
        self.view, self.pose = view, np.asarray(pose, dtype=np.float64)

    def describe(self) -> str:
        return f"moving to view {self.view}"

    def _fields(self) -> dict[str, Any]:
        return {"view": self.view, "pose": self.pose.tolist()}

    async def run(self, job: Job, cell: Cell) -> None:
        config, view = cell.config, self.view
        reply = await cell.ask(job, "robot", keys.robot_move(config.cell_id),
                               MoveRequest(T_base_flange=self.pose.tolist(), job_id=job.job_id), config.timeouts.move_s)
        moved = parse_reply(MoveReply, reply.payload, "the robot worker")
        job.durations_s[f"move{view}"] = moved.duration_s
        flange = job.flange = np.asarray(moved.T_base_flange)
        # The capture is asked first, and the job's change is stored, told and recorded while
        # the camera works: the same change in the same order, off the way of the picture.
        capture = asyncio.ensure_future(cell.ask(job, "camera", keys.camera_capture(config.cell_id),
                                                 CaptureRequest(job_id=job.job_id, view=view),
                                                 config.timeouts.capture_s))
        try:
            await cell.doing(job, JobState.CAPTURING, f"capturing view {view}")
            cell.record(job, "log_robot_pose", flange)
        except BaseException:
            capture.cancel()
            raise
        reply = await capture
        info = parse_reply(CaptureInfo, reply.attachment, "the camera worker")
        job.durations_s[f"capture{view}"] = info.duration_s
        picture = Picture(reply.payload, flange, camera_poses([flange], config.T_flange_cam)[0])
        try:
            await cell.keep(job, picture)
        except StoreError as exc:  # the job has it in memory; a restarted daemon would take this view again
            log.warning("job %s: picture %d not kept for a restart: %s", job.job_id, view, exc)
        job.captures.append(picture)
        cell.record(job, "log_view", view, picture.jpeg, config.camera.K, picture.T_base_cam, (info.width, info.height))
        return None


class Reconstruct(Step):
    """Send the pictures to the reconstruction pool, retrying on another worker when one fails.

    In an adaptive scan (``views: adaptive``) the reconstruction also chooses the next view among
    the poses the robot may take; while the model is unsure and the scan has views to spare, the
    step asks for that view and another reconstruction.
    """

    kind = "reconstruct"
    activity = JobState.RECONSTRUCTING

    def describe(self) -> str:
        return "reconstructing"

    async def run(self, job: Job, cell: Cell) -> list[Step] | None:
        config = cell.config
        backgrounds = await asyncio.to_thread(_backgrounds_of, job.captures, cell.backgrounds, config)
        request = _reconstruct_request(job, config, [len(b) for b in backgrounds])
        payload = b"".join(c.jpeg + b for c, b in zip(job.captures, backgrounds))
        used = sum(1 for b in backgrounds if b)
        if used:
            await cell.note(job, f"with the backgrounds of {used} of its {len(backgrounds)} views", level=logging.INFO)
        # Asked at the cap too: the scan then ends saying how unsure its model is.
        candidates = cell.candidates(job) if job.request.views == "adaptive" else []
        if candidates:
            request.next_view = NextViewQuery.model_validate({
                "candidates": [{"K": config.camera.K, "T_world_cam": T.tolist()}
                               for T in camera_poses(candidates, config.T_flange_cam)]})
        # No worker is trusted with the robot: every answer is checked against the daemon's own
        # silhouettes of the pictures, made once per job while the first worker reconstructs.
        evidence: asyncio.Future[Evidence] = asyncio.ensure_future(
            asyncio.to_thread(job_evidence, request, list(job.captures), config))
        try:
            return await self._attempts(job, cell, request, payload, candidates, evidence)
        finally:
            evidence.cancel()

    async def _attempts(self, job: Job, cell: Cell, request: ReconstructRequest, payload: bytes,
                        candidates: list[np.ndarray], evidence: asyncio.Future[Evidence]) -> list[Step] | None:
        config = cell.config
        attempts = config.reconstruct.max_attempts
        failures: list[str] = []      # "attempt <k> on <worker>: <why>"
        tried: set[str] = set()
        sent = 0
        attempt = 1
        while attempt <= attempts:
            sent += 1
            request.ticket = keys.ticket(config.cell_id, job.job_id, sent)
            began = time.perf_counter()
            try:
                worker, reply = await cell.pool.run(
                    request.ticket, payload, request.model_dump_json(), timeout=config.timeouts.reconstruct_s,
                    wait_s=config.timeouts.outage_s, avoid=tried)
            except LinkDown:  # not the worker's failure: send it again once the link is back
                await cell.wait_link(job)
                continue
            except AttemptFailed as exc:
                tried.add(exc.worker)
                failures.append(f"attempt {attempt} on {exc.worker}: {exc.reason}")
                if attempt < attempts:
                    await cell.note(job, f"{failures[-1]}; trying again")
                attempt += 1
                continue
            except NoReconstructor as exc:
                earlier = f" (after {'; '.join(failures)})" if failures else ""
                raise StepFailed(f"{exc}{earlier}") from None
            job.durations_s["reconstruct"] = time.perf_counter() - began
            answer = parse_reply(ReconstructReply, reply.attachment, "the reconstruction worker")
            if answer.result is None:  # the core's verdict on these pictures: no use retrying
                raise StepFailed(answer.error or "no result", kind=answer.error_kind)
            drawn = answer.worker == worker and answer.ticket == request.ticket
            if not drawn:
                verdict = Verdict(False, f"it answered as {answer.worker!r} to ticket {answer.ticket!r}")
            else:  # its model must agree with the daemon's own pictures, its grasps with the model
                # Drawn by the recorder's process while it is checked here; taken out again if refused.
                cell.record_reconstruction(job, reply.attachment or b"", reply.payload)
                verdict = await asyncio.to_thread(check_answer, answer.result, await evidence)
            if not verdict.ok:
                if drawn:
                    cell.record(job, "clear_reconstruction")
                cell.pool.refuse(worker, verdict.reason)
                tried.add(worker)
                failures.append(f"attempt {attempt} on {worker}: refused: {verdict.reason}")
                if attempt < attempts:
                    await cell.note(job, f"{failures[-1]}; trying again")
                attempt += 1
                continue
            cell.pool.confirm(worker)
            fit = answer.result.superquadric
            grasps = [answer.result.grasps[i] for i in verdict.grasps]
            nxt = answer.result.next_view
            job.result = ScanResult(
                job_id=job.job_id, superquadric=fit, parts=answer.result.parts, grasps=grasps,
                silhouette_iou=answer.result.silhouette_iou, residual=answer.result.residual,
                timings_ms=answer.result.timings_ms, T_base_cam=[c.T_base_cam.tolist() for c in job.captures],
                durations_s=job.durations_s, worker=worker, attempts=attempt,
                uncertainty=nxt.uncertainty if nxt is not None else None)
            return await self._next(job, cell, candidates, nxt)
        raise StepFailed(f"gave up after {attempts} attempts: {'; '.join(failures)}")

    async def _next(self, job: Job, cell: Cell, candidates: list[np.ndarray], nxt) -> list[Step] | None:
        """One more view and another reconstruction, while the model is unsure and views are left."""
        if job.request.views != "adaptive":
            return None
        views = len(job.captures)
        if nxt is not None and nxt.sure:
            await cell.note(job, f"the model is sure after {views} views (uncertainty {nxt.uncertainty:.3g})",
                            level=logging.INFO)
            return None
        if views >= job.request.max_views or nxt is None or nxt.candidate is None \
                or not 0 <= nxt.candidate < len(candidates):
            why = (f"the scan has its {job.request.max_views} views" if views >= job.request.max_views
                   else "no view the robot may take would help")
            unsure = f" (uncertainty {nxt.uncertainty:.3g})" if nxt is not None else ""
            await cell.note(job, f"{why}: ending with a model still unsure{unsure}")
            return None
        await cell.note(job, f"the model is unsure (uncertainty {nxt.uncertainty:.3g}): taking view {views}, "
                             f"expected to gain {nxt.expected_gain:.3g}", level=logging.INFO)
        return [View(views, candidates[nxt.candidate]), Reconstruct()]


def _backgrounds_of(captures: list[Picture], kept: Backgrounds, config: CellConfig) -> list[bytes]:
    """Each picture's background (JPEG), where the cell keeps one taken from its pose by its camera; else b""."""
    camera = config.camera
    size = (int(camera.resolution[0]), int(camera.resolution[1]))
    found = []
    for picture in captures:
        background = kept.find(picture.T_base_cam, K=camera.K, dist=camera.dist, size=size)
        try:
            found.append(background.path.read_bytes() if background is not None else b"")
        except OSError:  # deleted by retention since it was found: the view goes without
            found.append(b"")
    return found


def _reconstruct_request(job: Job, config: CellConfig, background_lengths: list[int]) -> ReconstructRequest:
    camera = CameraModel(K=config.camera.K, dist=config.camera.dist)
    settings = config.reconstruct
    options = {name: value for name in ("n_points", "inside_weight", "cauchy_scale")
               if (value := getattr(settings, name)) is not None}
    views = [ReconstructView(camera=camera, T_world_cam=c.T_base_cam.tolist(), length=len(c.jpeg),
                             background_length=length)
             for c, length in zip(job.captures, background_lengths)]
    # The scan's own segmentation, else the cell's [scan] one; None is auto (the core's default).
    segmentation = job.request.segmentation or config.scan.segmentation
    return ReconstructRequest(job_id=job.job_id, views=views, support_plane=config.support_plane, options=options,
                              gripper=config.gripper.dimensions(), segmentation=segmentation)


class KeepBackgrounds(Step):
    """Keep the job's pictures as the backgrounds of their poses (a ``kind: backgrounds`` job's last
    step): later scans from those poses send them with their views (``cell.backgrounds``)."""

    kind = "keep-backgrounds"
    activity = JobState.CAPTURING

    def describe(self) -> str:
        return "keeping the backgrounds"

    async def run(self, job: Job, cell: Cell) -> None:
        camera = cell.config.camera
        now = time.time()
        try:
            for view, picture in enumerate(job.captures):
                await asyncio.to_thread(cell.backgrounds.keep, job.job_id, view, picture.jpeg, picture.T_base_cam,
                                        K=camera.K, dist=camera.dist, now=now)
        except OSError as exc:
            raise StepFailed(f"the backgrounds cannot be kept in {cell.backgrounds.root}: {exc.strerror or exc}",
                             kind="StoreError") from None
        except CoreError as exc:
            raise StepFailed(f"the camera's picture is none: {exc}", kind=type(exc).__name__) from None
        return None


def parse_reply(model, payload, who: str):
    try:
        return parse(model, payload)
    except ValueError as exc:
        raise StepFailed(f"{who} answered with {exc}") from None
