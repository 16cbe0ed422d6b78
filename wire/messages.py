"""Messages on the wire: pydantic models, JSON, each with a ``schema_version``.

Job messages pass between clients and the cell daemon; worker messages
between the daemon and its robot, camera and reconstruction workers. Bytes
never travel inside JSON: pictures, silhouettes and point clouds are the raw
payload, with the JSON model that describes them (each part's encoding and
length, a :class:`Blob`) in the Zenoh attachment (see ``wire/keys.py``).
"""

from __future__ import annotations

import enum
import math
from typing import Annotated, Any, Literal, TypeVar

from robocell.core_cy.rigid import rigid_error
from pydantic import (AfterValidator, BeforeValidator, BaseModel, ConfigDict, Field, StrictBool, StrictFloat, StrictInt,
                      StrictStr, ValidationError, field_validator, model_validator)

__all__ = [
    "SCHEMA_VERSION", "Message", "Pose", "Point", "ViewPlan", "ScanRequest", "JobState", "Lifecycle", "Progress", "ACTIVITIES",
    "wire_state", "NextViewCandidate", "NextViewQuery", "NextViewAnswer",
    "JobStatus", "JobEvent", "Superquadric", "Grasp", "PickRequest", "PickOutcome", "ScanResult", "ErrorReply",
    "MoveRequest", "MoveReply",
    "RobotState", "GripRequest", "GripReply", "CaptureRequest", "CaptureInfo", "CameraModel", "ReconstructView",
    "Blob",
    "ReconstructRequest", "Reconstruction", "ReconstructReply", "WorkerLoad", "ReconstructorStatus",
    "FailedJob", "CellStatus", "parse", "field_errors", "POINTS_ENCODING", "parse_request", "RequestTooLarge",
    "REQUEST_LIMITS", "CancelRequest", "PickDecision", "JOB_TOKEN_BYTES", "DiskUsage", "BACKGROUND_POSE_TOLERANCE",
]

#: The version this robocell writes. Version 2 added a job's ``lifecycle`` and ``progress`` (see
#: README, "Job states"); a message of version 1 is read as before.
SCHEMA_VERSION: Literal[2] = 2
#: The most views a scan may ask for, as poses or as a plan.
MAX_VIEWS = 16
#: How close a view's camera pose must be to a kept background's (metres, degrees) for the
#: background to be used: about a pixel at the object (600 px focal length, 0.5 m away, a pixel
#: is 0.8 mm across and 0.1 degree turns the image by 1 px). A robot returns to a taught pose
#: far closer (a KUKA arm within 0.05 mm); the planned poses of a target are the same numbers.
BACKGROUND_POSE_TOLERANCE = (0.001, 0.1)


def _rigid(matrix: list[list[float]]) -> list[list[float]]:
    problem = rigid_error(matrix)
    if problem is not None:
        raise ValueError(f"pose {problem}")
    return matrix


def _finite(values: list[float]) -> list[float]:
    if not all(math.isfinite(v) for v in values):
        raise ValueError("must be finite numbers")
    return values


# Numbers a client sends are JSON numbers: "1.5" is not 1.5, and true is not 1 (strict types
# wherever a request is parsed; a JSON integer is still a good float).
Row4 = Annotated[list[StrictFloat], Field(min_length=4, max_length=4)]
#: A 4x4 rigid transform, metres; which frames it maps between is in the field's name.
Pose = Annotated[list[Row4], Field(min_length=4, max_length=4), AfterValidator(_rigid)]
#: A point, metres.
Point = Annotated[list[StrictFloat], Field(min_length=3, max_length=3), AfterValidator(_finite)]


def _integer(value: Any) -> Any:
    if type(value) is not int:  # JSON's true and 1.0 would pass as 1
        raise ValueError(f"must be the integer 1 or {SCHEMA_VERSION}, got {value!r}")
    return value


class Message(BaseModel):
    """Base of every message: strict fields, and the schema version first (an integer: ``true`` or
    ``1.0`` is not a version)."""

    model_config = ConfigDict(extra="forbid")
    schema_version: Annotated[Literal[1, 2], BeforeValidator(_integer)] = SCHEMA_VERSION


