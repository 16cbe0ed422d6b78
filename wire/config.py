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
from urllib.parse import urlsplit

import numpy as np
from pydantic import (AfterValidator, BaseModel, ConfigDict, Field, SecretStr, ValidationError, field_serializer,
                      model_validator)

from workers.robot.kuka.config import KukaConfig

from .errors import ConfigError
from .messages import Point, Pose, ViewPlan, field_errors

__all__ = ["CellConfig", "load_config", "DEFAULT_HAND_EYE"]

# A camera 10 cm out along the flange's z axis, looking along it, rotated so that
# image "up" is the flange's x axis: a typical wrist mount.
DEFAULT_HAND_EYE = [[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.1], [0.0, 0.0, 0.0, 1.0]]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)  # TOML has nan and inf


class ZenohConfig(_Section):
    #: The router's endpoint: ``robocell router`` listens on it, every other process connects to it.
    router: str = "tcp/127.0.0.1:7447"
    #: Zenoh configuration keys (JSON5 key to value) for every session, e.g. the CA to trust.
    settings: dict[str, object] = {}
    #: Keys for the router's session only: its certificate and key, the users' dictionary file.
    router_settings: dict[str, object] = {}
    #: Zenoh user/password authentication; the password comes from ROBOCELL_ZENOH_PASSWORD.
    user: str | None = None

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

    def router_session_settings(self) -> dict[str, object]:
        """What the router's session adds to its configuration."""
        return {**self.settings, **self.router_settings}


class Workspace(_Section):
    """The box the flange may move in (robot base frame, metres) and the tilt it may take."""

    min: Point = [0.1, -0.7, 0.05]
    max: Point = [1.0, 0.7, 1.0]
    #: Largest angle between the flange's z axis and straight down, degrees.
    max_tilt_deg: Annotated[float, Field(gt=0, le=180)] = 80.0

    @model_validator(mode="after")
    def _ordered(self) -> "Workspace":
        if any(lo >= hi for lo, hi in zip(self.min, self.max)):
            raise ValueError("workspace min must be below max on every axis")
        return self


class RobotConfig(_Section):
    #: ``sim``: the simulated robot; ``kuka``: a KUKA controller through the bridge in ``[robot.kuka]``.
    backend: Literal["sim", "kuka"] = "sim"
    kuka: KukaConfig = KukaConfig()
    #: Linear speed of the simulated robot, m/s; 0 moves instantly.
    speed: Annotated[float, Field(ge=0)] = 0.5
    #: Rotation speed of the simulated robot, degrees/s; 0 rotates instantly.
    rotation_speed_deg: Annotated[float, Field(ge=0)] = 180.0
    #: If set, every move of the simulated robot takes exactly this long, seconds, whatever its
    #: length (speeds are then ignored): for benchmarks and tests of the cell's timing.
    move_time_s: Annotated[float, Field(ge=0)] | None = None
    home: Pose = [[1.0, 0.0, 0.0, 0.4], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.6], [0.0, 0.0, 0.0, 1.0]]
    workspace: Workspace = Workspace()
    #: How often the robot worker publishes its pose while moving, Hz.
    publish_rate_hz: Annotated[float, Field(gt=0, le=200)] = 20.0


def _camera_url(url: str) -> str:
    # The URL is shown in logs and messages and stored in the run directory: no credentials in it.
    parts = urlsplit(url)
    if parts.username is not None or parts.password is not None:
        raise ValueError("no user or password in the URL: put the user in camera.username and the password "
                         "in ROBOCELL_CAMERA_PASSWORD")
    try:
        parts.port  # raises on a bad port
    except ValueError:  # not shown: what looks like a port may be a password with a "/" in it
        raise ValueError("its port is not a number from 0 to 65535") from None
    if parts.scheme not in ("http", "https") or not parts.hostname:
        shown = repr(url) if "@" not in url else "a URL with an @ in it (a password?)"
        raise ValueError(f"must be http:// or https:// with a host, got {shown}")
    return url


def _distortion(dist: list[float] | None) -> list[float] | None:
    if dist is not None and len(dist) not in (4, 5, 8, 12, 14):
        raise ValueError(f"OpenCV takes 4, 5, 8, 12 or 14 distortion coefficients, got {len(dist)}")
    return dist


