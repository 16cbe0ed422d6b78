"""Errors of the KUKA bridges: connection, protocol, safety and motion.

::

    KukaError (wire.errors.CellError)
    ├── KukaConnectionError   no connection to KukaVarProxy or the OPC gateway, or it was lost
    ├── KukaTimeout           an answer, the program's acknowledgment or the end of a move came too late
    ├── KukaProtocolError     a malformed or unexpected message on the wire
    ├── KukaVariableError     the controller would not read or write a variable (unknown name, bad value)
    ├── ControllerBusy        the controller still holds a command (RC_CMD is not 0): nothing was written
    └── GripperTimeout        the gripper's input did not confirm that it let go (a ``wire.errors.RobotError``)

    wire.errors.MoveRefused   the bridge refused a move before writing anything: ``limit`` names the limit
    wire.errors.MoveFailed    the controller took the move but did not finish it
    ├── ControllerRefused         the KRL program refused the command: ``code`` is its error code
    │   └── Unreachable               ... because the pose is outside the arm's reach or axis limits
    │                                 (also a ``wire.errors.Unreachable``)
    ├── wire.errors.EmergencyStop a stop message is active on the controller ($STOPMESS)
    └── wire.errors.DrivesOff     the drives are not ready ($PERI_RDY is FALSE)

The robot errors every robot shares are ``wire.errors``' own, so that they keep their
class across the wire; the rest are the bridge's. Errors of the libraries underneath
(``OSError`` from sockets, ``Pyro5.errors``, the gateway's ``OPCError`` as ``opc.GatewayError``)
are translated in one place per client: ``KvpClient._translated`` and ``OpcClient._translated``.
"""

from __future__ import annotations

from typing import Any

from robocell.wire import errors
from robocell.wire.errors import CellError, MoveFailed, RobotError

__all__ = [
    "KukaError", "KukaConnectionError", "KukaTimeout", "KukaProtocolError", "KukaVariableError", "ControllerBusy",
    "GripperTimeout", "ControllerRefused", "Unreachable",
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


class ControllerBusy(KukaError):
    """The controller still holds a command: a move in progress, or a program stopped in the middle of one."""


class _ProgramError(CellError):
    """An error the KRL program reported: ``code`` is its RC_ERROR value."""

    def __init__(self, message: str, *, code: int) -> None:
        super().__init__(message)
        self.code = code

    def details(self) -> dict[str, Any]:
        return {"code": self.code}


class GripperTimeout(_ProgramError, KukaError, RobotError):
    """The KRL program opened the gripper, but its input still said it held a part after the
    program's GRIP_TIMEOUT (RC_ERROR GRIP_TIMEOUT): the part may still be in the gripper."""


class ControllerRefused(_ProgramError, MoveFailed):
    """The KRL program checked the command and refused it; ``code`` is its RC_ERROR value."""


class Unreachable(ControllerRefused, errors.Unreachable):
    """The KRL program found no axis solution for the pose (reach, singularity or axis limits)."""