def _version_required(schema: dict[str, Any]) -> None:
    schema["required"] = ["schema_version", *schema.get("required", [])]


class ClientRequest(Message):
    """Base of what a client asks of the daemon: its ``schema_version`` is required on the wire
    (:func:`parse_request` refuses a request without it; a model made in Python has it)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra=_version_required)


def field_errors(exc: ValidationError, *, whole: str = "message", at_most: int = 10) -> str:
    """One line naming each invalid field: ``target: List should have at least 3 items``.

    The tag of a discriminated union (``backend=kuka``, see ``wire.backends``) is not a field,
    and is left out of the field's name.

    ``whole`` names what an error about the whole input (no field) is about. Past ``at_most``
    errors, the line says how many more there are (hostile input can hold thousands).
    """
    errors = exc.errors()
    named = [f"{'.'.join(str(p) for p in error['loc'] if '=' not in str(p)) or whole}: {error['msg']}"
             for error in errors[:at_most]]
    if len(errors) > at_most:
        named.append(f"and {len(errors) - at_most} more")
    return "; ".join(named)


M = TypeVar("M", bound=BaseModel)


def parse(model: type[M], payload: bytes | str | None) -> M:
    """Validate a JSON payload as a ``model``; raises ``ValueError`` whose text names the wrong fields."""
    if payload is None or len(payload) == 0:
        raise ValueError(f"empty payload: expected a JSON {model.__name__}")
    try:
        return model.model_validate_json(payload)
    except ValidationError as exc:
        raise ValueError(f"invalid {model.__name__}: {field_errors(exc)}") from None


class RequestTooLarge(ValueError):
    """A request longer than its limit: refused before it is parsed."""


#: The most bytes a request's payload may take, checked before it is parsed (:func:`parse_request`).
#: A submit with 16 flange poses at full precision takes about 8 kB; every other request to the
#: daemon (a cancel with its token, a pick decision, a status or list query) well under 1 kB.
REQUEST_LIMITS: dict[str, int] = {
    "submit": 64 * 1024,            # ScanRequest
    "cancel": 4 * 1024,             # CancelRequest
    "pick": 4 * 1024,               # PickDecision
    "query": 4 * 1024,              # jobs, jobs/<id>, jobs/<id>/result, status: parameters only
    "part": 4 * 1024,               # the robot's move, gripper and state, the camera's capture
    "worker": 1024 * 1024,          # a worker's JSON answer (ReconstructReply: grasps, timings)
}


def parse_request(model: type[M], payload: bytes | str | None, limit: int) -> M:
    """:func:`parse`, after checking the payload's size against ``limit`` (bytes; see
    :data:`REQUEST_LIMITS`): a payload of 50 MB is refused unread, with a one-line error. A
    request names its ``schema_version`` (a client of a later robocell would be misread otherwise):
    one without it is refused, naming the field.

    Raises
    ------
    RequestTooLarge
        If the payload is longer than ``limit``.
    ValueError
        As :func:`parse`.

    >>> parse_request(GripRequest, b'{"schema_version": 2, "close": true}', 4096).close
    True
    >>> parse_request(GripRequest, b'{"close": true}', 4096)
    Traceback (most recent call last):
    ...
    ValueError: invalid GripRequest: schema_version: Field required (every request names its schema version, 1 or 2)
    >>> parse_request(GripRequest, b" " * 5000, 4096)
    Traceback (most recent call last):
    ...
    robocell.wire.messages.RequestTooLarge: the GripRequest is 5000 bytes: at most 4096 are taken
    """
    size = 0 if payload is None else len(payload.encode() if isinstance(payload, str) else payload)
    if size > limit:
        raise RequestTooLarge(f"the {model.__name__} is {size} bytes: at most {limit} are taken")
    request = parse(model, payload)
    if "schema_version" in model.model_fields and "schema_version" not in request.model_fields_set:
        raise ValueError(f"invalid {model.__name__}: schema_version: Field required (every request names its "
                         f"schema version, 1 or {SCHEMA_VERSION})")
    return request


# --- jobs --------------------------------------------------------------------------------------

class ViewPlan(BaseModel):
    """Where to look at a target from: one view per (elevation, azimuth), at ``standoff`` metres."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    standoff: Annotated[StrictFloat, Field(gt=0.05, le=3.0)] = 0.5
    # Below 90: looking straight down, the camera's image "up" is undefined.
    elevations_deg: Annotated[list[Annotated[StrictFloat, Field(ge=5, lt=90)]],
                              Field(min_length=2, max_length=MAX_VIEWS)] = [55.0, 40.0, 35.0]
    azimuths_deg: Annotated[list[StrictFloat], Field(min_length=2, max_length=MAX_VIEWS)] = [0.0, 120.0, 240.0]

    @model_validator(mode="after")
    def _same_length(self) -> "ViewPlan":
        if len(self.elevations_deg) != len(self.azimuths_deg):
            raise ValueError("elevations_deg and azimuths_deg must have the same length")
        return self


