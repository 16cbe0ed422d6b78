"""The cell daemon's job store: every scan job, its events and its result in one SQLite file.

Each method is one short transaction (a millisecond at most: the daemon calls
them on its event loop), committed without waiting for the disk (WAL journal,
``synchronous=NORMAL``): a ``kill -9`` loses nothing committed. :meth:`JobStore.sync`
puts every commit so far on disk (an ``fsync`` of the journal, which needs no
connection, so that the daemon runs it in a thread while its loop goes on);
the daemon's ``cell.handle`` says which changes wait for it. After a power cut
a restarted daemon may find a job a step behind what it had not synced, and
carries it on from there. Every change of a job is one call of :meth:`JobStore.change`.

A job's checkpoint (``cell.job.Checkpoint``: its plan so far, the steps done)
is kept with it, replaced by each change that carries one, and so are the
pictures it has taken (:meth:`JobStore.keep_picture`) until it ends: a
restarted daemon carries it on from them, and the job's recording keeps them.

Job ids look like ``20261122-000042``: the UTC day the job was submitted, then
the job counter (the row number; jobs are never deleted). They are unique within a
store because the counter is, and sort in submission order as long as the clock does not
step back over midnight. """

from __future__ import annotations

import builtins
import contextlib
import os
import sqlite3
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

from pydantic import ValidationError

from robocell.wire.errors import StoreError
from robocell.wire.messages import ACTIVITIES, JobEvent, JobState, JobStatus, Lifecycle, Progress, ScanRequest, ScanResult

from .store_schema import SCHEMA as _SCHEMA
from .store_schema import SCHEMA_VERSION
from .store_schema import UPGRADES as _UPGRADES

__all__ = ["JobStore", "SCHEMA_VERSION", "job_id_for", "queued_status", "queued_event", "lifecycle_of"]

_T = TypeVar("_T")
_COLUMNS = "job_id, state, view, n_views, error, created, updated, recording, request, error_kind, progress"


