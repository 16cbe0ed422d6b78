"""Every KRL variable the bridges read or write, with its type and meaning, and the codes they carry.

This module is the one list: ``krl/config_dat_additions.txt`` declares exactly
the variables of :data:`GLOBALS` (a test parses it), ``krl/robocell.dat``
defines the command, status and error codes below under the same names, and
the simulator in ``workers.sim.kuka`` serves these and nothing else.

The handshake (one move)::

    bridge                                   KRL program (robocell.src)
    ------                                   --------------------------
    reads RC_CMD = 0, $STOPMESS, $PERI_RDY
    writes RC_TARGET, RC_OVERRIDE, RC_CMD_ID
    writes RC_CMD = PTP or LIN  ──────────▶  sees RC_CMD <> 0: RC_STATUS = MOVING
                                             checks the command; moves, or not
    polls RC_DONE_ID, RC_STATUS,   ◀──────── RC_ERROR, RC_STATUS = DONE or ERROR,
    RC_ERROR, $POS_ACT ...                   RC_DONE_ID = RC_CMD_ID, RC_CMD = 0

``RC_DONE_ID`` is written after ``RC_STATUS`` and ``RC_ERROR``, so a bridge that
reads ``RC_DONE_ID`` first and finds its own id can trust the other two.

The gripper takes the same handshake with ``RC_CMD`` = GRIP_CLOSE or GRIP_OPEN
(no target, no override): the program switches its output ``$OUT[GRIP_OUT]``,
waits at most ``GRIP_TIMEOUT`` for its input ``$IN[GRIP_IN]`` (TRUE: the
gripper holds a part) to follow, and leaves ``RC_GRIP_HELD`` (the input then)
and ``RC_GRIP_WAITED`` (how long it waited) before ``RC_DONE_ID``. The numbers
and the time-out are the program's own (robocell.dat); ``RC_GRIP_IN`` says which
input it is, so that a bridge can name it. A close the input does not confirm
is a miss (DONE, RC_GRIP_HELD FALSE); an open it does not confirm (the input
still says it holds) is ERROR GRIP_TIMEOUT.
Values travel as KRL text (``TRUE``, ``42``, ``{E6POS: X 1.0, ...}``).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Literal

__all__ = [
    "KrlVar", "Command", "Status", "ErrorCode", "ERROR_MESSAGES",
    "RC_CMD", "RC_CMD_ID", "RC_TARGET", "RC_OVERRIDE", "RC_STATUS", "RC_ERROR", "RC_DONE_ID",
    "RC_GRIP_HELD", "RC_GRIP_WAITED", "RC_GRIP_IN",
    "POS_ACT", "AXIS_ACT", "STOPMESS", "PERI_RDY", "GLOBALS", "SYSTEM", "ALL", "BY_NAME",
    "krl_text", "from_krl_text",
]

KrlType = Literal["INT", "REAL", "BOOL", "E6POS", "E6AXIS"]


@dataclass(frozen=True)
class KrlVar:
    """One KRL variable: its name on the controller, KRL type, who writes it, and what it means."""

    name: str
    type: KrlType
    #: "bridge" if the bridge writes it, "robot" if only the controller does.
    writer: Literal["bridge", "robot"]
    meaning: str


class Command(IntEnum):
    """Values of RC_CMD: what the bridge asks for. The program sets it back to NONE when finished."""

    NONE = 0
    PTP = 1  # axis-interpolated: fastest, the path between is not a straight line
    LIN = 2  # straight line of the flange
    GRIP_CLOSE = 3  # switch the gripper's output on, wait for its input to confirm a hold
    GRIP_OPEN = 4  # switch the gripper's output off, wait for its input to confirm it let go


class Status(IntEnum):
    """Values of RC_STATUS: what the program is doing."""

    IDLE = 0  # the program started and has taken no command yet
    MOVING = 1  # a command was taken: checking it, moving, or waiting for the gripper
    DONE = 2  # the last command finished at its target
    ERROR = 3  # the last command was refused; RC_ERROR says why


class ErrorCode(IntEnum):
    """Values of RC_ERROR, set by the program's own checks (robocell.src, CHECK_COMMAND)."""

    NONE = 0
    BAD_COMMAND = 1
    BAD_OVERRIDE = 2
    OUTSIDE_WORKSPACE = 3
    BAD_ORIENTATION = 4
    UNREACHABLE = 5
    GRIP_TIMEOUT = 6


