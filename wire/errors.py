"""Errors of robocell's shell: bundles, jobs, workers and transport; and how an error crosses the wire.

::

    CellError (Exception)
    ├── BundleError        a scan bundle is missing, unreadable or invalid
    ├── ConfigError        the configuration file is missing or invalid
    ├── StoreError         the job store's database cannot be opened, read or written
    ├── TransportError     Zenoh could not carry a message
    │   ├── CredentialsRefused the router refused the session's user and password (or certificate)
    │   ├── LinkDown           the link to the router is down: nothing can be asked or answered
    │   ├── NoResponder        nobody answers on a key: the worker is not running
    │   │   └── AccessDenied       the router's access control does not let this user do it
    │   ├── TransportTimeout   the answer did not come in time
    │   └── RemoteError        the other side answered with an error
    ├── CameraError        a snapshot could not be grabbed from the camera
    │   ├── CameraAuthError        the camera refused the credentials (HTTP 401/403)
    │   ├── CameraResponseError    a bad status, no snapshot endpoint, or not a JPEG
    │   ├── CameraTimeout          the camera did not answer in time
    │   └── CameraConnectionError  no connection to the camera (refused, DNS, reset)
    └── RobotError         the robot refused or failed a move
        ├── MoveRefused        refused before moving: ``limit`` names the limit
        └── MoveFailed         the robot took the move but did not finish it
            ├── Unreachable        the pose is out of the arm's reach or axis limits
            ├── EmergencyStop      a stop is active on the controller
            └── DrivesOff          the drives are not ready

An error crosses the wire as an ``ErrorReply``: its message, its ``kind`` (the
class's name) and its :meth:`~CellError.details`. The receiver raises the same
class (:func:`from_reply`): a refused move arrives as ``MoveRefused`` with its
``limit``. A kind the receiver does not know (a backend's own, say) arrives as
the nearest class it does know, which the sender names in the reply's
``details["known_as"]``; anything else as ``RemoteError``.

Errors of the reconstruction itself are ``core_cy.errors.CoreError``; the
reconstruction pool's (``AttemptFailed``, ``NoReconstructor``) live in
``cell/pool.py``, the KUKA bridges' own (``KukaError``) in
``workers/robot/kuka/errors.py``.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "CellError", "BundleError", "ConfigError", "StoreError",
    "TransportError", "CredentialsRefused", "LinkDown", "NoResponder", "AccessDenied", "TransportTimeout",
    "RemoteError",
    "CameraError", "CameraAuthError", "CameraResponseError", "CameraTimeout", "CameraConnectionError",
    "RobotError", "MoveRefused", "MoveFailed", "Unreachable", "EmergencyStop", "DrivesOff",
    "wire_kind", "from_reply",
]


class CellError(Exception):
    """Base class of the shell's errors."""

    def details(self) -> dict[str, Any]:
        """What the error carries besides its message, as keyword arguments of its class."""
        return {}


class BundleError(CellError):
    """A scan bundle is missing, unreadable or does not follow DESIGN.md §3."""


class ConfigError(CellError):
    """The configuration file is missing, not TOML, or has an invalid field."""


class StoreError(CellError):
    """The job store's SQLite database cannot be opened, read or written, or holds bad data."""


class CameraError(CellError):
    """A snapshot could not be grabbed from the network camera.

    ``source`` is the camera's URL without credentials; ``status`` the HTTP
    status code when the camera answered, else None. (Not to be confused with
    ``core_cy.errors.CameraError``, a malformed camera matrix.)
    """

    def __init__(self, message: str, *, source: str | None = None, status: int | None = None) -> None:
        super().__init__(message)
        self.source = source
        self.status = status

    def details(self) -> dict[str, Any]:
        return {"source": self.source, "status": self.status}


class CameraAuthError(CameraError):
    """The camera refused the credentials, or asked for some and none were configured."""


class CameraResponseError(CameraError):
    """The camera answered, but not with a snapshot: a bad status, no endpoint, or not a JPEG."""


class CameraTimeout(CameraError):
    """The camera did not answer within the time-out."""


class CameraConnectionError(CameraError):
    """No connection to the camera: refused, unknown host, reset, or broken protocol."""


class TransportError(CellError):
    """Zenoh could not open a session, or carry a message."""


class CredentialsRefused(TransportError):
    """The router is there, but refused this session: its user name and password (or the router's
    certificate, which this side does not trust). Trying again cannot help."""


class LinkDown(TransportError):
    """The link to the Zenoh router is down (the router stopped, or the network): a query was not
    sent, or its answer cannot come. Zenoh reconnects by itself when the router is back."""


class NoResponder(TransportError):
    """Nobody answers on the key: the worker or daemon behind it is not running."""


class AccessDenied(NoResponder):
    """The router's access control does not let this session's user do what it asked (Zenoh drops
    a denied query, declaration or publication unanswered): the message says which role may."""


class TransportTimeout(TransportError):
    """The answer did not come within the time limit."""


class RemoteError(TransportError):
    """The other side received the message and answered with an error of a kind this side does
    not know (or a request it found wrong: kind ``RequestError``)."""

    def __init__(self, message: str, *, kind: str = "RemoteError") -> None:
        super().__init__(message)
        self.kind = kind


class RobotError(CellError):
    """The robot refused or failed a move."""


class MoveRefused(RobotError):
    """The move was refused before the robot moved.

    ``limit`` is one of ``"workspace"``, ``"orientation"``, ``"override"``, ``"pose"``
    (the matrix is not a rigid transform) or ``"motion"`` (unknown motion type).
    """

    def __init__(self, message: str, *, limit: str) -> None:
        super().__init__(message)
        self.limit = limit

    def details(self) -> dict[str, Any]:
        return {"limit": self.limit}


class MoveFailed(RobotError):
    """The robot took the move but did not finish it."""


class Unreachable(MoveFailed):
    """The robot found no axis solution for the pose (reach, singularity or axis limits)."""


class EmergencyStop(MoveFailed):
    """A stop message is active on the controller: emergency stop or a safety stop."""


class DrivesOff(MoveFailed):
    """The drives are not ready: switched off, or not yet switched on."""


def _known() -> dict[str, type[CellError]]:
    kinds: dict[str, type[CellError]] = {}
    stack: list[type[CellError]] = [CellError]
    while stack:
        cls = stack.pop()
        if cls.__module__ == __name__:
            kinds[cls.__name__] = cls
        stack.extend(cls.__subclasses__())
    return kinds


def wire_kind(exc: BaseException) -> tuple[str, dict[str, Any]]:
    """The ``kind`` and ``details`` of an ErrorReply that carries ``exc``.

    The kind is the error's own class; where that class is not one of this module's (a
    backend's own), ``details["known_as"]`` names the nearest one that is.
    """
    details = exc.details() if isinstance(exc, CellError) else {}
    known = next((cls for cls in type(exc).__mro__ if cls.__module__ == __name__), None)
    if known is not None and known is not type(exc):
        details = {**details, "known_as": known.__name__}
    return type(exc).__name__, details


def from_reply(message: str, kind: str, details: dict[str, Any]) -> CellError:
    """The error an ErrorReply stands for: the same class where this side knows it."""
    kinds = _known()
    cls = kinds.get(kind) or kinds.get(str(details.get("known_as")))
    if cls is None or cls in (CellError, RemoteError):
        return RemoteError(message, kind=kind)
    try:
        return cls(message, **{k: v for k, v in details.items() if k != "known_as"})
    except TypeError:  # details this side's class does not take
        return cls(message)