class CameraConfig(_Section):
    url: Annotated[str, AfterValidator(_camera_url)] = "http://127.0.0.1:8080"
    resolution: tuple[Annotated[int, Field(gt=0)], Annotated[int, Field(gt=0)]] = (640, 480)
    username: str | None = None
    #: Prefer the environment variable ROBOCELL_CAMERA_PASSWORD to writing it here. Never written
    #: out: ``robocell config`` and the run directory's copy show null.
    password: SecretStr | None = None
    auth: Literal["digest", "basic"] = "digest"
    K: Annotated[list[Annotated[list[float], Field(min_length=3, max_length=3)]], Field(min_length=3, max_length=3)] \
        = [[600.0, 0.0, 319.5], [0.0, 600.0, 239.5], [0.0, 0.0, 1.0]]
    dist: Annotated[list[float] | None, AfterValidator(_distortion)] = None
    timeout_s: Annotated[float, Field(gt=0)] = 3.0
    retries: Annotated[int, Field(ge=0, le=10)] = 2
    #: HTTPS certificate check: true (the system's CAs), false (none: only on a closed network),
    #: or the path of a CA bundle that signed the camera's certificate.
    verify: bool | str = True
    #: Axis JPEG compression 0-100 (higher: smaller files, more artefacts); None: the camera's default.
    compression: Annotated[int, Field(ge=0, le=100)] | None = None

    @field_serializer("password")
    def _unwritten(self, password: SecretStr | None) -> None:
        return None

    def resolved_password(self) -> str | None:
        from_env = os.environ.get("ROBOCELL_CAMERA_PASSWORD")
        if from_env:
            return from_env
        return self.password.get_secret_value() if self.password else None

    def credentials(self) -> tuple[str | None, str | None]:
        """(user, password) for the camera, or (None, None) without a user.

        Raises
        ------
        ConfigError
            If a user is set but no password (neither ROBOCELL_CAMERA_PASSWORD nor camera.password).
        """
        if self.username is None:
            return None, None
        password = self.resolved_password()
        if not password:
            raise ConfigError(f"camera.username is {self.username!r}, but it has no password: set "
                              f"ROBOCELL_CAMERA_PASSWORD (or camera.password)")
        return self.username, password


class ScanConfig(_Section):
    #: The table surface's height in the robot base frame (the support plane z = height).
    table_height: float = 0.0
    plan: ViewPlan = ViewPlan()


class ReconstructConfig(_Section):
    #: Size of a reconstruction worker's process pool: its capacity, announced to the daemons.
    processes: Annotated[int, Field(ge=1, le=64)] = 1
    #: How many workers a job's reconstruction is tried on (one after another) before it fails.
    max_attempts: Annotated[int, Field(ge=1, le=10)] = 3
    n_points: Annotated[int, Field(ge=50)] = 1000
    inside_weight: Annotated[float, Field(gt=0)] | None = None
    cauchy_scale: Annotated[float, Field(gt=0)] | None = None


class SimConfig(_Section):
    """The simulated scene the simulated camera renders; the camera serves at ``camera.url``."""

    shape: Literal["box", "cylinder", "ellipsoid", "rounded-box", "cup-stack", "lumpy"] = "box"
    size: Point = [0.04, 0.03, 0.05]
    position: Annotated[list[float], Field(min_length=2, max_length=2)] = [0.6, 0.0]
    yaw_deg: float = 20.0
    seed: int = 0


class Timeouts(_Section):
    move_s: Annotated[float, Field(gt=0)] = 60.0
    capture_s: Annotated[float, Field(gt=0)] = 15.0
    reconstruct_s: Annotated[float, Field(gt=0)] = 60.0
    #: How long a job waits for a missing worker before failing.
    worker_wait_s: Annotated[float, Field(gt=0)] = 10.0
    #: A reconstruction worker whose heartbeat is silent this long is taken for hung: its jobs
    #: go to another worker (a hung Python process can keep its Zenoh liveliness alive).
    heartbeat_s: Annotated[float, Field(gt=0)] = 5.0


def _run_dir(path: Path) -> Path:
    if path.exists() and not path.is_dir():
        raise ValueError(f"{str(path)!r} is a file, not a directory")
    return path


class CellConfig(_Section):
    cell_id: Annotated[str, Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$")] = "cell1"
    run_dir: Annotated[Path, AfterValidator(_run_dir)] = Path("runs")
    zenoh: ZenohConfig = ZenohConfig()
    robot: RobotConfig = RobotConfig()
    camera: CameraConfig = CameraConfig()
    #: The camera's pose in the flange frame (camera-to-flange), from hand-eye calibration.
    T_flange_cam: Pose = DEFAULT_HAND_EYE
    scan: ScanConfig = ScanConfig()
    reconstruct: ReconstructConfig = ReconstructConfig()
    sim: SimConfig = SimConfig()
    timeouts: Timeouts = Timeouts()
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
