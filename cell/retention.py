"""Bounded disk: what the cell keeps of ended jobs, by age and by total size, applied while it runs.

A cell that picks 300 objects an hour writes about 500 kB a job (its
recording, mostly) and, kept forever, fills a gigabyte in 7 hours (issue 23).
:func:`apply_retention`, which the daemon calls every ``retention.interval_s``
in its store's thread, deletes:

- **recordings** (``<run dir>/<job id>.rrd``) older than
  ``recordings_max_age_days``, then the oldest until they take at most
  ``recordings_max_mb`` together;
- **pictures** kept for a restart (``<run dir>/pictures/<job id>/``) of jobs
  that have ended, older than ``pictures_max_age_days`` (a job drops its own
  when it ends; these are what a crash left);
- **backgrounds** (``<run dir>/backgrounds/``, ``cell/backgrounds.py``) older than
  ``backgrounds_max_age_days``, then the oldest until they take at most
  ``backgrounds_max_mb`` together (a newer background at a pose has replaced the older
  one already);
- **ended jobs** in the store (status, events, result) older than
  ``jobs_max_age_days``, and the oldest past ``jobs_max_count``; then the
  store's WAL is checkpointed, so that its file stays small too.

Nothing of a job that has not ended is touched: not its recording, not its
pictures, not its row (the store's unfinished jobs, and those the daemon names
as active, which it may not have stored yet). Nor is a file written in the
last :data:`GRACE_S` seconds (a job's recording is completed a moment after
its end), nor the store's newest job, whose number the next job's follows
(``JobStore.last_seq``). A pruned job is gone: a status query says there is no
such job, and a submit with its ``request_id`` makes a new job. A result whose
recording was deleted still names the file.

:func:`disk_usage` says what the run directory holds and what retention would
free now, for ``robocell status``.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import sqlite3
from collections.abc import Collection, Iterable
from dataclasses import dataclass
from pathlib import Path

from robocell.wire.config import RetentionConfig
from robocell.wire.messages import DiskUsage, JobState

from .backgrounds import Background, Backgrounds
from .backgrounds import remove as remove_background
from .reserve import free_bytes

__all__ = ["RetentionReport", "FileEntry", "apply_retention", "disk_usage", "plan_recordings", "plan_pictures",
           "plan_backgrounds", "GRACE_S"]

#: A file written this recently is kept whatever the policy: it may belong to a job just ended.
GRACE_S = 10.0
_DAY_S = 86400.0
_MB = 1024 * 1024
_STORE = "jobs.sqlite"
_ENDED = tuple(state.value for state in JobState if state.finished)


@dataclass(frozen=True)
class FileEntry:
    """A recording or a job's pictures: the job, its bytes, and when it was last written (unix time)."""

    path: Path
    job_id: str
    size: int
    mtime: float


@dataclass(frozen=True)
class RetentionReport:
    """What one application of the retention deleted."""

    recordings_deleted: int = 0
    recording_bytes_freed: int = 0
    pictures_deleted: int = 0
    picture_bytes_freed: int = 0
    backgrounds_deleted: int = 0
    background_bytes_freed: int = 0
    jobs_pruned: int = 0
    store_bytes_before: int = 0
    store_bytes_after: int = 0
    errors: tuple[str, ...] = ()      # what could not be deleted, one line each

    def summary(self) -> str:
        """One line for the log."""
        return (f"retention: {self.recordings_deleted} recordings ({self.recording_bytes_freed / _MB:.1f} MB), "
                f"{self.pictures_deleted} pictures ({self.picture_bytes_freed / _MB:.1f} MB), "
                f"{self.backgrounds_deleted} backgrounds ({self.background_bytes_freed / _MB:.1f} MB), "
                f"{self.jobs_pruned} ended jobs deleted; store {self.store_bytes_before / _MB:.1f} -> "
                f"{self.store_bytes_after / _MB:.1f} MB" + (f"; {len(self.errors)} errors" if self.errors else ""))


def _kept(entry: FileEntry, keep: Collection[str], now: float) -> bool:
    return entry.job_id in keep or now - entry.mtime < GRACE_S


