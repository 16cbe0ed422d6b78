"""The configuration each backend contributes: ``[robot]`` and ``[camera]`` are discriminated unions.

``[robot] backend`` picks the robot: ``sim`` (the simulated robot) or ``kuka``
(a KUKA controller, over KukaVarProxy or an OpenOPC gateway: ``[robot.kuka]
protocol``). ``[camera] backend`` picks the camera: ``axis`` (an Axis network
camera over VAPIX, or the simulated one that ``robocell sim camera`` serves) or
``sim`` (the camera worker renders the ``[sim]`` scene itself, from the robot's
pose). A tag left out takes the first choice, so a file written before the
unions existed reads as it did. A new backend adds its model here and to its
union, and names the function that makes it in :data:`BACKENDS`; the shared
configuration (``wire.config``) never imports a worker, and a worker imports a
backend (a simulator, say) only when the configuration names it
(:func:`load_backend`).
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from typing import Annotated, Any, Literal, Union
from urllib.parse import urlsplit

from pydantic import (AfterValidator, BaseModel, ConfigDict, Discriminator, Field, SecretStr, Tag,
                      field_serializer, model_validator)

from .errors import ConfigError
from .messages import Point, Pose

__all__ = [
    "Section", "Workspace", "SimRobotConfig", "KukaKvpConfig", "KukaOpcConfig", "KukaRobotConfig", "RobotConfig",
    "AxisCameraConfig", "SimCameraConfig", "CameraConfig", "SIM_OPC_SERVER", "BACKENDS", "load_backend",
]

#: What makes each backend, by part and name: ``module:function``, the function taking the cell's
#: configuration (and, for a camera, the worker's transport). Imported only when named.
BACKENDS: dict[tuple[str, str], str] = {
    ("robot", "sim"): "robocell.workers.sim.backends:make_robot",
    ("robot", "kuka"): "robocell.workers.robot.kuka.factory:make_robot",
    ("camera", "sim"): "robocell.workers.sim.backends:make_camera",
    ("camera", "axis"): "robocell.workers.camera.axis_factory:make_camera",
}


def load_backend(part: str, name: str) -> Callable[..., Any]:
    """The function that makes ``part``'s backend ``name`` (see :data:`BACKENDS`), imported now.

    Raises
    ------
    ConfigError
        If there is no such backend.
    """
    where = BACKENDS.get((part, name))
    if where is None:
        known = ", ".join(n for p, n in BACKENDS if p == part)
        raise ConfigError(f"[{part}] backend = {name!r}: no such backend (known: {known})")
    module, _, function = where.partition(":")
    return getattr(importlib.import_module(module), function)


#: The OPC server name the simulated gateway answers to.
SIM_OPC_SERVER = "robocell.KukaSim"


class Section(BaseModel):
    """A section of the configuration file: strict, and no NaN or infinity (TOML has both)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


def _tagged(tag: str, models: tuple[type[BaseModel], ...]) -> Discriminator:
    """The discriminator of a union of ``models`` on the field ``tag``: the first model where the
    file leaves the tag out. Each member is tagged ``backend=kuka`` (say): an error's location
    names the tag so, and ``messages.field_errors`` leaves it out of the field's name."""
    values = [model.model_fields[tag].default for model in models]

    def discriminator(value: Any) -> str:
        chosen = value.get(tag, values[0]) if isinstance(value, dict) else getattr(value, tag, values[0])
        return f"{tag}={chosen}"

    expected = " or ".join(repr(v) for v in values)
    return Discriminator(discriminator, custom_error_type="backend_unknown",
                         custom_error_message=f"{tag} must be {expected}")


# --- robots ------------------------------------------------------------------------------------

class Workspace(Section):
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


class _Robot(Section):
    """What every robot backend has: where it rests, where it may go, how often it reports."""

    home: Pose = [[1.0, 0.0, 0.0, 0.4], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.6], [0.0, 0.0, 0.0, 1.0]]
    workspace: Workspace = Workspace()
    #: How often the robot worker publishes its pose while moving, Hz.
    publish_rate_hz: Annotated[float, Field(gt=0, le=200)] = 20.0


class SimRobotConfig(_Robot):
    """The simulated robot (``workers.sim.robot``)."""

    backend: Literal["sim"] = "sim"
    #: Linear speed, m/s; 0 moves instantly.
    speed: Annotated[float, Field(ge=0)] = 0.5
    #: Rotation speed, degrees/s; 0 rotates instantly.
    rotation_speed_deg: Annotated[float, Field(ge=0)] = 180.0
    #: If set, every move takes exactly this long, seconds, whatever its length (speeds are
    #: then ignored): for benchmarks and tests of the cell's timing.
    move_time_s: Annotated[float, Field(ge=0)] | None = None


