"""The steps of a job: objects with one way in (:meth:`Step.run`) and one way out.

A job runs its steps in order and knows nothing of what each does; a step says
in which state the job is while it runs (``state``), what to tell the client
(``describe``), and whether it needs the robot and the camera (``needs_robot``:
the daemon then runs it in the motion lane, one job at a time). A step that
fails raises :class:`StepFailed` with the reason; what it gathers it leaves on
the :class:`~cell.job.Job`. A new step (a grasp, a pick, a second look) is a new
class here and a line in the function that lists a request's steps.

The steps ask the cell's workers through a :class:`Cell`, which the daemon is.
"""

from __future__ import annotations

import abc
import time
from typing import ClassVar, Protocol

import numpy as np

from core_cy.plan import camera_poses
from wire import keys
from wire.config import CellConfig
from wire.errors import CellError, LinkDown
from wire.messages import (CameraModel, CaptureInfo, CaptureRequest, JobState, Message, MoveReply, MoveRequest,
                           ReconstructReply, ReconstructRequest, ReconstructView, ScanResult, Superquadric, parse)
from wire.transport import Reply

from .job import Job, Picture
from .pool import AttemptFailed, NoReconstructor, ReconstructorPool

__all__ = ["Step", "StepFailed", "Cell", "Move", "Capture", "Reconstruct", "scan_steps"]


class StepFailed(CellError):
    """A step failed; the message says why, ``kind`` the class of the error behind it."""

    def __init__(self, message: str, *, kind: str | None = None) -> None:
        super().__init__(message)
        self.kind = kind


class Cell(Protocol):
    """What a step may use of the daemon."""

    config: CellConfig
    pool: ReconstructorPool

    def clock(self) -> float: ...

    async def ask(self, job: Job, part: str, key: str, message: Message, timeout: float) -> Reply:
        """Query the cell's ``part`` worker, and repeat the query while the part is away (the link
        down, the worker gone, its camera not answering), within the outage allowance;
        :class:`StepFailed` says why not."""

    async def wait_link(self, job: Job) -> None:
        """Return once the link to the router is up, within the outage allowance; else
        :class:`StepFailed`."""

    def record(self, job: Job, method: str, *args: object) -> None:
        """Add to the job's recording (handed over while the job waits, see ``cell.journal``)."""

    def hand_over(self, job: Job) -> None:
        """Hand the job's recording messages to the recorder now."""

    def note(self, job: Job, message: str) -> None:
        """Tell the job's listeners something that changes no state (a retry, say)."""


class Step(abc.ABC):
    """One step of a job."""

    #: The job's state while the step runs.
    state: ClassVar[JobState]
    #: Whether the step needs the robot (and the camera on it): it then runs in the motion lane.
    needs_robot: ClassVar[bool] = False
    #: The view the step is about, if any.
    view: int | None = None

    @abc.abstractmethod
    def describe(self) -> str:
        """What the job is doing, for its event: "moving to view 0"."""

    def label(self) -> str:
        """The step, in the error of a job it failed: "<label>: <reason>"."""
        return self.describe()

    @abc.abstractmethod
    async def run(self, job: Job, cell: Cell) -> None:
        """Do the step; raise :class:`StepFailed` if it cannot be done."""


class Move(Step):
    """Move the flange to a view's pose."""

    state = JobState.MOVING
    needs_robot = True

    def __init__(self, view: int) -> None:
        self.view = view

    def describe(self) -> str:
        return f"moving to view {self.view}"

    async def run(self, job: Job, cell: Cell) -> None:
        assert self.view is not None
        pose = job.poses[self.view]
        reply = await cell.ask(job, "robot", keys.robot_move(cell.config.cell_id),
                               MoveRequest(T_base_flange=pose.tolist(), job_id=job.job_id), cell.config.timeouts.move_s)
        moved = _parse(MoveReply, reply.payload, "the robot worker")
        job.durations_s[f"move{self.view}"] = moved.duration_s
        job.flange = np.asarray(moved.T_base_flange)
        cell.record(job, "log_robot_pose", job.flange)


class Capture(Step):
    """Take the picture of a view, where the robot stands."""

    state = JobState.CAPTURING
    needs_robot = True

    def __init__(self, view: int) -> None:
        self.view = view

    def describe(self) -> str:
        return f"capturing view {self.view}"

    async def run(self, job: Job, cell: Cell) -> None:
        cell.hand_over(job)  # during the snapshot, which takes tens of milliseconds
        config = cell.config
        reply = await cell.ask(job, "camera", keys.camera_capture(config.cell_id),
                               CaptureRequest(job_id=job.job_id, view=self.view), config.timeouts.capture_s)
        info = _parse(CaptureInfo, reply.attachment, "the camera worker")
        job.durations_s[f"capture{self.view}"] = info.duration_s
        if job.flange is None:
            raise StepFailed("no picture before the robot has moved")
        T_base_cam = camera_poses([job.flange], config.T_flange_cam)[0]
        job.captures.append(Picture(reply.payload, job.flange, T_base_cam))
        cell.record(job, "log_view", self.view, reply.payload, config.camera.K, T_base_cam, (info.width, info.height))


