"""Errors of the KUKA bridges: connection, protocol, safety and motion.

::

    KukaError (cell.errors.CellError)
    ├── KukaConnectionError   no connection to KukaVarProxy or the OPC gateway, or it was lost
    ├── KukaTimeout           an answer, the program's acknowledgment or the end of a move came too late
    ├── KukaProtocolError     a malformed or unexpected message on the wire
    ├── KukaVariableError     the controller would not read or write a variable (unknown name, bad value)
    ├── MoveRefused           the bridge refused a move before writing anything: ``limit`` names the limit
    ├── ControllerBusy        the controller still holds a command (RC_CMD is not 0): nothing was written
    └── MoveFailed            the controller took the move but did not finish it
        ├── ControllerRefused     the KRL program refused the command: ``code`` is its error code
        │   └── Unreachable           ... because the pose is outside the arm's reach or axis limits
        ├── EmergencyStop         a stop message is active on the controller ($STOPMESS)
        └── DrivesOff             the drives are not ready ($PERI_RDY is FALSE)

Errors of the libraries underneath (``OSError`` from sockets, ``Pyro5.errors``,
the gateway's ``OPCError`` as ``opc.GatewayError``) are translated in one place per client:
``KvpClient._translated`` and ``OpcClient._translated``.
"""

from __future__ import annotations

from cell.errors import CellError

__all__ = [
    "KukaError", "KukaConnectionError", "KukaTimeout", "KukaProtocolError", "KukaVariableError",
    "MoveRefused", "ControllerBusy", "MoveFailed", "ControllerRefused", "Unreachable", "EmergencyStop", "DrivesOff",
]


class KukaError(CellError):
    """Base class of the KUKA bridges' errors."""


class KukaConnectionError(KukaError):
    """No connection to the bridge on the controller (refused, reset, closed, unknown host)."""


class KukaTimeout(KukaError):
    """A wait ran out: an answer on the wire, the KRL program taking a command, or a move ending."""


class KukaProtocolError(KukaError):
    """A message that does not follow the protocol: bad framing, wrong message id, unparsable value."""


class KukaVariableError(KukaError):
    """The controller answered, but would not read or write the variable (``name``)."""

    def __init__(self, message: str, *, name: str | None = None) -> None:
        super().__init__(message)
        self.name = name


class MoveRefused(KukaError):
    """The bridge refused the move before anything was written to the controller.

    ``limit`` is one of ``"workspace"``, ``"orientation"``, ``"override"``, ``"pose"``
    (the matrix is not a rigid transform) or ``"motion"`` (unknown motion type).
    """

    def __init__(self, message: str, *, limit: str) -> None:
        super().__init__(message)
        self.limit = limit


class ControllerBusy(KukaError):
    """The controller still holds a command: a move in progress, or a program stopped in the middle of one."""


class MoveFailed(KukaError):
    """The controller took the move but did not finish it."""


class ControllerRefused(MoveFailed):
    """The KRL program checked the command and refused it; ``code`` is its RC_ERROR value."""

    def __init__(self, message: str, *, code: int) -> None:
        super().__init__(message)
        self.code = code


class Unreachable(ControllerRefused):
    """The KRL program found no axis solution for the pose (reach, singularity or axis limits)."""


class EmergencyStop(MoveFailed):
    """A stop message is active on the controller: emergency stop or a safety stop."""


class DrivesOff(MoveFailed):
    """The drives are not ready: switched off, or not yet switched on."""
