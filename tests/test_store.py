import contextlib
import os
import re
import select
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from robocell.wire.errors import StoreError
from robocell.wire.messages import JobEvent, JobState, Lifecycle, Progress, ScanRequest, ScanResult
from robocell.cell.store import _SCHEMA, SCHEMA_VERSION, JobStore, lifecycle_of, queued_event

T0 = 1_795_000_000.0  # 2026-11-18T11:06:40Z
IDENTITY = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
REPO = Path(__file__).resolve().parents[1]


def request(request_id=None, label=""):
    return ScanRequest(request_id=request_id, target=[0.5, 0.0, 0.1], label=label)


def result(job_id, recording=None):
    return ScanResult(job_id=job_id, superquadric={"size": [0.1, 0.1, 0.1], "shape": [1.0, 1.0], "T_world_object": np.eye(4).tolist()},
                      silhouette_iou=[0.9, 0.92, 0.95], residual=0.01, timings_ms={"carve": 12.5},
                      T_base_cam=[IDENTITY, IDENTITY], recording=recording)


def event(job_id, state, *, view=None, message="", now, result=None) -> JobEvent:
    """The event of a change of job ``job_id`` to ``state`` (schema 1's state), as a daemon makes it."""
    state = JobState(state)
    lifecycle = lifecycle_of(state)
    progress = (Progress(activity=state, doing=message or state.value, view=view, step=0, steps=4)
                if lifecycle is Lifecycle.RUNNING else None)
    return JobEvent(job_id=job_id, state=state, lifecycle=lifecycle, progress=progress, view=view,
                    message=message or state.value, time=now, result=result)


def change(store, job_id, state, *, view=None, message="", now, result=None, **fields):
    return store.change(event(job_id, state, view=view, message=message, now=now, result=result), **fields)


@pytest.fixture
def store(tmp_path):
    with JobStore(tmp_path / "jobs.sqlite") as s:
        yield s


def test_a_new_store_is_a_wal_database_with_a_schema_version(tmp_path):
    JobStore(tmp_path / "jobs.sqlite").close()
    db = sqlite3.connect(tmp_path / "jobs.sqlite")
    try:
        assert db.execute("PRAGMA user_version").fetchone() == (SCHEMA_VERSION,) == (4,)
        assert db.execute("PRAGMA journal_mode").fetchone() == ("wal",)
    finally:
        db.close()


def test_add_queues_a_job_with_a_dated_counter_id(store):
    first, created = store.add(request(label="cube"), n_views=3, now=T0)
    second, _ = store.add(request(), n_views=3, now=T0 + 1)
    assert created
    assert (first.job_id, second.job_id) == ("20261118-000001", "20261118-000002")
    assert first.state is JobState.QUEUED and first.n_views == 3 and first.view is None
    assert first.created == first.updated == T0
    assert first.request == request(label="cube")
    assert store.get(first.job_id) == first
    assert store.get("nope") is None


def test_a_repeated_request_id_returns_the_existing_job(store):
    first, created = store.add(request("client-7"), n_views=3, now=T0)
    change(store, first.job_id, JobState.MOVING, view=0, now=T0 + 1)
    again, created_again = store.add(request("client-7", label="resent"), n_views=3, now=T0 + 2)
    assert created and not created_again
    assert again == store.get(first.job_id) and again.state is JobState.MOVING
    assert store.count(set(JobState)) == 1


def test_request_ids_are_unique_across_connections(tmp_path):
    with JobStore(tmp_path / "jobs.sqlite") as a, JobStore(tmp_path / "jobs.sqlite") as b:
        mine, _ = a.add(request("r1"), n_views=3, now=T0)
        theirs, created = b.add(request("r1"), n_views=3, now=T0)
        assert theirs == mine and not created
        # Jobs without a request id never collide.
        assert a.add(request(), n_views=3, now=T0)[1] and b.add(request(), n_views=3, now=T0)[1]
        assert a.count(set(JobState)) == 3