class PickRequest(BaseModel):
    """After the scan, pick the object up with the best grasp the robot can reach.

    The gripper opens, moves ``approach_m`` back from the grasp along its approach, goes in,
    closes, and lifts the object ``lift_m`` straight up; with ``place`` (x, y on the table, base
    frame, metres) it then carries it over, sets it down there as it stood (the grasp moved
    across, at its height and turn), opens, and backs away.
    """

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    approach_m: Annotated[StrictFloat, Field(gt=0, le=0.5)] = 0.1
    lift_m: Annotated[StrictFloat, Field(gt=0, le=0.5)] = 0.1
    place: Annotated[list[StrictFloat], Field(min_length=2, max_length=2)] | None = None


class ScanRequest(ClientRequest):
    """Scan one object: either explicit flange poses, or a target point to plan views around;
    with ``pick``, then pick it up.

    ``flange_poses`` are flange-to-base transforms in the robot base frame. ``request_id``,
    chosen by the client, makes submitting idempotent.

    ``kind: backgrounds`` takes no model: the robot goes to the same poses (the target's
    planned views, or the flange poses), and the camera photographs the empty workspace
    at each (the object not yet there). The cell keeps one background per pose; a later
    scan whose view stands at a pose within :data:`BACKGROUND_POSE_TOLERANCE` of one sends
    it as that view's ``background`` to the reconstruction (README, "Backgrounds").
    """

    request_id: Annotated[StrictStr, Field(min_length=1, max_length=128)] | None = None
    flange_poses: Annotated[list[Pose], Field(min_length=2, max_length=MAX_VIEWS)] | None = None
    target: Point | None = None
    plan: ViewPlan | None = None
    pick: PickRequest | None = None
    label: Annotated[StrictStr, Field(max_length=200)] = ""
    #: How the reconstruction finds the object, as scan.json's ``segmentation``; None: the cell's
    #: ``[scan]`` configuration, whose default is ``auto``.
    segmentation: dict | None = None
    #: ``"adaptive"``: after the planned views, one more view at a time where the model is least
    #: sure, until it is sure or it has ``max_views`` views (needs ``target``: the views look at it).
    views: Literal["planned", "adaptive"] = "planned"
    max_views: Annotated[StrictInt, Field(ge=2, le=MAX_VIEWS)] = 6
    #: ``"scan"`` models the object; ``"backgrounds"`` photographs the empty workspace at the scan's
    #: poses, for later scans at those poses.
    kind: Literal["scan", "backgrounds"] = "scan"

    @model_validator(mode="after")
    def _one_kind_of_views(self) -> "ScanRequest":
        if self.segmentation is not None:
            from .segmentation import core_segmentation

            core_segmentation(self.segmentation)  # a ValueError naming the field
        if (self.flange_poses is None) == (self.target is None):
            raise ValueError("give exactly one of flange_poses and target")
        if self.plan is not None and self.target is None:
            raise ValueError("plan goes with target")
        if self.views == "adaptive" and self.target is None:
            raise ValueError("views: adaptive goes with target (the next views look at it)")
        if self.kind == "backgrounds" and (self.pick is not None or self.views == "adaptive"):
            raise ValueError("kind: backgrounds photographs the empty workspace: it takes no pick and no "
                             "adaptive views")
        return self