class JobStore:
    """Scan jobs kept in the SQLite file ``path``, created with its schema if missing.

    Use as a context manager, or call :meth:`close`. Not thread-safe: one
    store per thread (other processes may open the same file).

    Raises
    ------
    StoreError
        The file cannot be opened or created, is not a database, is damaged
        (SQLite's ``quick_check``), or has a newer schema version. Every method raises it when SQLite fails or a stored
        row no longer validates.
    """

    def __init__(self, path: Path, *, timeout: float = 5.0):
        self.path = Path(path)
        self.closed = False
        with self._errors():
            # isolation_level=None: we issue BEGIN/COMMIT ourselves, so each
            # method is exactly one transaction and nothing is left open.
            self._db = sqlite3.connect(self.path, timeout=timeout, isolation_level=None)
            try:
                damage = [line for row in self._db.execute("PRAGMA quick_check(3)") for line in row[0].splitlines()
                          if not line.startswith("***")]
                if damage != ["ok"]:
                    raise StoreError(f"job store {self.path} is damaged ({'; '.join(damage[:3])}): move it aside "
                                     f"(a new one is made) or restore it from a backup")
                self._db.execute("PRAGMA journal_mode = WAL")      # readers don't block the writer
                self._db.execute("PRAGMA synchronous = NORMAL")    # on disk at sync(), see the module's text
                self._db.execute("PRAGMA foreign_keys = ON")
                with self._write() as db:
                    version = db.execute("PRAGMA user_version").fetchone()[0]
                    if version == 0:
                        for statement in _SCHEMA:
                            db.execute(statement)
                    elif version > SCHEMA_VERSION:
                        raise StoreError(f"job store {self.path} has schema version {version}; "
                                         f"this robocell reads versions up to {SCHEMA_VERSION}")
                    else:
                        for upgrade in range(version + 1, SCHEMA_VERSION + 1):
                            for statement in _UPGRADES[upgrade]:
                                db.execute(statement)
                    db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
            except BaseException:
                self._db.close()
                raise

    def close(self) -> None:
        """Close the database; later calls raise :class:`StoreError`. Closing twice is fine."""
        self.closed = True
        self._db.close()

    def __enter__(self) -> JobStore:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # --- writing ----------------------------------------------------------------------------

    def add(self, request: ScanRequest, *, n_views: int, now: float, checkpoint: str | None = None,
            token_digest: str | None = None) -> tuple[JobStatus, bool]:
        """Queue a new job, with its first event ("queued"); returns ``(status, True)``.

        If a job was already submitted with ``request.request_id``, nothing is
        added and that job comes back as ``(status, False)``, whatever its state.
        ``checkpoint``: the job's plan, as
        JSON (see :meth:`checkpoint`); ``token_digest``: what the job keeps of its token
        (:meth:`token_digest`). On disk once :meth:`sync` returns.

        Raises
        ------
        ValueError
            ``n_views`` is below 1.
        StoreError
            The database fails.
        """
        if n_views < 1:
            raise ValueError(f"n_views must be at least 1, got {n_views}")
        with self._write() as db:
            # BEGIN IMMEDIATE holds the write lock, so look-up and insert cannot
            # interleave with another writer; the UNIQUE index is the backstop.
            if request.request_id is not None:
                row = db.execute(f"SELECT {_COLUMNS} FROM jobs WHERE request_id = ?",
                                 (request.request_id,)).fetchone()
                if row is not None:
                    return _status(row), False
            seq = db.execute("SELECT COALESCE(MAX(seq), 0) + 1 FROM jobs").fetchone()[0]
            status = queued_status(job_id_for(seq, now), request, n_views=n_views, now=now)
            db.execute(
                "INSERT INTO jobs (seq, job_id, request_id, state, n_views, created, updated, request, checkpoint,"
                " token_digest) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (seq, status.job_id, request.request_id, JobState.QUEUED.value, n_views, now, now,
                 request.model_dump_json(), checkpoint, token_digest),
            )
            self._insert_event(db, queued_event(status))
            return status, True

    def sync(self) -> None:
        """Put every commit so far on disk: the journal synced (a checkpoint syncs the database file
        before it empties the journal). Needs no connection: any thread may call it.

        Raises
        ------
        StoreError
            The journal cannot be synced (the disk failed, say).
        """
        try:
            wal = os.open(f"{self.path}-wal", os.O_RDONLY)
        except FileNotFoundError:  # checkpointed and removed: the database file has it all
            return
        except OSError as exc:
            raise StoreError(f"job store {self.path}: cannot open its journal: {exc.strerror or exc}") from exc
        try:
            os.fsync(wal)
        except OSError as exc:
            raise StoreError(f"job store {self.path}: cannot sync its journal: {exc.strerror or exc}") from exc
        finally:
            os.close(wal)

    def change(self, event: JobEvent, *, error_kind: str | None = None, checkpoint: str | None = None,
               n_views: int | None = None, recording: str | None = None) -> JobStatus:
        """A change of a job, as its ``event`` says: its state and progress, the event in its
        history, its result (stored once, not in the history) if the event carries one; all of it or
        none. A failure's message is the job's ``error``, of kind ``error_kind``. ``checkpoint``
        (JSON) and ``n_views`` replace the job's when given, ``recording`` names its recording.

        Raises
        ------
        KeyError
            There is no job ``event.job_id``.
        ValueError
            The job is finished (succeeded, failed or cancelled): that is final.
        """
        job_id, state = event.job_id, JobState(event.state)
        failed = state is JobState.FAILED
        result = event.result
        with self._write() as db:
            self._check_open(db, job_id, state)
            if result is not None:
                db.execute("INSERT INTO results (job_id, result) VALUES (?, ?)", (job_id, result.model_dump_json()))
                recording = recording or result.recording
            db.execute(
                "UPDATE jobs SET state = ?, view = ?, error = ?, error_kind = ?, progress = ?,"
                " checkpoint = COALESCE(?, checkpoint), n_views = COALESCE(?, n_views),"
                " recording = COALESCE(?, recording), updated = ? WHERE job_id = ?",
                (state.value, event.view, event.message if failed else None, error_kind if failed else None,
                 event.progress.model_dump_json() if event.progress is not None else None, checkpoint, n_views,
                 recording, event.time, job_id),
            )
            self._insert_event(db, event)
            if state.finished:
                db.execute("DELETE FROM pictures WHERE job_id = ?", (job_id,))
            return self._get(db, job_id)

    def keep_picture(self, job_id: str, view: int, jpeg: bytes, poses: str) -> None:
        """Keep the picture of the job's ``view`` (replacing one kept before), with ``poses``
        (JSON).

        Raises
        ------
        KeyError
            There is no job ``job_id``.
        """
        with self._write() as db:
            if db.execute("SELECT 1 FROM jobs WHERE job_id = ?", (job_id,)).fetchone() is None:
                raise KeyError(f"no job {job_id!r}")
            db.execute("INSERT OR REPLACE INTO pictures (job_id, view, jpeg, poses) VALUES (?, ?, ?, ?)",
                       (job_id, view, jpeg, poses))

    def pictures(self, job_id: str) -> builtins.list[tuple[bytes, str]]:
        """The pictures kept of the job, (JPEG, poses JSON), in the order of their views 0, 1, ...:
        as many as there are from view 0 on without a gap."""
        rows = self._read("SELECT view, jpeg, poses FROM pictures WHERE job_id = ? ORDER BY view", [job_id],
                          lambda row: row)
        kept = []
        for expected, (view, jpeg, poses) in enumerate(rows):
            if view != expected:
                break
            kept.append((bytes(jpeg), poses))
        return kept

    # --- reading ----------------------------------------------------------------------------

    def get(self, job_id: str) -> JobStatus | None:
        """The job's status, or None if there is no such job."""
        rows = self._read(f"SELECT {_COLUMNS} FROM jobs WHERE job_id = ?", [job_id], _status)
        return rows[0] if rows else None

    def result(self, job_id: str) -> ScanResult | None:
        """The job's result, or None if it has none (yet)."""
        stored = self.result_json(job_id)
        return None if stored is None else ScanResult.model_validate_json(stored)

    def result_json(self, job_id: str) -> str | None:
        """The job's result as stored, the JSON of a ScanResult (validated when it was stored; what a
        result query answers), or None if it has none (yet)."""
        rows = self._read("SELECT result FROM results WHERE job_id = ?", [job_id], lambda row: str(row[0]))
        return rows[0] if rows else None

    def last_seq(self) -> int:
        """The number of the newest job (0: none yet); the next job's is one more."""
        return self._read("SELECT COALESCE(MAX(seq), 0) FROM jobs", [], lambda row: int(row[0]))[0]

    def token_digest(self, job_id: str) -> str | None:
        """The digest of the job's token (``cell.tokens``), or None (no such job, or one without)."""
        rows = self._read("SELECT token_digest FROM jobs WHERE job_id = ?", [job_id], lambda row: row[0])
        return rows[0] if rows else None

    def checkpoint(self, job_id: str) -> str | None:
        """The job's checkpoint (JSON, ``cell.job.Checkpoint``), or None if it has none."""
        rows = self._read("SELECT checkpoint FROM jobs WHERE job_id = ?", [job_id], lambda row: row[0])
        return rows[0] if rows else None

    def events(self, job_id: str) -> builtins.list[JobEvent]:
        """The job's events in the order they were added (none for an unknown job)."""
        return self._read("SELECT event FROM events WHERE job_id = ? ORDER BY seq", [job_id],
                          lambda row: JobEvent.model_validate_json(row[0]))

    def list(self, *, states: set[JobState] | None = None, limit: int = 100) -> builtins.list[JobStatus]:
        """Up to ``limit`` jobs, newest first, only those in ``states`` if given.

        Raises
        ------
        ValueError
            ``limit`` is below 1.
        """
        if limit < 1:
            raise ValueError(f"limit must be at least 1, got {limit}")
        where, params = _in_states(states)
        return self._read(f"SELECT {_COLUMNS} FROM jobs {where} ORDER BY seq DESC LIMIT ?",
                          [*params, limit], _status)

    def unfinished(self) -> builtins.list[JobStatus]:
        """Every job not yet succeeded, failed or cancelled, oldest first: a restarted daemon's to-do."""
        where, params = _in_states({s for s in JobState if not s.finished})
        return self._read(f"SELECT {_COLUMNS} FROM jobs {where} ORDER BY seq", params, _status)

    def count(self, states: set[JobState]) -> int:
        """How many jobs are in one of ``states``."""
        where, params = _in_states(states)
        return self._read(f"SELECT COUNT(*) FROM jobs {where}", params, lambda row: row[0])[0]

    def counts(self) -> dict[JobState, int]:
        """How many jobs are in each state (every state, zero included)."""
        found: dict[JobState, int] = dict(self._read("SELECT state, COUNT(*) FROM jobs GROUP BY state", [],
                                lambda row: (JobState(row[0]), row[1])))
        return {state: found.get(state, 0) for state in JobState}

    def find_request(self, request_id: str) -> JobStatus | None:
        """The job submitted with the client's ``request_id``, or None."""
        rows = self._read(f"SELECT {_COLUMNS} FROM jobs WHERE request_id = ?", [request_id], _status)
        return rows[0] if rows else None

    # --- plumbing ---------------------------------------------------------------------------

    @contextlib.contextmanager
    def _errors(self) -> Iterator[None]:
        """The one place where SQLite's and pydantic's errors become :class:`StoreError`."""
        try:
            yield
        except sqlite3.Error as exc:
            raise StoreError(f"job store {self.path}: {exc}") from exc
        except ValidationError as exc:
            raise StoreError(f"job store {self.path} holds an invalid row: {exc}") from exc

    def _read(self, sql: str, params: builtins.list[Any], convert: Callable[[tuple], _T]) -> builtins.list[_T]:
        """One query, every row converted; a single statement needs no explicit transaction."""
        with self._errors():
            return [convert(row) for row in self._db.execute(sql, params)]

    @contextlib.contextmanager
    def _write(self) -> Iterator[sqlite3.Connection]:
        """One write transaction: committed if the block returns, rolled back if it raises."""
        with self._errors():
            db = self._db
            db.execute("BEGIN IMMEDIATE")  # take the write lock now, not half-way through
            try:
                yield db
                db.execute("COMMIT")
            except BaseException:
                if db.in_transaction:  # SQLite may already have rolled back; a failed COMMIT has not
                    db.execute("ROLLBACK")
                raise

    @staticmethod
    def _insert_event(db: sqlite3.Connection, event: JobEvent) -> None:
        inserted = db.execute(
            "INSERT INTO events (job_id, event) SELECT job_id, ? FROM jobs WHERE job_id = ?",
            (event.model_dump_json(exclude={"result"}), event.job_id),
        ).rowcount
        if inserted == 0:
            raise KeyError(f"no job {event.job_id!r}")

    def _get(self, db: sqlite3.Connection, job_id: str) -> JobStatus:
        return _status(db.execute(f"SELECT {_COLUMNS} FROM jobs WHERE job_id = ?", (job_id,)).fetchone())

    def _check_open(self, db: sqlite3.Connection, job_id: str, new: JobState) -> None:
        row = db.execute("SELECT state FROM jobs WHERE job_id = ?", (job_id,)).fetchone()
        if row is None:
            raise KeyError(f"no job {job_id!r}")
        if JobState(row[0]).finished:
            raise ValueError(f"job {job_id} is {row[0]}, which is final: it cannot become {new.value}")