def plan_recordings(entries: Iterable[FileEntry], keep: Collection[str], policy: RetentionConfig,
                    now: float) -> list[FileEntry]:
    """The recordings to delete, oldest first: past the age limit, then the oldest while all of
    them (those kept included) take more than the size limit. Never one of a job in ``keep``,
    nor one written in the last :data:`GRACE_S`.

    >>> from pathlib import Path
    >>> old, new = FileEntry(Path("a.rrd"), "a", 600, 0.0), FileEntry(Path("b.rrd"), "b", 600, 500.0)
    >>> policy = RetentionConfig(recordings_max_mb=1000 / 1024 / 1024)
    >>> [e.job_id for e in plan_recordings([new, old], set(), policy, now=1000.0)]
    ['a']
    >>> [e.job_id for e in plan_recordings([new, old], {"a"}, policy, now=1000.0)]  # a's job runs: b goes
    ['b']
    """
    entries = sorted(entries, key=lambda e: (e.mtime, e.job_id))
    doomed = [e for e in entries if not _kept(e, keep, now) and now - e.mtime > policy.recordings_max_age_days * _DAY_S]
    total = sum(e.size for e in entries) - sum(e.size for e in doomed)
    limit = policy.recordings_max_mb * _MB
    chosen = {e.path for e in doomed}
    for entry in entries:
        if total <= limit:
            break
        if entry.path in chosen or _kept(entry, keep, now):
            continue
        doomed.append(entry)
        chosen.add(entry.path)
        total -= entry.size
    return sorted(doomed, key=lambda e: (e.mtime, e.job_id))


def plan_pictures(entries: Iterable[FileEntry], keep: Collection[str], policy: RetentionConfig,
                  now: float) -> list[FileEntry]:
    """The pictures to delete: of jobs not in ``keep``, past the age limit."""
    return sorted((e for e in entries if not _kept(e, keep, now)
                   and now - e.mtime > policy.pictures_max_age_days * _DAY_S), key=lambda e: (e.mtime, e.job_id))


def plan_backgrounds(entries: Iterable[FileEntry], policy: RetentionConfig, now: float) -> list[FileEntry]:
    """The backgrounds to delete, oldest first: past the age limit, then the oldest while all of
    them take more than the size limit; never one written in the last :data:`GRACE_S`. (A
    background belongs to no job that runs: a scan reads it whole or goes without.)

    >>> from pathlib import Path
    >>> old, new = FileEntry(Path("a.jpg"), "a", 600, 0.0), FileEntry(Path("b.jpg"), "b", 600, 500.0)
    >>> policy = RetentionConfig(backgrounds_max_mb=1000 / 1024 / 1024, backgrounds_max_age_days=1)
    >>> [e.job_id for e in plan_backgrounds([new, old], policy, now=1000.0)]
    ['a']
    >>> [e.job_id for e in plan_backgrounds([new, old], policy, now=2 * 86400.0)]
    ['a', 'b']
    """
    entries = sorted(entries, key=lambda e: (e.mtime, str(e.path)))
    doomed = [e for e in entries if now - e.mtime >= GRACE_S and now - e.mtime > policy.backgrounds_max_age_days * _DAY_S]
    chosen = {e.path for e in doomed}
    total = sum(e.size for e in entries if e.path not in chosen)
    for entry in entries:
        if total <= policy.backgrounds_max_mb * _MB:
            break
        if entry.path in chosen or now - entry.mtime < GRACE_S:
            continue
        doomed.append(entry)
        chosen.add(entry.path)
        total -= entry.size
    return sorted(doomed, key=lambda e: (e.mtime, str(e.path)))


def _backgrounds(run_dir: Path) -> dict[Path, tuple[FileEntry, Background]]:
    """Each background kept, by its picture's path: as a file entry (its picture and description
    together), and as itself."""
    found = {}
    for background in Backgrounds(run_dir).all():
        size, mtime = 0, 0.0
        for path in (background.path, background.description):
            with contextlib.suppress(FileNotFoundError):
                stat = path.stat()
                size, mtime = size + stat.st_size, max(mtime, stat.st_mtime)
        found[background.path] = (FileEntry(background.path, background.job_id, size, mtime), background)
    return found


