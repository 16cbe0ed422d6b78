"""The cell's one configuration file (TOML), validated once into pydantic models.

Every field has a default that works out of the box on one machine in
simulation; ``robocell config`` prints the defaults as a starting file.
"""

from __future__ import annotations

import json
import os
import tomllib
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import AfterValidator, AliasChoices, Field, ValidationError, field_validator, model_validator

from . import keys
from .access import USER_NAME, access_control
from .backends import AxisCameraConfig, CameraConfig, RobotConfig, Section, SimRobotConfig
from .errors import ConfigError
from .messages import Point, Pose, ViewPlan, field_errors

__all__ = ["CellConfig", "Roles", "RetentionConfig", "load_config", "DEFAULT_HAND_EYE"]

# A camera 10 cm out along the flange's z axis, looking along it, rotated so that
# image "up" is the flange's x axis: a typical wrist mount.
DEFAULT_HAND_EYE = [[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.1], [0.0, 0.0, 0.0, 1.0]]


CellId = Annotated[str, Field(pattern=rf"^{keys.CELL_ID.pattern}$")]
UserName = Annotated[str, Field(pattern=rf"^{USER_NAME.pattern}$")]
# Where the router's users and their passwords are: without it, no session has a user to match a role.
_DICTIONARY_FILE = "transport/auth/usrpwd/dictionary_file"


class Roles(Section):
    """Zenoh users by role, for the router's access control (``wire.access``, deploy/README.md)."""

    #: The cells these users act in; by default the cell of this file (``cell_id``).
    cells: list[CellId] | None = None
    client: list[UserName] = []
    observer: list[UserName] = []
    daemon: list[UserName] = []
    robot: list[UserName] = []
    camera: list[UserName] = []
    #: Reconstruction workers serve the pool of every cell, whichever cells are named.
    reconstruct: list[UserName] = []


class ZenohConfig(Section):
    #: The router's endpoint: ``robocell router`` listens on it, every other process connects to it.
    router: str = "tcp/127.0.0.1:7447"
    #: Zenoh configuration keys (JSON5 key to value) for every session, e.g. the CA to trust.
    settings: dict[str, object] = {}
    #: Keys for the router's session only: its certificate and key, the users' dictionary file.
    router_settings: dict[str, object] = {}
    #: Zenoh user/password authentication; the password comes from ROBOCELL_ZENOH_PASSWORD.
    user: str | None = None
    #: For the router: who may do what (``[zenoh.roles]``, or ``[[zenoh.roles]]`` for other cells
    #: with users of their own). Empty: every session the router lets in may do everything.
    roles: list[Roles] = []

    @field_validator("roles", mode="before")
    @classmethod
    def _one_table_or_many(cls, value: object) -> object:
        return [value] if isinstance(value, dict) else value

    def client_settings(self) -> dict[str, object]:
        """What a client session (every process but the router) adds to its configuration.

        Raises
        ------
        ConfigError
            If ``user`` is set but ROBOCELL_ZENOH_PASSWORD is not (the router would refuse the
            session with nothing better than "unable to connect").
        """
        settings = dict(self.settings)
        if self.user is not None:
            password = os.environ.get("ROBOCELL_ZENOH_PASSWORD")
            if not password:
                raise ConfigError(f"zenoh.user is {self.user!r}, but ROBOCELL_ZENOH_PASSWORD, its password, is not set")
            settings["transport/auth/usrpwd/user"] = self.user
            settings["transport/auth/usrpwd/password"] = password
        return settings

    def router_session_settings(self, cell_id: str) -> dict[str, object]:
        """What the router's session adds to its configuration: with ``roles``, its access control
        (the roles of a table without ``cells`` are in ``cell_id``).

        Raises
        ------
        ConfigError
            If ``roles`` names users but the router has no users' dictionary to know them by.
        """
        settings = {**self.settings, **self.router_settings}
        users = self.users_by_role(cell_id)
        if users:
            if _DICTIONARY_FILE not in settings:
                raise ConfigError(f"zenoh.roles names users, but zenoh.router_settings has no {_DICTIONARY_FILE!r}: "
                                  f"the router could not tell who is who, and would refuse everyone")
            settings["access_control"] = access_control(users)
        return settings

    def users_by_role(self, cell_id: str) -> dict[str, dict[str, list[str]]]:
        """``roles`` as cell id -> role -> user names (empty without roles)."""
        users: dict[str, dict[str, list[str]]] = {}
        for table in self.roles:
            for cell in table.cells if table.cells is not None else [cell_id]:
                for role, names in table.model_dump(exclude={"cells"}).items():
                    users.setdefault(cell, {}).setdefault(role, []).extend(names)
        if not any(names for roles in users.values() for names in roles.values()):
            return {}
        return users