def job_id_for(seq: int, now: float) -> str:
    """The id of job number ``seq``, submitted at ``now``: ``20261122-000042``."""
    return f"{time.strftime('%Y%m%d', time.gmtime(now))}-{seq:06d}"


def queued_status(job_id: str, request: ScanRequest, *, n_views: int, now: float) -> JobStatus:
    """A new job's status, as :meth:`JobStore.add` stores it."""
    return JobStatus(job_id=job_id, state=JobState.QUEUED, n_views=n_views, created=now, updated=now,
                     request=request)


def queued_event(status: JobStatus) -> JobEvent:
    """A job's first event, which :meth:`JobStore.add` stores with the job."""
    return JobEvent(job_id=status.job_id, state=JobState.QUEUED, kind=status.request.kind, message="queued",
                    time=status.created)


def _status(row: tuple) -> JobStatus:
    job_id, state, view, n_views, error, created, updated, recording, request, error_kind, progress = row
    state = JobState(state)
    return JobStatus(job_id=job_id, state=state, lifecycle=lifecycle_of(state), view=view, n_views=n_views,
                     error=error, error_kind=error_kind, created=created, updated=updated, recording=recording,
                     request=ScanRequest.model_validate_json(request),
                     progress=Progress.model_validate_json(progress) if progress else None)


def lifecycle_of(state: JobState) -> Lifecycle:
    """The lifecycle of a job whose schema-1 ``state`` is ``state``."""
    return Lifecycle.RUNNING if state in ACTIVITIES else Lifecycle(state.value)


def _in_states(states: set[JobState] | None) -> tuple[str, builtins.list[str]]:
    """A WHERE clause for ``states`` (None: every job; empty: none) and its parameters."""
    if states is None:
        return "", []
    values = sorted(JobState(s).value for s in states)
    if not values:
        return "WHERE 0", []
    return f"WHERE state IN ({', '.join('?' * len(values))})", values
