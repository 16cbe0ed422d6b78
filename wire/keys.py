"""The Zenoh key expressions of robocell: the wire contract (also in README.md).

Everything of one cell lives under ``robocell/<cell-id>/``; the reconstruction
pool, shared by every cell on the network, under ``robocell/_pool/``. Cell ids
cannot start with ``_``, so the two never meet.

The reconstruction pool
-----------------------
A reconstruction worker ``<worker>`` (an id unique on the network) declares:

- ``robocell/_pool/alive/<worker>``: its liveliness token, for as long as its
  session lives. This is membership: a worker is in the pool while its token
  is there. Zenoh withdraws the token at once when the process dies, and
  after the worker's lease (3 s) when its host or network freezes.
- ``robocell/_pool/heartbeat/<worker>``: a ``WorkerLoad`` publication every
  :data:`HEARTBEAT_PERIOD_S` seconds, sent from the worker's event loop, and
  whenever its load changes (at once, or :data:`HEARTBEAT_CHANGE_GAP_S` after
  the previous one, whichever is later). This is health: a worker whose event
  loop hangs keeps its token (Zenoh's own threads keep the lease alive) but
  falls silent here. It is also the load: ``capacity`` (the worker's process
  pool size) and ``in_flight`` (requests received and not yet answered, from
  every cell), with the ``tickets`` of those requests.
- ``robocell/_pool/info/<worker>``: a query answered with the same ``WorkerLoad``,
  for whoever cannot wait for the next heartbeat (a daemon that has just seen
  the worker's token).
- ``robocell/_pool/reconstruct/<worker>``: the work itself (below).

Every cell daemon watches all of these and sends each reconstruction to the
live, healthy worker with the lowest ``in_flight / capacity`` that has a free
slot (load = what the worker last reported, plus what the daemon sent since);
ties go to the worker used least recently; when every slot is taken, jobs
wait, oldest first. A worker whose token goes, or whose heartbeat is silent
for ``timeouts.heartbeat_s``, loses its requests: they are sent to another
worker, each job at most ``reconstruct.max_attempts`` times. An attempt that
outlasts ``timeouts.reconstruct_s``, or that the worker answers with an error
reply, counts as failed too (a ReconstructReply whose ``error`` is the core's
verdict on the pictures fails the job at once). The answer of an abandoned
attempt, should it come, is ignored.

Each attempt carries a ``ticket``, ``<cell>/<job_id>/<attempt>``, unique on the
network; the worker lists the tickets it holds in its heartbeat and echoes the
ticket in its reply.
"""

from __future__ import annotations

import re

__all__ = [
    "submit", "jobs", "job", "result", "cancel", "events", "robot_move", "robot_grip", "robot_state",
    "camera_capture", "alive", "status", "reconstructor", "reconstructor_alive", "reconstructor_info",
    "reconstructor_heartbeat", "ticket", "CELL_ID", "WORKER_ID", "safe_worker_id", "RECONSTRUCTORS_ALIVE", "RECONSTRUCTORS_HEARTBEAT", "HEARTBEAT_PERIOD_S",
    "HEARTBEAT_CHANGE_GAP_S",
]

#: The Rerun application id of every job's recording; its recording id is the job's id, so that
#: what several processes log of one job is one recording (Rerun's shared recordings).
RECORDING_APPLICATION_ID = "robocell"
ROOT = "robocell"
POOL = f"{ROOT}/_pool"
#: What a cell id must match: one key chunk, never starting with "_" (the pool's keys do).
CELL_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")


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
    """Query; the reply is the job's ScanResult once it succeeded. With the parameter ``wait=<seconds>``
    the daemon answers once a job under way has ended (or after that many seconds)."""
    return f"{ROOT}/{cell}/jobs/{job_id}/result"


def cancel(cell: str, job_id: str) -> str:
    """Query; cancels the job and replies with its JobStatus."""
    return f"{ROOT}/{cell}/jobs/{job_id}/cancel"


def events(cell: str, job_id: str = "*") -> str:
    """Publications of JobEvent, one per state change or step of the job; the ``succeeded``
    event carries the job's ScanResult."""
    return f"{ROOT}/{cell}/events/{job_id}"


def status(cell: str) -> str:
    """Query (parameter ``failures=10``: how many recent failures); the reply is the cell's
    CellStatus: its live workers, each reconstructor's capacity and load, the queue, jobs by
    state, and the most recent failed jobs with their reasons."""
    return f"{ROOT}/{cell}/status"


def robot_move(cell: str) -> str:
    """Query with a MoveRequest; replies with a MoveReply once the robot is there."""
    return f"{ROOT}/{cell}/robot/move"


def robot_grip(cell: str) -> str:
    """Query with a GripRequest; replies with a GripReply once the gripper has closed or opened."""
    return f"{ROOT}/{cell}/robot/gripper"


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


# A reconstruction worker's id is one key chunk: no "/", and none of the characters key
# expressions reserve ("*", "$", "?", "#").
_WORKER_ID_CHARACTERS = "A-Za-z0-9._-"
#: What a worker id must match: letters, digits, ".", "_" and "-", starting with a letter or digit.
WORKER_ID = re.compile(rf"[A-Za-z0-9][{_WORKER_ID_CHARACTERS}]{{0,127}}")


def safe_worker_id(text: str) -> str:
    """``text`` with each character a worker id cannot hold made "_"."""
    return re.sub(rf"[^{_WORKER_ID_CHARACTERS}]", "_", text)


def reconstructor(worker_id: str) -> str:
    """Query with a ReconstructRequest attachment and the views' JPEGs, concatenated, as payload;
    the reply is a ReconstructReply."""
    return f"{POOL}/reconstruct/{worker_id}"


def reconstructor_alive(worker_id: str) -> str:
    """Liveliness token of a reconstruction worker: it is in the pool while this exists."""
    return f"{POOL}/alive/{worker_id}"


def reconstructor_info(worker_id: str) -> str:
    """Query; the reply is the worker's WorkerLoad (capacity and load) now."""
    return f"{POOL}/info/{worker_id}"


def reconstructor_heartbeat(worker_id: str = "*") -> str:
    """Publications of WorkerLoad, every HEARTBEAT_PERIOD_S and at each change of load."""
    return f"{POOL}/heartbeat/{worker_id}"


def ticket(cell: str, job_id: str, sending: int) -> str:
    """The id of one sending of a job's reconstruction (the first, or one after a failed attempt
    or a lost link), unique on the network."""
    return f"{cell}/{job_id}/{sending}"


RECONSTRUCTORS_ALIVE = f"{POOL}/alive/*"
RECONSTRUCTORS_HEARTBEAT = f"{POOL}/heartbeat/*"
#: Seconds between two heartbeats of a reconstruction worker.
HEARTBEAT_PERIOD_S = 0.5
#: The least seconds between two heartbeats sent because the worker's load changed.
HEARTBEAT_CHANGE_GAP_S = 0.05