# The gripper's mounting: the grasp frame (DESIGN.md §3) 20 cm out along the flange's z axis,
# approaching along it (a gripper body of about 14 cm, then its fingers).
DEFAULT_FLANGE_GRASP = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.2], [0.0, 0.0, 0.0, 1.0]]


class GripperConfig(Section):
    """The cell's parallel-jaw gripper (DESIGN.md §3), metres, and where it sits on the flange."""

    max_opening: float = 0.085
    finger_length: float = 0.045
    finger_width: float = 0.02
    finger_thickness: float = 0.008
    pad_length: float = 0.02
    palm_width: float = 0.06
    #: The pads' coefficient of friction on the objects the cell picks.
    friction: float = 0.5
    #: The grasp frame in the flange frame (grasp-to-flange): a robot reaches a grasp with its
    #: flange at ``T_world_grasp @ inv(T_flange_grasp)``.
    T_flange_grasp: Pose = DEFAULT_FLANGE_GRASP

    @model_validator(mode="after")
    def _a_gripper(self) -> "GripperConfig":
        from robocell.core_cy.gripper import Gripper  # the one check of a gripper's dimensions

        Gripper.from_dict(self.dimensions())  # a GripperError is a ValueError: named by pydantic
        return self

    def dimensions(self) -> dict[str, float]:
        """The gripper of DESIGN.md §3 (GRIPPER.json), without its mounting."""
        return self.model_dump(exclude={"T_flange_grasp"})


class ScanConfig(Section):
    #: The table surface's height in the robot base frame (the support plane z = height).
    table_height: float = 0.0
    plan: ViewPlan = ViewPlan()
    #: How the reconstruction finds the object, as scan.json's ``segmentation``; None: ``auto``.
    segmentation: dict | None = None

    @field_validator("segmentation")
    @classmethod
    def _known_segmentation(cls, value: dict | None) -> dict | None:
        from .segmentation import core_segmentation

        core_segmentation(value)  # a ValueError naming the field
        return value


class ReconstructConfig(Section):
    #: Size of a reconstruction worker's process pool: its capacity, announced to the daemons.
    processes: Annotated[int, Field(ge=1, le=64)] = 1
    #: How many workers a job's reconstruction is tried on (one after another) before it fails.
    max_attempts: Annotated[int, Field(ge=1, le=10)] = 3
    n_points: Annotated[int, Field(ge=50)] = 1000
    inside_weight: Annotated[float, Field(gt=0)] | None = None
    cauchy_scale: Annotated[float, Field(gt=0)] | None = None


class SimConfig(Section):
    """The simulated scene the simulated camera renders; the camera serves at ``camera.url``."""

    shape: Literal["box", "cylinder", "ellipsoid", "rounded-box", "cup-stack", "lumpy"] = "box"
    size: Point = [0.04, 0.03, 0.05]
    position: Annotated[list[float], Field(min_length=2, max_length=2)] = [0.6, 0.0]
    yaw_deg: float = 20.0
    seed: int = 0
    #: Instead of the object above: a scene of the grasp benchmark (``workers/sim/grasp_set.py``), a
    #: family (box, cylinder, ellipsoid, rounded-box, plate, lying-cylinder, cups, mug,
    #: box-and-ball, l-boxes, too-big) drawn from ``seed``.
    grasp_scene: str | None = None
    #: How the object and its table look: ``printed`` (a label's print, an oak table, a lamp and its
    #: shadow: what the any-colour segmentation must find) or ``red`` (a red object on a pale table,
    #: unlit: a sixth of the rendering's CPU, which is what the test cells use).
    look: Literal["printed", "red"] = "printed"