class Reconstruct(Step):
    """Send the pictures to the reconstruction pool, retrying on another worker when one fails."""

    state = JobState.RECONSTRUCTING

    def __init__(self, n_views: int) -> None:
        self.n_views = n_views

    def describe(self) -> str:
        return f"{self.n_views} views taken"

    def label(self) -> str:
        return "reconstructing"

    async def run(self, job: Job, cell: Cell) -> None:
        config = cell.config
        attempts = config.reconstruct.max_attempts
        payload = b"".join(c.jpeg for c in job.captures)
        request = _reconstruct_request(job, config)
        cell.hand_over(job)
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
                    cell.note(job, f"{failures[-1]}; trying again")
                attempt += 1
                continue
            except NoReconstructor as exc:
                earlier = f" (after {'; '.join(failures)})" if failures else ""
                raise StepFailed(f"{exc}{earlier}") from None
            job.durations_s["reconstruct"] = time.perf_counter() - began
            answer = _parse(ReconstructReply, reply.attachment, "the reconstruction worker")
            if answer.result is None:  # the core's verdict on these pictures: no use retrying
                raise StepFailed(answer.error or "no result", kind=answer.error_kind)
            implausible = _implausible(answer.result.superquadric, job.captures, config)
            if implausible:
                raise StepFailed(f"the answer of {answer.worker or worker} is refused: {implausible}",
                                 kind="ImplausibleResult")
            job.reconstruction = (reply.attachment or b"", reply.payload, cell.clock() - job.started)
            job.result = ScanResult(
                job_id=job.job_id, superquadric=answer.result.superquadric,
                silhouette_iou=answer.result.silhouette_iou, residual=answer.result.residual,
                timings_ms=answer.result.timings_ms, T_base_cam=[c.T_base_cam.tolist() for c in job.captures],
                durations_s=job.durations_s, worker=answer.worker or worker, attempts=attempt)
            return
        raise StepFailed(f"gave up after {attempts} attempts: {'; '.join(failures)}")


def scan_steps(n_views: int) -> list[Step]:
    """A scan: move and capture at each view, then reconstruct."""
    steps: list[Step] = []
    for view in range(n_views):
        steps += [Move(view), Capture(view)]
    return [*steps, Reconstruct(n_views)]


def _reconstruct_request(job: Job, config: CellConfig) -> ReconstructRequest:
    camera = CameraModel(K=config.camera.K, dist=config.camera.dist)
    settings = config.reconstruct
    options = {name: value for name in ("n_points", "inside_weight", "cauchy_scale")
               if (value := getattr(settings, name)) is not None}
    views = [ReconstructView(camera=camera, T_world_cam=c.T_base_cam.tolist(), length=len(c.jpeg))
             for c in job.captures]
    return ReconstructRequest(job_id=job.job_id, views=views, support_plane=config.support_plane, options=options)


def _implausible(fit: Superquadric, pictures: list[Picture], config: CellConfig) -> str | None:
    """Why a reconstruction cannot be of what the cameras saw, or None: its centre must be in
    every picture and above the workspace's floor plan, and no camera inside it."""
    T = np.asarray(fit.T_world_object)
    centre, half = T[:3, 3], np.asarray(fit.size)
    low, high = config.robot.workspace.min, config.robot.workspace.max
    if not all(lo <= x <= hi for lo, x, hi in zip(low[:2], centre[:2], high[:2])):
        return f"its centre {np.round(centre, 3).tolist()} m is not over the workspace"
    K = np.asarray(config.camera.K)
    width, height = config.camera.resolution
    for view, picture in enumerate(pictures):
        R, c = picture.T_base_cam[:3, :3], picture.T_base_cam[:3, 3]
        in_object = T[:3, :3].T @ (c - centre)
        if np.all(np.abs(in_object) <= half):
            return f"camera {view} would be inside it (size {np.round(half, 3).tolist()} m)"
        x = K @ (R.T @ (centre - c))
        if x[2] <= 0 or not (0 <= x[0] / x[2] < width and 0 <= x[1] / x[2] < height):
            return f"its centre is outside the picture of view {view}"
    return None


def _parse(model, payload, who: str):
    try:
        return parse(model, payload)
    except ValueError as exc:
        raise StepFailed(f"{who} answered with {exc}") from None