def test_changes_walk_a_job_through_its_states(store):
    job, _ = store.add(request(), n_views=3, now=T0)
    moving = change(store, job.job_id, JobState.MOVING, view=1, recording="/runs/j.rrd", now=T0 + 5)
    assert (moving.state, moving.view, moving.recording, moving.updated) == (JobState.MOVING, 1, "/runs/j.rrd", T0 + 5)
    assert (moving.lifecycle, moving.progress.activity, moving.progress.view) == (Lifecycle.RUNNING, JobState.MOVING, 1)
    assert moving.created == T0
    # The recording is kept when not given again; the view describes the current state only.
    rec = change(store, job.job_id, JobState.RECONSTRUCTING, now=T0 + 9)
    assert (rec.view, rec.recording) == (None, "/runs/j.rrd")
    failed = change(store, job.job_id, "failed", message="reconstruct: no silhouette", error_kind="SilhouetteError",
                    now=T0 + 10)
    assert failed.state is JobState.FAILED and failed.error == "reconstruct: no silhouette"
    assert (failed.error_kind, failed.lifecycle, failed.progress) == ("SilhouetteError", Lifecycle.FAILED, None)
    assert store.get(job.job_id) == failed


def test_a_checkpoint_is_kept_with_the_job_until_a_change_brings_another(store):
    job, _ = store.add(request(), n_views=3, now=T0, checkpoint='{"plan": [{"kind": "reconstruct"}], "done": 0}')
    assert store.checkpoint(job.job_id) == '{"plan": [{"kind": "reconstruct"}], "done": 0}'
    change(store, job.job_id, JobState.MOVING, view=0, now=T0 + 1)
    assert store.checkpoint(job.job_id) == '{"plan": [{"kind": "reconstruct"}], "done": 0}'
    grown = change(store, job.job_id, JobState.MOVING, view=3, now=T0 + 2, checkpoint='{"done": 4}', n_views=4)
    assert store.checkpoint(job.job_id) == '{"done": 4}' and grown.n_views == 4
    assert store.checkpoint("nope") is None


@pytest.mark.parametrize("final", [JobState.SUCCEEDED, JobState.FAILED, JobState.CANCELLED])
def test_a_finished_job_cannot_change_state(store, final):
    job, _ = store.add(request(), n_views=3, now=T0)
    done = change(store, job.job_id, final, now=T0 + 1)
    for other in (JobState.QUEUED, JobState.MOVING, JobState.FAILED if final != JobState.FAILED else JobState.SUCCEEDED):
        with pytest.raises(ValueError, match=f"is {final.value}.*cannot become {other.value}"):
            change(store, job.job_id, other, now=T0 + 2)
    with pytest.raises(ValueError, match=f"is {final.value}.*cannot become succeeded"):
        change(store, job.job_id, JobState.SUCCEEDED, result=result(job.job_id), now=T0 + 2)
    assert store.get(job.job_id) == done and store.result(job.job_id) is None


def test_unknown_jobs_are_key_errors(store):
    with pytest.raises(KeyError, match="nope"):
        change(store, "nope", JobState.MOVING, now=T0)
    with pytest.raises(KeyError, match="nope"):
        change(store, "nope", JobState.SUCCEEDED, result=result("nope"), now=T0)


def test_events_come_back_in_order(store):
    job, _ = store.add(request(), n_views=3, now=T0)
    other, _ = store.add(request(), n_views=3, now=T0)
    events = [event(job.job_id, JobState.MOVING, view=v, message=f"view {v}", now=T0 + v) for v in (0, 1, 2)]
    for one in events:
        store.change(one)
    store.change(event(other.job_id, JobState.FAILED, message="gone", now=T0))
    # add() stores the job's first event with it.
    assert store.events(job.job_id) == [queued_event(job), *events]
    assert [e.message for e in store.events(other.job_id)] == ["queued", "gone"]
    assert store.events("nope") == []