ERROR_MESSAGES = {
    ErrorCode.NONE: "no error",
    ErrorCode.BAD_COMMAND: "the command is none of PTP, LIN, GRIP_CLOSE and GRIP_OPEN",
    ErrorCode.BAD_OVERRIDE: "the override is outside 1 % and the program's MAX_OVERRIDE",
    ErrorCode.OUTSIDE_WORKSPACE: "the target is outside the program's workspace box (robocell.dat WS_MIN/WS_MAX)",
    ErrorCode.BAD_ORIENTATION: "the flange would tilt more than the program's MAX_TILT from straight down",
    ErrorCode.UNREACHABLE: "no axis solution for the target: out of reach, singular or beyond an axis limit",
    ErrorCode.GRIP_TIMEOUT: "the gripper's input did not confirm that it let go within the program's GRIP_TIMEOUT",
}

# Written by the bridge. RC_CMD is written last: it is the trigger.
RC_CMD = KrlVar("RC_CMD", "INT", "bridge",
                "command: 0 none, 1 PTP, 2 LIN, 3 close, 4 open the gripper (Command); cleared by the program")
RC_CMD_ID = KrlVar("RC_CMD_ID", "INT", "bridge", "id of the command, 1..32767, echoed in RC_DONE_ID")
RC_TARGET = KrlVar("RC_TARGET", "E6POS", "bridge", "target pose of the flange in the robot base frame (mm, deg)")
RC_OVERRIDE = KrlVar("RC_OVERRIDE", "INT", "bridge", "program override for the move, percent ($OV_PRO)")
# Written by the program.
RC_STATUS = KrlVar("RC_STATUS", "INT", "robot", "what the program is doing (Status)")
RC_ERROR = KrlVar("RC_ERROR", "INT", "robot", "why the last command was refused (ErrorCode), 0 if it was not")
RC_DONE_ID = KrlVar("RC_DONE_ID", "INT", "robot", "RC_CMD_ID of the last command finished or refused")
RC_GRIP_HELD = KrlVar("RC_GRIP_HELD", "BOOL", "robot",
                      "the gripper's input $IN[GRIP_IN] as the last gripper command left it: TRUE holds a part")
RC_GRIP_WAITED = KrlVar("RC_GRIP_WAITED", "REAL", "robot",
                        "seconds the last gripper command waited for its input (GRIP_TIMEOUT if it never came)")
RC_GRIP_IN = KrlVar("RC_GRIP_IN", "INT", "robot", "the number of the gripper's input, GRIP_IN of robocell.dat")
# System variables of the KUKA System Software: read only, never declared by us.
POS_ACT = KrlVar("$POS_ACT", "E6POS", "robot", "actual pose of the current $TOOL in the current $BASE")
AXIS_ACT = KrlVar("$AXIS_ACT", "E6AXIS", "robot", "actual axis angles, degrees")
STOPMESS = KrlVar("$STOPMESS", "BOOL", "robot", "TRUE while a stop message is active (emergency stop, safety stop)")
PERI_RDY = KrlVar("$PERI_RDY", "BOOL", "robot", "TRUE while the drives are ready (switched on)")

#: The variables robocell declares in $config.dat, the program's interface.
GLOBALS = (RC_CMD, RC_CMD_ID, RC_TARGET, RC_OVERRIDE, RC_STATUS, RC_ERROR, RC_DONE_ID, RC_GRIP_HELD, RC_GRIP_WAITED,
           RC_GRIP_IN)
#: The system variables the bridges read.
SYSTEM = (POS_ACT, AXIS_ACT, STOPMESS, PERI_RDY)
ALL = GLOBALS + SYSTEM
BY_NAME = {var.name: var for var in ALL}


def krl_text(value: object) -> str:
    """A Python value as KRL text: booleans as TRUE/FALSE, numbers as digits, text as it is.

    Examples
    --------
    >>> krl_text(True), krl_text(3), krl_text(0.5), krl_text("{X 1.0}")
    ('TRUE', '3', '0.5', '{X 1.0}')
    """
    if isinstance(value, bool):
        return "TRUE" if value else "FALSE"
    if isinstance(value, float):
        return repr(value)
    return str(value).strip()


def from_krl_text(var_type: str, text: str) -> object:
    """KRL text as the Python value an OPC server takes for a variable of ``var_type``.

    Structures (E6POS, E6AXIS) stay text.

    Raises
    ------
    ValueError
        If the text is not a value of that type.

    Examples
    --------
    >>> from_krl_text("BOOL", "TRUE"), from_krl_text("INT", " 7 "), from_krl_text("REAL", "2.5")
    (True, 7, 2.5)
    """
    text = text.strip()
    if var_type == "BOOL":
        if text.upper() in ("TRUE", "1"):
            return True
        if text.upper() in ("FALSE", "0"):
            return False
        raise ValueError(f"not a KRL BOOL: {text!r}")
    if var_type == "INT":
        return int(text)
    if var_type == "REAL":
        return float(text)
    return text
