"""The steps of a job: objects with one way in (:meth:`Step.run`) and one way out.

A job runs its steps in order and knows nothing of what each does; a step says
in which state the job is while it runs (``state``), what to tell the client
(``describe``), whether it needs the robot and the camera (``needs_robot``:
the daemon then runs it in the motion lane, one job at a time), and whether the
job's state must be on disk before it runs (``stored_first``). A step that
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

from wire import keys
from wire.config import CellConfig
from wire.errors import CellError, LinkDown
from core_cy.plan import camera_poses, workspace_violation
from wire.messages import (CameraModel, CaptureInfo, CaptureRequest, GripReply, GripRequest, JobState, Message,
                           MoveReply, MoveRequest, PickOutcome, PickRequest, ReconstructReply, ReconstructRequest,
                           ReconstructView, ScanRequest, ScanResult, Superquadric, parse)
from wire.transport import Reply

from .job import Job, Picture
from .pool import AttemptFailed, NoReconstructor, ReconstructorPool

__all__ = ["Step", "StepFailed", "Cell", "Move", "Capture", "Reconstruct", "ChooseGrasp", "PickMove", "Gripper",
           "scan_steps", "job_steps"]


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
        """The job is about to wait for something slow: its recording messages go to the recorder,
        and the store's waiting writes to its thread, a moment into the wait."""

    def note(self, job: Job, message: str) -> None:
        """Tell the job's listeners something that changes no state (a retry, say)."""


class Step(abc.ABC):
    """One step of a job."""

    #: The job's state while the step runs.
    state: ClassVar[JobState]
    #: Whether the step needs the robot (and the camera on it): it then runs in the motion lane.
    needs_robot: ClassVar[bool] = False
    #: Whether the job's state must be on disk before the step runs: a restart must know it began.
    stored_first: ClassVar[bool] = False
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
                job_id=job.job_id, superquadric=answer.result.superquadric, grasps=answer.result.grasps,
                silhouette_iou=answer.result.silhouette_iou, residual=answer.result.residual,
                timings_ms=answer.result.timings_ms, T_base_cam=[c.T_base_cam.tolist() for c in job.captures],
                durations_s=job.durations_s, worker=answer.worker or worker, attempts=attempt)
            return
        raise StepFailed(f"gave up after {attempts} attempts: {'; '.join(failures)}")


class ChooseGrasp(Step):
    """The best of the result's grasps whose every pose the robot may take; the poses of the pick.

    Fails before any motion: with no grasp at all ("no grasp holds this object"), or when the
    robot may reach none (naming the limit the best one breaks).
    """

    state = JobState.PICKING
    stored_first = True  # the pick begins: restarted, the daemon must not pick again (the gripper may hold it)

    def __init__(self, pick: PickRequest) -> None:
        self.pick = pick

    def describe(self) -> str:
        return "choosing a grasp"

    async def run(self, job: Job, cell: Cell) -> None:
        assert job.result is not None, "the reconstruction leaves the result"
        if not job.result.grasps:
            raise StepFailed("no grasp holds this object", kind="NoGrasp")
        first_problem = None
        for index, grasp in enumerate(job.result.grasps):
            # The gripper is symmetric under a half turn about its approach: take the turn the wrist prefers.
            for turned in (False, True):
                poses = pick_poses(np.asarray(grasp.T_world_grasp), self.pick, cell.config, half_turn=turned)
                problem = next(((name, why) for name, pose in poses.items()
                                if (why := workspace_violation(pose, cell.config.robot.workspace))), None)
                if problem is None:
                    job.pick_poses = poses
                    cell.record(job, "log_grasps", [g.T_world_grasp for g in job.result.grasps],
                                [g.width for g in job.result.grasps], index, cell.config.gripper.dimensions())
                    job.result.pick = PickOutcome(grasp=index, T_base_flange=poses["grasp"].tolist(), held=None)
                    return
                first_problem = first_problem or problem
        assert first_problem is not None
        name, why = first_problem
        raise StepFailed(f"no grasp is within the robot's reach: the best one's {name} pose: {why}", kind="MoveRefused")


class PickMove(Step):
    """Move the flange to one of the pick's poses."""

    state = JobState.PICKING
    needs_robot = True

    def __init__(self, pose: str, doing: str) -> None:
        self.pose, self.doing = pose, doing

    def describe(self) -> str:
        return self.doing

    async def run(self, job: Job, cell: Cell) -> None:
        if self.pose in PLACE_POSES and not _holding(job):
            return  # nothing in the gripper to put down
        reply = await cell.ask(job, "robot", keys.robot_move(cell.config.cell_id),
                               MoveRequest(T_base_flange=job.pick_poses[self.pose].tolist(), job_id=job.job_id),
                               cell.config.timeouts.move_s)
        moved = _parse(MoveReply, reply.payload, "the robot worker")
        job.durations_s[f"pick {self.pose}"] = moved.duration_s
        cell.record(job, "log_robot_pose", np.asarray(moved.T_base_flange))