class JobState(str, enum.Enum):
    """Where a job is; ``cell/job.py`` has the legal moves between states."""

    QUEUED = "queued"
    MOVING = "moving"
    CAPTURING = "capturing"
    RECONSTRUCTING = "reconstructing"
    #: Choosing a grasp, moving to it, closing the gripper, lifting, placing (a pick).
    PICKING = "picking"
    #: A cancel was accepted; the job stops at the end of what it is doing.
    CANCELLING = "cancelling"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"

    @property
    def finished(self) -> bool:
        return self in (JobState.SUCCEEDED, JobState.FAILED, JobState.CANCELLED)


class Lifecycle(str, enum.Enum):
    """Where a job is in its life (``cell/job.py`` has the legal moves); what it is doing while
    it runs is its :class:`Progress`."""

    QUEUED = "queued"
    RUNNING = "running"
    CANCELLING = "cancelling"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"

    @property
    def finished(self) -> bool:
        return self in (Lifecycle.SUCCEEDED, Lifecycle.FAILED, Lifecycle.CANCELLED)


#: What a running job may be doing, as the ``state`` clients of schema version 1 read.
ACTIVITIES = (JobState.MOVING, JobState.CAPTURING, JobState.RECONSTRUCTING, JobState.PICKING)


class Progress(BaseModel):
    """What a job is doing: the step of its plan it runs, and what that step does now."""

    model_config = ConfigDict(extra="forbid")
    activity: JobState                      # moving, capturing, reconstructing or picking
    doing: str                              # "moving to view 2", "approaching"
    view: int | None = None                 # the view being moved to or captured, from 0
    step: Annotated[int, Field(ge=0)]       # the step's place in the plan, from 0
    steps: Annotated[int, Field(ge=1)]      # the steps of the plan so far (it may grow)

    @field_validator("activity")
    @classmethod
    def _an_activity(cls, value: JobState) -> JobState:
        if value not in ACTIVITIES:
            raise ValueError(f"must be one of {', '.join(a.value for a in ACTIVITIES)}, got {value.value}")
        return value


def wire_state(lifecycle: Lifecycle, progress: Progress | None) -> JobState:
    """The ``state`` of schema version 1: the lifecycle, or while running the activity."""
    if lifecycle is Lifecycle.RUNNING:
        return progress.activity if progress is not None else JobState.MOVING
    return JobState(lifecycle.value)


class JobStatus(Message):
    job_id: str
    #: Kept for clients of schema version 1: ``lifecycle``, or while it runs ``progress.activity``.
    state: JobState
    lifecycle: Lifecycle = Lifecycle.QUEUED
    progress: Progress | None = None
    view: int | None = None          # the view being moved to or captured, from 0
    n_views: int
    error: str | None = None         # why it failed: "<step>: <reason>"
    error_kind: str | None = None    # the class of that error, as ErrorReply.kind
    created: float                   # unix time
    updated: float
    recording: str | None = None     # path of the job's Rerun .rrd
    request: ScanRequest
    #: The job's token, a secret: in the answer to its submit only (never in a list, a status
    #: query or an event). Cancel and pick decisions must show it (:class:`CancelRequest`).
    token: str | None = None


PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]


class Superquadric(BaseModel):
    """The 11 parameters (DESIGN.md §3): half-sizes, shape exponents (e1, e2), object-to-world pose;
    in the bundle's units (metres in a cell)."""

    model_config = ConfigDict(extra="forbid")
    size: Annotated[list[PositiveFloat], Field(min_length=3, max_length=3)]
    shape: Annotated[list[PositiveFloat], Field(min_length=2, max_length=2)]
    T_world_object: Pose


class Grasp(BaseModel):
    """A parallel-jaw grasp (DESIGN.md §3): the grasp frame (z the approach, y the closing
    direction, the origin between the pads), the object's width between the pads, and how
    likely it is to hold given the model's own error."""

    model_config = ConfigDict(extra="forbid")
    T_world_grasp: Pose
    width: Annotated[float, Field(gt=0)]
    score: Annotated[float, Field(ge=0, le=1)]
    approach: Literal["top", "side", "tilted"] = "top"