def test_the_succeeded_event_is_stored_without_its_result(store):
    job, _ = store.add(request(), n_views=3, now=T0)
    done = event(job.job_id, JobState.SUCCEEDED, message="reconstructed", now=T0 + 2, result=result(job.job_id))
    store.change(done)
    assert store.events(job.job_id)[-1] == done.model_copy(update={"result": None})
    assert store.result(job.job_id) == result(job.job_id)


def test_a_success_stores_its_result_and_marks_the_job_succeeded(store):
    job, _ = store.add(request(), n_views=3, now=T0)
    change(store, job.job_id, JobState.RECONSTRUCTING, now=T0 + 1)
    status = change(store, job.job_id, JobState.SUCCEEDED, result=result(job.job_id, recording="/runs/j.rrd"),
                    now=T0 + 2)
    assert (status.state, status.updated, status.recording) == (JobState.SUCCEEDED, T0 + 2, "/runs/j.rrd")
    assert store.result(job.job_id) == result(job.job_id, recording="/runs/j.rrd")
    assert store.result("nope") is None


def test_a_success_is_one_transaction(store):
    job, _ = store.add(request(), n_views=3, now=T0)
    # A result row that is already there makes the insert fail: the state must not change either.
    store._db.execute("INSERT INTO results (job_id, result) VALUES (?, '{}')", (job.job_id,))
    with pytest.raises(StoreError, match="UNIQUE constraint failed"):
        change(store, job.job_id, JobState.SUCCEEDED, result=result(job.job_id), now=T0 + 1)
    assert store.get(job.job_id) == job and not store._db.in_transaction
    assert store.events(job.job_id) == [queued_event(job)]


def test_list_filters_and_orders_newest_first(store):
    ids = [store.add(request(), n_views=3, now=T0 + i)[0].job_id for i in range(5)]
    change(store, ids[1], JobState.MOVING, now=T0 + 10)
    change(store, ids[3], JobState.CANCELLED, now=T0 + 11)
    assert [s.job_id for s in store.list()] == ids[::-1]
    assert [s.job_id for s in store.list(limit=2)] == [ids[4], ids[3]]
    assert [s.job_id for s in store.list(states={JobState.QUEUED})] == [ids[4], ids[2], ids[0]]
    assert [s.job_id for s in store.list(states={JobState.MOVING, JobState.CANCELLED})] == [ids[3], ids[1]]
    assert store.list(states=set()) == []
    assert [s.job_id for s in store.unfinished()] == [ids[0], ids[1], ids[2], ids[4]]
    assert store.count({JobState.QUEUED}) == 3 and store.count({JobState.QUEUED, JobState.MOVING}) == 4
    assert store.count(set()) == 0
    with pytest.raises(ValueError, match="limit"):
        store.list(limit=0)


def test_a_reopened_store_keeps_everything(tmp_path):
    path = tmp_path / "jobs.sqlite"
    with JobStore(path) as store:
        job, _ = store.add(request("r1"), n_views=3, now=T0)
        moving = change(store, job.job_id, JobState.MOVING, view=0, message="moving", now=T0 + 1)
        done = change(store, job.job_id, JobState.SUCCEEDED, result=result(job.job_id), now=T0 + 2)
        queued, _ = store.add(request(), n_views=2, now=T0 + 3)
    with JobStore(path) as store:
        assert store.list() == [queued, done]
        assert [e.state for e in store.events(job.job_id)] == [JobState.QUEUED, JobState.MOVING, JobState.SUCCEEDED]
        assert moving.progress is not None
        assert store.result(job.job_id) == result(job.job_id)
        assert store.add(request("r1"), n_views=3, now=T0 + 4) == (done, False)
        # The counter carries on from where it was.
        assert store.add(request(), n_views=3, now=T0 + 5)[0].job_id == "20261118-000003"