def _delete_backgrounds(doomed: list[FileEntry], kept: dict[Path, tuple[FileEntry, Background]],
                        errors: list[str]) -> tuple[int, int]:
    count = freed = 0
    for entry in doomed:
        try:
            remove_background(kept[entry.path][1])
        except OSError as exc:
            errors.append(f"{entry.path}: {exc.strerror or exc}")
            continue
        count, freed = count + 1, freed + entry.size
    return count, freed


def _recordings(run_dir: Path) -> list[FileEntry]:
    entries = []
    with contextlib.suppress(FileNotFoundError):
        for item in os.scandir(run_dir):
            if item.name.endswith(".rrd") and item.is_file(follow_symlinks=False):
                with contextlib.suppress(FileNotFoundError):
                    stat = item.stat(follow_symlinks=False)
                    entries.append(FileEntry(Path(item.path), item.name[:-4], stat.st_size, stat.st_mtime))
    return entries


def _pictures(run_dir: Path) -> list[FileEntry]:
    entries = []
    with contextlib.suppress(FileNotFoundError):
        for item in os.scandir(run_dir / "pictures"):
            if not item.is_dir(follow_symlinks=False):
                continue
            size, mtime = 0, item.stat(follow_symlinks=False).st_mtime
            with contextlib.suppress(FileNotFoundError):
                for file in os.scandir(item.path):
                    with contextlib.suppress(FileNotFoundError):
                        stat = file.stat(follow_symlinks=False)
                        size, mtime = size + stat.st_size, max(mtime, stat.st_mtime)
            entries.append(FileEntry(Path(item.path), item.name, size, mtime))
    return entries


def _store_bytes(store_path: Path) -> int:
    total = 0
    for suffix in ("", "-wal", "-shm"):
        with contextlib.suppress(FileNotFoundError):
            total += os.stat(f"{store_path}{suffix}").st_size
    return total


def _prunable_sql(policy: RetentionConfig, now: float) -> tuple[str, list[object]]:
    """The ended jobs to prune: too old, or past the count (never the newest job of all)."""
    ended = ", ".join("?" * len(_ENDED))
    sql = (f"SELECT job_id FROM jobs WHERE state IN ({ended}) AND seq < (SELECT MAX(seq) FROM jobs) AND "
           f"(updated < ? OR seq IN (SELECT seq FROM jobs WHERE state IN ({ended}) ORDER BY seq DESC "
           f"LIMIT -1 OFFSET ?))")
    return sql, [*_ENDED, now - policy.jobs_max_age_days * _DAY_S, *_ENDED, policy.jobs_max_count]


def _prune_store(store_path: Path, keep: Collection[str], policy: RetentionConfig, now: float) -> int:
    """Delete the ended jobs past the policy from the store's file, then checkpoint its WAL.

    Its own connection: the daemon's store is not in a transaction between its calls, and
    SQLite serialises writers (the daemon's waits at most its busy time-out)."""
    db = sqlite3.connect(store_path, timeout=5.0, isolation_level=None)
    try:
        db.execute("PRAGMA synchronous = FULL")
        db.execute("BEGIN IMMEDIATE")
        try:
            sql, params = _prunable_sql(policy, now)
            doomed = [row[0] for row in db.execute(sql, params) if row[0] not in keep]
            for start in range(0, len(doomed), 500):   # SQLite takes a bounded number of parameters
                chunk = doomed[start:start + 500]
                marks = ", ".join("?" * len(chunk))
                for table in ("events", "results", "pictures", "jobs"):
                    db.execute(f"DELETE FROM {table} WHERE job_id IN ({marks})", chunk)
            db.execute("COMMIT")
        except BaseException:
            if db.in_transaction:
                db.execute("ROLLBACK")
            raise
        db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        return len(doomed)
    finally:
        db.close()


def _delete(entries: list[FileEntry], errors: list[str]) -> tuple[int, int]:
    count = freed = 0
    for entry in entries:
        try:
            if entry.path.is_dir():
                shutil.rmtree(entry.path)
            else:
                entry.path.unlink()
        except FileNotFoundError:
            continue
        except OSError as exc:
            errors.append(f"{entry.path}: {exc.strerror or exc}")
            continue
        count, freed = count + 1, freed + entry.size
    return count, freed