class PickOutcome(BaseModel):
    """How a pick went. ``held`` is None where the gripper cannot tell; in a simulated cell the
    simulator judges the grasp against its true object, and ``reason`` says why."""

    model_config = ConfigDict(extra="forbid")
    grasp: int                              # which of the result's grasps, from 0
    T_base_flange: Pose                     # where the flange was when the gripper closed
    held: bool | None
    reason: str = ""
    width: float | None = None              # the gripper's opening once closed, metres, if known
    placed: bool = False


class ScanResult(Message):
    job_id: str
    #: The one superquadric closest to the whole object, for programs that take one.
    superquadric: Superquadric
    #: The model as parts (DESIGN.md §1.11), the object their union; one part for an object that is
    #: one superquadric, empty from an older reconstruction worker.
    parts: Annotated[list[Superquadric], Field(max_length=6)] = []
    #: Grasps of the cell's gripper, best first; empty when none is likely to hold (DESIGN.md §3).
    grasps: list[Grasp] = []
    #: For a job that asked for a pick.
    pick: PickOutcome | None = None
    silhouette_iou: list[float]
    residual: float
    timings_ms: dict[str, float]
    T_base_cam: list[Pose]           # where each picture was taken from
    #: What the job waited for, seconds: ``move<i>`` and ``capture<i>`` as the robot and camera
    #: workers reported them, ``reconstruct`` the round trip to the reconstruction worker (of the
    #: attempt that succeeded, with its wait for a free worker).
    durations_s: dict[str, float] = {}
    recording: str | None = None             # the job's Rerun .rrd; None: see recording_error
    recording_error: str | None = None       # why the job has no recording, if it has none
    #: The reconstruction worker that made this result, and on which attempt (see ``wire/keys.py``).
    worker: str | None = None
    attempts: Annotated[int, Field(ge=1)] = 1
    #: An adaptive scan's last word on how unsure its model is (``core_cy.next_view``); None otherwise.
    uncertainty: float | None = None


class JobEvent(Message):
    job_id: str
    #: As in :class:`JobStatus`: ``lifecycle``, or while it runs ``progress.activity``.
    state: JobState
    #: The job's ``ScanRequest.kind``: a listener tells a scan from the taking of backgrounds.
    kind: Literal["scan", "backgrounds"] = "scan"
    lifecycle: Lifecycle = Lifecycle.QUEUED
    progress: Progress | None = None
    view: int | None = None
    message: str
    time: float
    #: The result, in the published ``succeeded`` event only: a client waiting for the job
    #: needs no further query. (The stored history leaves it out; the result is stored once.)
    result: ScanResult | None = None


#: Random bytes in a job token (``secrets.token_urlsafe``): 32 bytes, 43 characters.
JOB_TOKEN_BYTES = 32
JobToken = Annotated[StrictStr, Field(min_length=16, max_length=256)]


class CancelRequest(ClientRequest):
    """The payload of a cancel (``robocell/<cell>/jobs/<id>/cancel``): the job's token, which only
    the client that submitted it holds (``JobStatus.token`` in the submit's answer)."""

    token: JobToken


class PickDecision(ClientRequest):
    """A client's decision on a pick that waits for one: go with grasp ``grasp`` of the result
    (or the daemon's choice, None), or not (``go`` false). Shows the job's token."""

    token: JobToken
    go: StrictBool
    grasp: Annotated[StrictInt, Field(ge=0)] | None = None


class ErrorReply(Message):
    """An error answer: its message, its ``kind`` (the class of the error, see ``wire/errors.py``:
    the receiver raises the same class) and the ``details`` that class carries (a refused move's
    ``limit``, a camera's HTTP ``status``)."""

    error: str
    kind: str = "RequestError"
    details: dict[str, Any] = {}


# --- workers -----------------------------------------------------------------------------------

class MoveRequest(Message):
    T_base_flange: Pose
    job_id: StrictStr | None = None


class MoveReply(Message):
    T_base_flange: Pose              # where the robot really is
    duration_s: float


class GripRequest(Message):
    """Close (``close``) or open the parallel-jaw gripper."""

    close: StrictBool                # JSON true or false: "yes" or 1 closes nothing
    job_id: StrictStr | None = None