def test_sqlite_failures_become_store_errors(tmp_path):
    (tmp_path / "junk.sqlite").write_bytes(b"this is not a database, not at all" * 100)
    with pytest.raises(StoreError, match="junk.sqlite.*not a database"):
        JobStore(tmp_path / "junk.sqlite")
    with pytest.raises(StoreError, match="unable to open"):
        JobStore(tmp_path / "missing" / "jobs.sqlite")
    db = sqlite3.connect(tmp_path / "future.sqlite")
    db.execute("PRAGMA user_version = 99")
    db.close()
    with pytest.raises(StoreError, match="schema version 99"):
        JobStore(tmp_path / "future.sqlite")
    store = JobStore(tmp_path / "jobs.sqlite")
    store.close()
    store.close()
    with pytest.raises(StoreError, match="closed"):
        store.get("x")
    with pytest.raises(StoreError, match="closed"):
        store.add(request(), n_views=3, now=T0)


_WRITER = """
import sys
from pathlib import Path
from robocell.wire.messages import ScanRequest
from robocell.cell.store import JobStore

store = JobStore(Path(sys.argv[1]))  # never closed: this process dies by SIGKILL
for i in range(100_000):
    status, _ = store.add(ScanRequest(request_id=f"r{i}", target=[0.5, 0, 0.1]), n_views=3, now=1.8e9 + i)
    print(status.job_id, flush=True)
"""


class _PrintedLines:
    """The whole lines a process prints, read as they come. What follows the last newline waits in ``partial``
    for the rest of its line: a print may reach the pipe in two writes (the text, then its newline), so a read
    can end inside a line, and a line cut short by the kill is never a whole one."""

    def __init__(self, stream):
        self.stream, self.lines, self.partial = stream, [], b""

    def read_until(self, until, timeout):
        """Reads until ``until(self.lines)`` holds or the pipe closes; fails on timeout."""
        deadline = time.monotonic() + timeout
        while not until(self.lines):
            ready, _, _ = select.select([self.stream], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                pytest.fail(f"no output within {timeout} s; got {len(self.lines)} lines")
            chunk = os.read(self.stream.fileno(), 65536)
            if not chunk:
                return
            *complete, self.partial = (self.partial + chunk).split(b"\n")
            self.lines += [line.decode() for line in complete]


@pytest.mark.parametrize("kill_after", [1, 40])
def test_every_acknowledged_add_survives_kill_9(tmp_path, kill_after):
    path = tmp_path / "jobs.sqlite"
    proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(path)], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    printed = _PrintedLines(proc.stdout)
    try:
        printed.read_until(lambda lines: len(lines) >= kill_after, timeout=60)
        proc.send_signal(signal.SIGKILL)  # mid-stream: the writer is busy adding the next jobs
        assert proc.wait(timeout=10) == -signal.SIGKILL, proc.stderr.read().decode()
        printed.read_until(lambda lines: False, timeout=10)  # whatever it printed before dying
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    assert len(printed.lines) >= kill_after
    with JobStore(path) as store:
        for job_id in printed.lines:
            assert store.get(job_id) is not None, job_id
        count = store.count(set(JobState))
        assert len(printed.lines) <= count <= len(printed.lines) + 1  # at most one committed but not yet printed
        assert [s.request.request_id for s in store.unfinished()] == [f"r{i}" for i in range(count)]


