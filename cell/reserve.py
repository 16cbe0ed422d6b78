"""Room kept on the run directory's disk for the daemon itself: a full disk must not stop it from starting.

Opening the job store needs a little room (SQLite's WAL index), and so does a daemon that is
to say what is wrong. On a disk that something else filled, a daemon that cannot open its
store cannot start, and under systemd it restarts for ever. So, while the disk has room, the
daemon keeps a file of :data:`RESERVE_BYTES` in the run directory (``reserve``), and it
deletes it when it starts on a full disk: it then opens its store, serves, says in its status
how little room there is (``disk.free_on_disk``), and refuses new jobs, saying why, while less
than :data:`MIN_FREE_BYTES` is free. Once there is room again it takes jobs, and keeps its
reserve again.
"""

from __future__ import annotations

import logging
import os
import shutil
from pathlib import Path

__all__ = ["RESERVE_BYTES", "MIN_FREE_BYTES", "RESERVE_NAME", "free_bytes", "release_if_full", "keep_reserve",
           "full_disk_refusal"]

log = logging.getLogger(__name__)

#: The room the daemon keeps for itself, in a file it deletes to start on a full disk.
RESERVE_BYTES = 4 * 1024 * 1024
#: Below this much free room no new job is taken (a job writes about half a megabyte).
MIN_FREE_BYTES = 2 * RESERVE_BYTES
RESERVE_NAME = "reserve"
_MB = 1024 * 1024  # as robocell status counts them


def free_bytes(run_dir: Path) -> int | None:
    """The room free on the run directory's file system; None if it cannot be read."""
    try:
        return shutil.disk_usage(run_dir).free
    except OSError:
        return None


def release_if_full(run_dir: Path) -> None:
    """Delete the reserve when the disk has less than :data:`MIN_FREE_BYTES` free."""
    free, reserve = free_bytes(run_dir), Path(run_dir) / RESERVE_NAME
    if free is None or free >= MIN_FREE_BYTES or not reserve.exists():
        return
    try:
        reserve.unlink()
    except OSError as exc:
        log.error("the disk of %s is full, and its reserve cannot be deleted: %s", run_dir, exc)
        return
    log.error("the disk of %s is full (%.1f MB free): its reserve of %.0f MB deleted so that the daemon starts; "
              "no new job is taken until there is room", run_dir, free / _MB, RESERVE_BYTES / _MB)


def keep_reserve(run_dir: Path) -> None:
    """Make the reserve if it is missing and the disk has room for it and the jobs besides (the
    daemon's upkeep calls it). Blocking (a few megabytes written): call it in a thread."""
    reserve = Path(run_dir) / RESERVE_NAME
    free = free_bytes(run_dir)
    if reserve.exists() or free is None or free < MIN_FREE_BYTES + RESERVE_BYTES:
        return
    partial = reserve.with_name(RESERVE_NAME + ".partial")
    try:
        with open(partial, "wb") as file:
            file.write(bytes(RESERVE_BYTES))  # written, not sparse: the room is taken now
            file.flush()
            os.fsync(file.fileno())
        partial.replace(reserve)
    except OSError as exc:
        log.warning("the reserve of %s cannot be made: %s", run_dir, exc)
        partial.unlink(missing_ok=True)


def full_disk_refusal(run_dir: Path) -> str | None:
    """Why a new job is refused for want of room (one line); None when there is room."""
    free = free_bytes(run_dir)
    if free is None or free >= MIN_FREE_BYTES:
        return None
    return (f"the cell's disk is full: {free / _MB:.1f} MB free where {run_dir} is, at least "
            f"{MIN_FREE_BYTES / _MB:.0f} MB needed: no new job until there is room")