class GripReply(Message):
    closed: bool
    holding: bool | None = None      # the fingers stopped on something; None: the gripper cannot tell
    width: float | None = None       # the opening between the pads now, metres, if known
    reason: str = ""                 # why it holds or not, where the robot knows (a simulator)
    duration_s: float


class RobotState(Message):
    T_base_flange: Pose
    moving: bool
    time: float


class CaptureRequest(Message):
    job_id: StrictStr | None = None
    view: Annotated[StrictInt, Field(ge=0)] | None = None


class CaptureInfo(Message):
    """Describes the JPEG payload of a capture reply."""

    encoding: Literal["image/jpeg"] = "image/jpeg"
    width: int
    height: int
    source: str                      # the camera's URL, credentials removed
    time: float
    duration_s: float


class CameraModel(BaseModel):
    model_config = ConfigDict(extra="forbid")
    K: Annotated[list[Annotated[list[float], Field(min_length=3, max_length=3)]], Field(min_length=3, max_length=3)]
    dist: list[float] | None = None


class Blob(BaseModel):
    """One part of a binary payload: how it is encoded, and how many bytes it takes."""

    model_config = ConfigDict(extra="forbid")
    encoding: str
    length: Annotated[int, Field(ge=0)]


#: A point cloud in a payload: x, y, z of each point as little-endian float32, point after point.
POINTS_ENCODING = "application/vnd.robocell.points+float32"


class ReconstructView(BaseModel):
    model_config = ConfigDict(extra="forbid")
    camera: CameraModel
    T_world_cam: Pose
    length: Annotated[int, Field(ge=1)]   # bytes of this view's JPEG in the payload
    #: Bytes of this view's background (the empty workspace from the same pose, a JPEG), right
    #: after its picture in the payload; 0: the view has none.
    background_length: Annotated[int, Field(ge=0)] = 0


class ReconstructRequest(Message):
    """The attachment of a reconstruction query; the payload is the views' JPEGs, concatenated, each
    followed by its background's where it has one (``ReconstructView.background_length``)."""

    job_id: str
    views: Annotated[list[ReconstructView], Field(min_length=2)]
    segmentation: dict | None = None        # as in scan.json
    support_plane: Row4 | None = None
    options: dict = {}                      # core_cy.reconstruct.Options fields
    #: The gripper to plan grasps for (DESIGN.md §3's GRIPPER.json), and how many; None: no grasps.
    gripper: dict[str, float] | None = None
    max_grasps: Annotated[int, Field(ge=1, le=50)] = 10
    #: Asks for the best next view among candidates, in the result's ``next_view``.
    next_view: NextViewQuery | None = None
    #: This attempt's id, ``<cell>/<job_id>/<attempt>``: unique on the network, listed in the
    #: worker's heartbeat while it works on it, and echoed in its reply.
    ticket: Annotated[str, Field(max_length=300)] | None = None


class NextViewCandidate(BaseModel):
    """A pose the camera could take next (reachable, inside the workspace), and its camera."""

    model_config = ConfigDict(extra="forbid")
    K: Annotated[list[Annotated[list[float], Field(min_length=3, max_length=3)]], Field(min_length=3, max_length=3)]
    T_world_cam: Pose


class NextViewQuery(BaseModel):
    """Asks the reconstruction for the best next view among ``candidates``."""

    model_config = ConfigDict(extra="forbid")
    candidates: Annotated[list[NextViewCandidate], Field(min_length=1, max_length=64)]


class NextViewAnswer(BaseModel):
    """The next view the model would gain most from (``core_cy.next_view.NextView``)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    candidate: int | None                   # the index among the query's candidates; None: none helps
    T_world_cam: Pose
    expected_gain: float
    uncertainty: float
    sure: bool                              # the model is sure: no view needed


class Reconstruction(BaseModel):
    """What the reconstruction found (DESIGN.md §1.8), in the bundle's units."""

    model_config = ConfigDict(extra="forbid")
    superquadric: Superquadric
    silhouette_iou: list[float]
    residual: float
    timings_ms: dict[str, float]
    centre: Point                           # the enclosing sphere the points started on
    radius: PositiveFloat
    grasps: list[Grasp] = []                # of the request's gripper, best first
    #: The model as parts (DESIGN.md §1.11), the object their union; empty from an older worker.
    parts: Annotated[list[Superquadric], Field(max_length=6)] = []
    next_view: NextViewAnswer | None = None  # when the request asked for one