class _Kuka(Section):
    """How the robot worker reaches a KUKA controller and what it lets it do."""

    #: The controller (kvp) or the gateway machine (opc).
    host: str = "127.0.0.1"
    #: Connecting, seconds.
    connect_timeout_s: Annotated[float, Field(gt=0, le=60)] = 3.0
    #: One read or write, seconds.
    request_timeout_s: Annotated[float, Field(gt=0, le=60)] = 2.0
    #: How long the KRL program may take to pick up a command before the bridge withdraws it, seconds.
    ack_timeout_s: Annotated[float, Field(gt=0, le=60)] = 2.0
    #: The longest a move may take, seconds.
    move_timeout_s: Annotated[float, Field(gt=0, le=600)] = 60.0
    #: The longest a gripper command may take, seconds: more than the program's own GRIP_TIMEOUT
    #: (krl/robocell.dat, which also sets the gripper's output and input).
    grip_timeout_s: Annotated[float, Field(gt=0, le=600)] = 10.0
    #: Time between polls of the controller during a move, seconds (also the progress rate).
    poll_period_s: Annotated[float, Field(gt=0, le=5)] = 0.05
    #: Program override used for moves, percent.
    override: Annotated[int, Field(ge=1, le=100)] = 20
    #: The highest override the bridge will ever send, percent; a higher one is refused.
    max_override: Annotated[int, Field(ge=1, le=100)] = 30
    #: Motion type of a move unless the caller asks for another.
    motion: Literal["ptp", "lin"] = "ptp"
    #: How far the reached pose may be from the target before the move counts as failed, mm and degrees.
    reached_tolerance_mm: Annotated[float, Field(gt=0)] = 1.0
    reached_tolerance_deg: Annotated[float, Field(gt=0)] = 0.5

    @model_validator(mode="after")
    def _override_within_limit(self) -> "_Kuka":
        if self.override > self.max_override:
            raise ValueError(f"override {self.override} % is above max_override {self.max_override} %")
        return self


class KukaKvpConfig(_Kuka):
    """KukaVarProxy on the controller (TCP)."""

    protocol: Literal["kvp"] = "kvp"
    port: Annotated[int, Field(ge=1, le=65535)] = 7000


class KukaOpcConfig(_Kuka):
    """An OPC DA server on the controller, reached through an OpenOPC gateway (Pyro5)."""

    protocol: Literal["opc"] = "opc"
    port: Annotated[int, Field(ge=1, le=65535)] = 7766
    #: The OPC DA server's ProgID on the gateway machine (as the gateway's ``servers()`` lists it).
    opc_server: str = SIM_OPC_SERVER
    #: The host of the OPC DA server, as the gateway sees it.
    opc_host: str = "localhost"
    #: Put before every KRL variable name to make the OPC item id (server-specific, often empty).
    opc_item_prefix: str = ""


KukaConfig = Annotated[Union[Annotated[KukaKvpConfig, Tag("protocol=kvp")],
                             Annotated[KukaOpcConfig, Tag("protocol=opc")]],
                       _tagged("protocol", (KukaKvpConfig, KukaOpcConfig))]


class KukaRobotConfig(_Robot):
    """A KUKA arm running ``krl/robocell.src`` (``workers.robot.kuka``)."""

    backend: Literal["kuka"] = "kuka"
    kuka: KukaConfig = KukaKvpConfig()


RobotConfig = Annotated[Union[Annotated[SimRobotConfig, Tag("backend=sim")],
                              Annotated[KukaRobotConfig, Tag("backend=kuka")]],
                        _tagged("backend", (SimRobotConfig, KukaRobotConfig))]


# --- cameras -----------------------------------------------------------------------------------

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


Matrix3 = Annotated[list[Annotated[list[float], Field(min_length=3, max_length=3)]], Field(min_length=3, max_length=3)]


class _Camera(Section):
    """What every camera backend has: its pictures' size and its calibration."""

    resolution: tuple[Annotated[int, Field(gt=0)], Annotated[int, Field(gt=0)]] = (640, 480)
    K: Matrix3 = [[600.0, 0.0, 319.5], [0.0, 600.0, 239.5], [0.0, 0.0, 1.0]]
    dist: Annotated[list[float] | None, AfterValidator(_distortion)] = None


class AxisCameraConfig(_Camera):
    """An Axis network camera's VAPIX snapshot endpoint (``workers.camera.axis``)."""

    backend: Literal["axis"] = "axis"
    url: Annotated[str, AfterValidator(_camera_url)] = "http://127.0.0.1:8080"
    username: str | None = None
    #: Prefer the environment variable ROBOCELL_CAMERA_PASSWORD to writing it here. Never written
    #: out: ``robocell config`` and the run directory's copy show null.
    password: SecretStr | None = None
    auth: Literal["digest", "basic"] = "digest"
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


class SimCameraConfig(_Camera):
    """The camera worker renders the ``[sim]`` scene itself, from where the robot stands
    (``workers.sim.camera``): no HTTP server, no network camera."""

    backend: Literal["sim"] = "sim"
    #: JPEG quality of the rendered pictures, 1-100.
    jpeg_quality: Annotated[int, Field(ge=1, le=100)] = 90


CameraConfig = Annotated[Union[Annotated[AxisCameraConfig, Tag("backend=axis")],
                               Annotated[SimCameraConfig, Tag("backend=sim")]],
                         _tagged("backend", (AxisCameraConfig, SimCameraConfig))]