class Timeouts(Section):
    move_s: Annotated[float, Field(gt=0)] = 60.0
    capture_s: Annotated[float, Field(gt=0)] = 15.0
    reconstruct_s: Annotated[float, Field(gt=0)] = 60.0
    #: The outage allowance: how long a job waits for a part that is away before it fails, naming
    #: it. A worker not running (or not answering, for the reconstruction pool), the link to the
    #: router down, a camera that does not answer: the step waits, then repeats its query (a move
    #: to an absolute pose and a snapshot are safe to repeat). ``worker_wait_s`` is its old name.
    outage_s: Annotated[float, Field(gt=0, validation_alias=AliasChoices("outage_s", "worker_wait_s"))] = 30.0
    #: A reconstruction worker whose heartbeat is silent this long is taken for hung: its jobs
    #: go to another worker (a hung Python process can keep its Zenoh liveliness alive).
    heartbeat_s: Annotated[float, Field(gt=0)] = 5.0


class RetentionConfig(Section):
    """How much of the run directory the cell keeps (``cell/retention.py``), applied while it runs:
    recordings, pictures left by jobs that ended, backgrounds, and ended jobs in the store, by age
    and by size.
    A job that has not ended keeps everything."""

    #: Recordings (``<run dir>/<job id>.rrd``) older than this are deleted.
    recordings_max_age_days: Annotated[float, Field(gt=0)] = 30.0
    #: The recordings together take at most this much; the oldest go first.
    recordings_max_mb: Annotated[float, Field(gt=0)] = 2048.0
    #: Pictures kept for a restart (``<run dir>/pictures/<job id>/``) of jobs that ended, older than this.
    pictures_max_age_days: Annotated[float, Field(gt=0)] = 1.0
    #: Ended jobs (their status, events and result) older than this leave the store.
    jobs_max_age_days: Annotated[float, Field(gt=0)] = 90.0
    #: At most this many ended jobs stay in the store; the oldest leave first.
    jobs_max_count: Annotated[int, Field(ge=1)] = 100_000
    #: Backgrounds (``<run dir>/backgrounds/``, ``robocell background``) older than this are deleted:
    #: the light of a room drifts, and an old background no longer shows the workspace as it is.
    backgrounds_max_age_days: Annotated[float, Field(gt=0)] = 7.0
    #: The backgrounds together take at most this much; the oldest go first.
    backgrounds_max_mb: Annotated[float, Field(gt=0)] = 256.0
    #: How often the daemon applies it, seconds.
    interval_s: Annotated[float, Field(gt=0)] = 600.0


def _run_dir(path: Path) -> Path:
    if path.exists() and not path.is_dir():
        raise ValueError(f"{str(path)!r} is a file, not a directory")
    return path


class CellConfig(Section):
    cell_id: CellId = "cell1"
    run_dir: Annotated[Path, AfterValidator(_run_dir)] = Path("runs")
    zenoh: ZenohConfig = ZenohConfig()
    robot: RobotConfig = SimRobotConfig()
    camera: CameraConfig = AxisCameraConfig()
    #: The camera's pose in the flange frame (camera-to-flange), from hand-eye calibration.
    T_flange_cam: Pose = DEFAULT_HAND_EYE
    scan: ScanConfig = ScanConfig()
    reconstruct: ReconstructConfig = ReconstructConfig()
    sim: SimConfig = SimConfig()
    timeouts: Timeouts = Timeouts()
    gripper: GripperConfig = GripperConfig()
    retention: RetentionConfig = RetentionConfig()
    #: Jobs that may wait in the queue; a submit beyond this is refused.
    max_queued: Annotated[int, Field(ge=1)] = 100

    @property
    def support_plane(self) -> list[float]:
        return [0.0, 0.0, 1.0, -self.scan.table_height]

    @property
    def hand_eye(self) -> np.ndarray:
        return np.asarray(self.T_flange_cam, dtype=np.float64)


def load_config(path: str | Path | None) -> CellConfig:
    """Read a TOML (or, as ``robocell up`` writes for its children, JSON) file; ``None`` gives the defaults.

    Raises
    ------
    ConfigError
        If the file is missing, not TOML, or a field is invalid (named in the message).
    """
    if path is None:
        return CellConfig()
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
        data = json.loads(text) if path.suffix == ".json" else tomllib.loads(text)
    except FileNotFoundError:
        raise ConfigError(f"configuration file {str(path)!r} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read configuration file {str(path)!r}: {exc}") from exc
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(f"{path}: not valid {'JSON' if path.suffix == '.json' else 'TOML'}: {exc}") from exc
    try:
        return CellConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(f"{path}: {field_errors(exc)}") from exc
