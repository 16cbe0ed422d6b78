"""The daemon's upkeep of its run directory: retention (``cell.retention``) applied every
``retention.interval_s`` while the cell runs, and the disk it uses for ``robocell status``.

Both read and delete files, so they run in a thread, off the event loop; the store's connection
belongs to the loop, so what retention needs of it (its path, its unfinished jobs) is read there.
"""

from __future__ import annotations

import asyncio
import logging
import sqlite3
from collections.abc import Callable, Collection
from dataclasses import dataclass
from pathlib import Path

from robocell.wire.config import RetentionConfig
from robocell.wire.messages import DiskUsage, JobStatus

from .reserve import keep_reserve
from .retention import apply_retention, disk_usage
from .store import JobStore

__all__ = ["apply_retention_every", "disk_used"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class _StoreAsSeen:
    """What :func:`~cell.retention.apply_retention` reads of the store, read on the loop."""

    path: Path
    statuses: list[JobStatus]

    def unfinished(self) -> list[JobStatus]:
        return self.statuses


async def apply_retention_every(run_dir: Path, store: JobStore, policy: RetentionConfig, *,
                                active: Callable[[], Collection[str]], clock: Callable[[], float]) -> None:
    """Apply ``policy`` every ``policy.interval_s`` until cancelled, logging what each run freed; a run
    that fails is logged, and the next one tries again. ``active``: the jobs the daemon runs now. The
    daemon's reserve is kept, from the start and after every run."""
    while True:
        # The room kept to start on a full disk (cell.reserve): made at start, and again once there is room.
        await asyncio.to_thread(keep_reserve, run_dir)
        await asyncio.sleep(policy.interval_s)
        seen = _StoreAsSeen(store.path, store.unfinished())
        try:
            report = await asyncio.to_thread(apply_retention, run_dir, seen, policy, clock(), active=set(active()))
        except (OSError, sqlite3.Error) as exc:
            log.warning("retention could not run: %s", exc)
            continue
        if report.errors:
            log.warning("%s: %s", report.summary(), report.errors[0])
        elif report.recordings_deleted or report.pictures_deleted or report.jobs_pruned:
            log.info("%s", report.summary())


async def disk_used(run_dir: Path, store: JobStore, policy: RetentionConfig, *, active: Collection[str],
                    now: float) -> DiskUsage | None:
    """What the run directory holds and what retention would free now; None if it cannot be read."""
    try:
        return await asyncio.to_thread(disk_usage, run_dir, policy, now=now, store_path=store.path,
                                       active=set(active))
    except (OSError, sqlite3.Error) as exc:
        log.warning("the run directory's disk use cannot be read: %s", exc)
        return None
