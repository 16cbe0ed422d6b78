"""The Zenoh key expressions of robocell: the wire contract (also in README.md).

Everything of one cell lives under ``robocell/<cell-id>/``; the reconstruction
pool, shared by every cell on the network, under ``robocell/_pool/``. Cell ids
cannot start with ``_``, so the two never meet.
"""

from __future__ import annotations

__all__ = [
    "submit", "jobs", "job", "result", "cancel", "events", "robot_move", "robot_state",
    "camera_capture", "alive", "reconstructor", "reconstructor_alive", "RECONSTRUCTORS_ALIVE",
]

ROOT = "robocell"
POOL = f"{ROOT}/_pool"


def submit(cell: str) -> str:
    """Query with a ScanRequest; the reply is the new (or, for a repeated request_id, existing) JobStatus."""
    return f"{ROOT}/{cell}/submit"


def jobs(cell: str) -> str:
    """Query (parameters ``state=queued,moving;limit=20``); the reply is a JSON list of JobStatus."""
    return f"{ROOT}/{cell}/jobs"


def job(cell: str, job_id: str) -> str:
    """Query; the reply is the job's JobStatus."""
    return f"{ROOT}/{cell}/jobs/{job_id}"


def result(cell: str, job_id: str) -> str:
    """Query; the reply is the job's ScanResult once it succeeded."""
    return f"{ROOT}/{cell}/jobs/{job_id}/result"


def cancel(cell: str, job_id: str) -> str:
    """Query; cancels the job and replies with its JobStatus."""
    return f"{ROOT}/{cell}/jobs/{job_id}/cancel"


def events(cell: str, job_id: str = "*") -> str:
    """Publications of JobEvent, one per state change or step of the job."""
    return f"{ROOT}/{cell}/events/{job_id}"


def robot_move(cell: str) -> str:
    """Query with a MoveRequest; replies with a MoveReply once the robot is there."""
    return f"{ROOT}/{cell}/robot/move"


def robot_state(cell: str) -> str:
    """Publications of RobotState while the robot moves; also a query for the current state."""
    return f"{ROOT}/{cell}/robot/state"


def camera_capture(cell: str) -> str:
    """Query with a CaptureRequest; the reply payload is the JPEG (encoding image/jpeg),
    its attachment the CaptureInfo JSON."""
    return f"{ROOT}/{cell}/camera/capture"


def alive(cell: str, part: str = "*") -> str:
    """Liveliness tokens of a cell's daemon, robot and camera workers."""
    return f"{ROOT}/{cell}/alive/{part}"


def reconstructor(worker_id: str) -> str:
    """Query with a ReconstructRequest attachment and the views' JPEGs, concatenated, as payload;
    the reply is a ReconstructReply."""
    return f"{POOL}/reconstruct/{worker_id}"


def reconstructor_alive(worker_id: str) -> str:
    """Liveliness token of a reconstruction worker."""
    return f"{POOL}/alive/{worker_id}"


RECONSTRUCTORS_ALIVE = f"{POOL}/alive/*"