class Gripper(Step):
    """Open or close the gripper; closing on the object says whether it holds it. A release that
    puts the object down (``places``) is skipped when the gripper missed it."""

    state = JobState.PICKING
    needs_robot = True

    def __init__(self, close: bool, doing: str, *, places: bool = False) -> None:
        self.close, self.doing, self.places = close, doing, places

    def describe(self) -> str:
        return self.doing

    async def run(self, job: Job, cell: Cell) -> None:
        assert job.result is not None and job.result.pick is not None
        pick = job.result.pick
        if self.places and not _holding(job):
            return
        reply = await cell.ask(job, "robot", keys.robot_grip(cell.config.cell_id),
                               GripRequest(close=self.close, job_id=job.job_id), cell.config.timeouts.move_s)
        grip = _parse(GripReply, reply.payload, "the robot worker")
        if self.close:
            pick.held, pick.reason, pick.width = grip.holding, grip.reason, grip.width
            verdict = {True: "holds it", False: "missed it", None: "closed (the gripper cannot tell what it holds)"}
            why = f": {grip.reason}" if grip.reason and grip.holding is not True else ""
            cell.note(job, f"the gripper {verdict[grip.holding]}{why}")
        pick.placed = pick.placed or self.places


#: The pick's poses that put the object down: skipped when the gripper missed it.
PLACE_POSES = ("above place", "place", "away")


def _holding(job: Job) -> bool:
    pick = job.result.pick if job.result is not None else None
    return pick is not None and pick.held is not False


def pick_poses(T_world_grasp: np.ndarray, pick: PickRequest, config: CellConfig, *,
               half_turn: bool = False) -> dict[str, np.ndarray]:
    """The flange poses of a pick with this grasp: above it, at it, lifted; and with a place, above
    the place, at it, and backed away. Pure."""
    grasp = T_world_grasp.copy()
    if half_turn:
        grasp[:3, :2] *= -1
    flange_from_grasp = np.linalg.inv(np.asarray(config.gripper.T_flange_grasp))

    def back(T: np.ndarray, distance: float) -> np.ndarray:  # along the grasp's approach, away from it
        moved = T.copy()
        moved[:3, 3] -= distance * T[:3, 2]
        return moved

    def up(T: np.ndarray, distance: float) -> np.ndarray:
        moved = T.copy()
        moved[2, 3] += distance
        return moved

    grasps = {"above": back(grasp, pick.approach_m), "grasp": grasp, "lift": up(grasp, pick.lift_m)}
    if pick.place is not None:  # set down as it stood: the grasp moved across the table
        place = grasp.copy()
        place[:2, 3] = pick.place
        grasps |= {"above place": up(place, pick.lift_m), "place": place, "away": back(place, pick.approach_m)}
    return {name: T @ flange_from_grasp for name, T in grasps.items()}


def scan_steps(n_views: int) -> list[Step]:
    """A scan: move and capture at each view, then reconstruct."""
    steps: list[Step] = []
    for view in range(n_views):
        steps += [Move(view), Capture(view)]
    return [*steps, Reconstruct(n_views)]


def job_steps(request: ScanRequest, n_views: int) -> list[Step]:
    """The steps of a request: its scan, and its pick if it asks for one."""
    steps = scan_steps(n_views)
    if request.pick is None:
        return steps
    steps += [ChooseGrasp(request.pick), Gripper(False, "opening the gripper"),
              PickMove("above", "moving above the grasp"), PickMove("grasp", "approaching"),
              Gripper(True, "closing the gripper"), PickMove("lift", "lifting")]
    if request.pick.place is not None:
        steps += [PickMove("above place", "carrying it over"), PickMove("place", "putting it down"),
                  Gripper(False, "letting go", places=True), PickMove("away", "backing away")]
    return steps


def _reconstruct_request(job: Job, config: CellConfig) -> ReconstructRequest:
    camera = CameraModel(K=config.camera.K, dist=config.camera.dist)
    settings = config.reconstruct
    options = {name: value for name in ("n_points", "inside_weight", "cauchy_scale")
               if (value := getattr(settings, name)) is not None}
    views = [ReconstructView(camera=camera, T_world_cam=c.T_base_cam.tolist(), length=len(c.jpeg))
             for c in job.captures]
    return ReconstructRequest(job_id=job.job_id, views=views, support_plane=config.support_plane, options=options,
                              gripper=config.gripper.dimensions())


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