def _unfinished(store_path: Path) -> set[str]:
    """The jobs of the store that have not ended (read-only; none without a store)."""
    if not store_path.exists():
        return set()
    db = sqlite3.connect(f"file:{store_path}?mode=ro", uri=True, timeout=5.0)
    try:
        ended = ", ".join("?" * len(_ENDED))
        return {row[0] for row in db.execute(f"SELECT job_id FROM jobs WHERE state NOT IN ({ended})", _ENDED)}
    finally:
        db.close()


def apply_retention(run_dir: Path, store, policy: RetentionConfig, now: float, *,
                    active: Collection[str] = ()) -> RetentionReport:
    """Delete what ``policy`` no longer keeps of the run directory and the store (module text).

    Parameters
    ----------
    run_dir : Path
        The cell's run directory.
    store : cell.store.JobStore
        The daemon's job store; call this in its thread. Its unfinished jobs keep everything.
    policy : RetentionConfig
        ``[retention]`` of the cell's configuration.
    now : float
        Unix time.
    active : collection of str
        Jobs the daemon runs that the store may not hold yet: kept too.

    Raises
    ------
    sqlite3.Error
        If the store cannot be pruned (the files were still deleted; the next run tries again).
    """
    run_dir = Path(run_dir)
    keep = {status.job_id for status in store.unfinished()} | set(active)
    errors: list[str] = []
    recordings, recording_bytes = _delete(plan_recordings(_recordings(run_dir), keep, policy, now), errors)
    pictures, picture_bytes = _delete(plan_pictures(_pictures(run_dir), keep, policy, now), errors)
    kept_backgrounds = _backgrounds(run_dir)
    backgrounds, background_bytes = _delete_backgrounds(
        plan_backgrounds([entry for entry, _ in kept_backgrounds.values()], policy, now), kept_backgrounds, errors)
    before = _store_bytes(store.path)
    pruned = _prune_store(store.path, keep, policy, now)
    return RetentionReport(recordings, recording_bytes, pictures, picture_bytes, backgrounds, background_bytes,
                           pruned, before, _store_bytes(store.path), tuple(errors))


def disk_usage(run_dir: Path, policy: RetentionConfig, *, now: float, store_path: Path | None = None,
               active: Collection[str] = ()) -> DiskUsage:
    """What the run directory holds, bytes, and what :func:`apply_retention` would free now.

    ``store_path`` is the job store (default ``<run dir>/jobs.sqlite``), read only.
    """
    run_dir = Path(run_dir)
    store_path = Path(store_path) if store_path is not None else run_dir / _STORE
    keep = _unfinished(store_path) | set(active)
    recordings, pictures = _recordings(run_dir), _pictures(run_dir)
    total = 0
    for root, _, files in os.walk(run_dir):
        for name in files:
            with contextlib.suppress(FileNotFoundError):
                total += os.lstat(os.path.join(root, name)).st_size
    prunable = 0
    if store_path.exists():
        db = sqlite3.connect(f"file:{store_path}?mode=ro", uri=True, timeout=5.0)
        try:
            sql, params = _prunable_sql(policy, now)
            prunable = sum(1 for row in db.execute(sql, params) if row[0] not in keep)
        finally:
            db.close()
    recording_bytes = sum(e.size for e in recordings)
    picture_bytes = sum(e.size for e in pictures)
    backgrounds = [entry for entry, _ in _backgrounds(run_dir).values()]
    background_bytes = sum(e.size for e in backgrounds)
    store_bytes = _store_bytes(store_path)
    free = free_bytes(run_dir)
    return DiskUsage(recordings=recording_bytes, pictures=picture_bytes, store=store_bytes,
                     other=max(0, total - recording_bytes - picture_bytes - background_bytes - store_bytes),
                     free_on_disk=free,
                     recordings_to_free=sum(e.size for e in plan_recordings(recordings, keep, policy, now)),
                     pictures_to_free=sum(e.size for e in plan_pictures(pictures, keep, policy, now)),
                     jobs_to_prune=prunable, backgrounds=background_bytes,
                     backgrounds_to_free=sum(e.size for e in plan_backgrounds(backgrounds, policy, now)))