def test_a_store_of_version_1_is_upgraded_and_keeps_its_jobs(tmp_path):
    """Version 2 adds the error's kind, 3 the progress and the checkpoint, 4 the token's digest; a run directory of an older
    robocell opens with its jobs."""
    path = tmp_path / "jobs.sqlite"
    db = sqlite3.connect(path, isolation_level=None)
    for statement in _SCHEMA:  # version 1: without jobs.error_kind, progress, checkpoint, nor pictures
        if "CREATE TABLE pictures" in statement:
            continue
        db.execute(re.sub(r",(\s*--[^\n]*)?\n\s*error_kind TEXT,.*?token_digest TEXT\)[^\n]*", ")", statement,
                          flags=re.S))
    db.execute("PRAGMA user_version = 1")
    db.execute("INSERT INTO jobs (seq, job_id, state, n_views, error, created, updated, request) VALUES "
               "(1, '20261101-000001', 'failed', 3, 'moving to view 0: no robot', 1.0, 2.0, ?)",
               (ScanRequest(target=[0.6, 0.0, 0.05]).model_dump_json(),))
    db.close()
    with JobStore(path) as store:
        old = store.get("20261101-000001")
        assert old.state is JobState.FAILED and old.error == "moving to view 0: no robot" and old.error_kind is None
        status, _ = store.add(ScanRequest(target=[0.6, 0.0, 0.05]), n_views=3, now=3.0, token_digest="d" * 64)
        assert store.token_digest(status.job_id) == "d" * 64 and store.token_digest("20261101-000001") is None
        failed = change(store, status.job_id, JobState.FAILED, message="capturing view 1: camera gone",
                        error_kind="CameraTimeout", now=4.0)
        assert failed.error_kind == "CameraTimeout"
    with contextlib.closing(sqlite3.connect(path)) as db:   # Python 3.13 warns of a connection left open
        assert db.execute("PRAGMA user_version").fetchone() == (SCHEMA_VERSION,)


def test_a_damaged_store_is_refused_at_open(tmp_path):
    """64 KB of garbage inside the file: refused at once with what to do, not opened to fail later."""
    path = tmp_path / "jobs.sqlite"
    with JobStore(path) as store:
        for k in range(300):
            store.add(ScanRequest(target=[0.6, 0.0, 0.05], label="x" * 200), n_views=3, now=T0 + k)
    size = path.stat().st_size
    assert size > 4096 + 65536
    with open(path, "r+b") as file:
        file.seek(4096)
        file.write(os.urandom(65536))
    with pytest.raises(StoreError, match=r"jobs.sqlite is damaged \(.*\): move it aside"):
        JobStore(path)


def test_a_job_keeps_its_pictures_until_it_ends(store):
    job, _ = store.add(request(), n_views=3, now=T0)
    other, _ = store.add(request(), n_views=3, now=T0)
    store.keep_picture(job.job_id, 0, b"jpeg 0", '{"at": 0}')
    store.keep_picture(job.job_id, 2, b"jpeg 2", '{"at": 2}')
    store.keep_picture(other.job_id, 0, b"other's", "{}")
    assert store.pictures(job.job_id) == [(b"jpeg 0", '{"at": 0}')]  # view 1 is missing: 2 is not whole
    store.keep_picture(job.job_id, 1, b"jpeg 1", '{"at": 1}')
    store.keep_picture(job.job_id, 0, b"jpeg 0 again", '{"at": 0}')
    assert [jpeg for jpeg, _ in store.pictures(job.job_id)] == [b"jpeg 0 again", b"jpeg 1", b"jpeg 2"]
    with pytest.raises(KeyError, match="nope"):
        store.keep_picture("nope", 0, b"", "{}")
    change(store, job.job_id, JobState.FAILED, message="gone", now=T0 + 1)
    assert store.pictures(job.job_id) == [] and store.pictures(other.job_id) == [(b"other's", "{}")]


def test_sync_puts_the_journal_on_disk_and_has_nothing_to_do_once_it_was_checkpointed_away(tmp_path):
    path = tmp_path / "jobs.sqlite"
    with JobStore(path) as store:
        status, _ = store.add(request(), n_views=3, now=T0)
        assert (tmp_path / "jobs.sqlite-wal").stat().st_size > 0
        store.sync()
    assert not (tmp_path / "jobs.sqlite-wal").exists()  # the last connection closed: all in the database file
    with JobStore(path) as store:
        store.sync()
        assert store.get(status.job_id).state is JobState.QUEUED