class ReconstructReply(Message):
    """The attachment of a reconstruction reply; the payload is each view's silhouette (PNG, for
    the recording) and then the carved point cloud, as ``silhouettes`` and ``points`` describe them.

    A ``result`` with no ``error``, or an ``error`` (the core's verdict on the pictures) with no
    result.
    """

    job_id: str
    result: Reconstruction | None = None
    silhouettes: list[Blob] = []
    points: Blob | None = None
    error: str | None = None
    error_kind: str | None = None            # the core's class of that error (SilhouetteError, ...)
    worker: str = ""
    ticket: str | None = None               # the request's ticket

    @model_validator(mode="after")
    def _result_or_error(self) -> "ReconstructReply":
        if (self.result is None) == (self.error is None):
            raise ValueError("give exactly one of result and error")
        return self


class WorkerLoad(Message):
    """A reconstruction worker's heartbeat, and its answer on ``robocell/_pool/info/<worker>``."""

    worker: str
    capacity: Annotated[int, Field(ge=1)]   # its process pool's size: reconstructions at a time
    in_flight: Annotated[int, Field(ge=0)]  # requests received and not yet answered, from every cell
    tickets: list[str] = []                 # the tickets of those requests (of those that had one)
    answered: Annotated[int, Field(ge=0)] = 0   # requests answered since the worker started
    period_s: Annotated[float, Field(gt=0)]     # seconds between two heartbeats
    time: float                             # unix time, the worker's clock
    started: float                          # unix time the worker started


# --- cell status -------------------------------------------------------------------------------

class ReconstructorStatus(BaseModel):
    """One reconstruction worker as a cell daemon sees it."""

    model_config = ConfigDict(extra="forbid")
    worker: str
    capacity: int
    in_flight: int              # from every cell: the worker's last report plus what this daemon sent since
    in_flight_here: int         # of which this cell's
    tickets_here: list[str] = []    # the tickets of this cell's requests there, ``<cell>/<job_id>/<attempt>``
    healthy: bool               # false while its heartbeat is silent: it gets no work
    heartbeat_age_s: float | None   # since its last heartbeat; None: none heard yet
    sent: int = 0               # attempts this daemon sent it
    failed: int = 0             # of which failed: it died, hung, ran out of time or answered an error
    proven: bool = False        # one of its answers was checked against the pictures and found right
    refused: int = 0            # its answers that the check refused


class FailedJob(BaseModel):
    model_config = ConfigDict(extra="forbid")
    job_id: str
    error: str | None
    updated: float


class DiskUsage(BaseModel):
    """What the cell keeps in its run directory, bytes, and what its retention would free now
    (``cell/retention.py``)."""

    model_config = ConfigDict(extra="forbid")
    recordings: int
    pictures: int
    store: int                  # the job store with its WAL
    other: int
    free_on_disk: int | None = None       # what the run directory's file system has free
    recordings_to_free: int = 0
    pictures_to_free: int = 0
    jobs_to_prune: int = 0
    backgrounds: int = 0        # the backgrounds kept for later scans (``<run dir>/backgrounds``)
    backgrounds_to_free: int = 0


class CellStatus(Message):
    """The answer on ``robocell/<cell>/status``: the cell at a glance."""

    cell: str
    time: float
    started: float                          # when the daemon started
    workers: dict[str, bool]                # the cell's own workers (robot, camera): alive or not
    reconstructors: list[ReconstructorStatus]
    queued: int                             # jobs waiting for the robot
    max_queued: int                         # submits beyond this many waiting jobs are refused
    waiting_for_reconstructor: int          # jobs whose pictures are taken, waiting for a free worker
    jobs: dict[str, int]                    # every job in the store, by state
    recent_failures: list[FailedJob]        # newest first
    disk: DiskUsage | None = None           # the run directory, and what retention will free
