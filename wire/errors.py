"""Errors of robocell's shell: bundles, jobs, workers and transport.

::

    CellError (Exception)
    ├── BundleError        a scan bundle is missing, unreadable or invalid
    ├── ConfigError        the configuration file is missing or invalid
    ├── StoreError         the job store's database cannot be opened, read or written
    ├── TransportError     Zenoh could not carry a message
    │   ├── NoResponder        nobody answers on a key: the worker is not running
    │   ├── TransportTimeout   the answer did not come in time
    │   └── RemoteError        the other side answered with an error
    └── CameraError        a snapshot could not be grabbed from the camera
        ├── CameraAuthError        the camera refused the credentials (HTTP 401/403)
        ├── CameraResponseError    a bad status, no snapshot endpoint, or not a JPEG
        ├── CameraTimeout          the camera did not answer in time
        └── CameraConnectionError  no connection to the camera (refused, DNS, reset)

Errors of the reconstruction itself are ``core_cy.errors.CoreError``; the
reconstruction pool's (``AttemptFailed``, ``NoReconstructor``) live in
``cell/pool.py``, the KUKA bridges' (``KukaError``) in ``workers/kuka/errors.py``.
"""

from __future__ import annotations

__all__ = [
    "CellError", "BundleError", "ConfigError", "StoreError",
    "TransportError", "NoResponder", "TransportTimeout", "RemoteError",
    "CameraError", "CameraAuthError", "CameraResponseError", "CameraTimeout", "CameraConnectionError",
]


class CellError(Exception):
    """Base class of the shell's errors."""


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


class NoResponder(TransportError):
    """Nobody answers on the key: the worker or daemon behind it is not running."""


class TransportTimeout(TransportError):
    """The answer did not come within the time limit."""


class RemoteError(TransportError):
    """The other side received the message and answered with an error."""

