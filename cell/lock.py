"""One cell daemon per run directory: an exclusive lock on ``<run dir>/daemon.lock``.

A second daemon on the same run directory would read the same job store and
take the first one's jobs for its own; it is refused before it opens anything.
The lock is the kernel's (``flock``), so it goes with the process that holds
it, however that process ends.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from robocell.wire.errors import CellError

__all__ = ["RunDirLock", "RunDirBusy"]


class RunDirBusy(CellError):
    """Another cell daemon holds the run directory."""


class RunDirLock:
    """Hold the run directory ``run_dir`` for this process (``with RunDirLock(path):``)."""

    def __init__(self, run_dir: Path) -> None:
        self.path = Path(run_dir) / "daemon.lock"
        self._fd: int | None = None

    def acquire(self) -> None:
        """Take the lock, or raise :class:`RunDirBusy` naming who holds it.

        Raises
        ------
        RunDirBusy
            If another process holds it.
        OSError
            If the lock file cannot be made (the run directory is missing or not writable).
        """
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 64).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise RunDirBusy(f"the run directory {self.path.parent} is in use by another cell daemon "
                             f"(pid {holder}): stop it, or give this cell a run_dir of its own") from None
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
        self._fd = fd

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor lets go of the lock
            self._fd = None

    def __enter__(self) -> RunDirLock:
        self.acquire()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.release()
