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

from wire.errors import StoreError
from wire.messages import JobEvent, JobState, ScanRequest, ScanResult
from cell.store import _SCHEMA, SCHEMA_VERSION, JobStore, job_id_for, queued_event, queued_status

T0 = 1_795_000_000.0  # 2026-11-18T11:06:40Z
IDENTITY = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
REPO = Path(__file__).resolve().parents[1]


def request(request_id=None, label=""):
    return ScanRequest(request_id=request_id, target=[0.5, 0.0, 0.1], label=label)


def result(job_id, recording=None):
    return ScanResult(job_id=job_id, superquadric={"size": [0.1, 0.1, 0.1], "shape": [1.0, 1.0], "T_world_object": np.eye(4).tolist()},
                      silhouette_iou=[0.9, 0.92, 0.95], residual=0.01, timings_ms={"carve": 12.5},
                      T_base_cam=[IDENTITY, IDENTITY], recording=recording)


@pytest.fixture
def store(tmp_path):
    with JobStore(tmp_path / "jobs.sqlite") as s:
        yield s


def test_a_new_store_is_a_wal_database_with_a_schema_version(tmp_path):
    JobStore(tmp_path / "jobs.sqlite").close()
    db = sqlite3.connect(tmp_path / "jobs.sqlite")
    try:
        assert db.execute("PRAGMA user_version").fetchone() == (SCHEMA_VERSION,) == (2,)
        assert db.execute("PRAGMA journal_mode").fetchone() == ("wal",)
    finally:
        db.close()


def test_a_caller_that_numbers_its_jobs_gets_the_ids_and_statuses_the_store_would_give(store):
    assert store.last_seq() == 0
    first, _ = store.add(request(), n_views=3, now=T0)
    given, created = store.add(request(label="numbered"), n_views=2, now=T0 + 1, seq=store.last_seq() + 1)
    assert created and given.job_id == job_id_for(2, T0 + 1) == "20261118-000002" and store.last_seq() == 2
    assert given == store.get(given.job_id) == queued_status(given.job_id, request(label="numbered"), n_views=2,
                                                             now=T0 + 1)
    with pytest.raises(StoreError, match="UNIQUE constraint failed: jobs.seq"):
        store.add(request(), n_views=3, now=T0 + 2, seq=2)
    assert [job.job_id for job in store.list(limit=10)] == [given.job_id, first.job_id]  # nothing half added


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
    store.update(first.job_id, JobState.MOVING, view=0, now=T0 + 1)
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


def test_update_walks_a_job_through_its_states(store):
    job, _ = store.add(request(), n_views=3, now=T0)
    moving = store.update(job.job_id, JobState.MOVING, view=1, recording="/runs/j.rrd", now=T0 + 5)
    assert (moving.state, moving.view, moving.recording, moving.updated) == (JobState.MOVING, 1, "/runs/j.rrd", T0 + 5)
    assert moving.created == T0
    # The recording is kept when not given again; the view describes the current state only.
    rec = store.update(job.job_id, JobState.RECONSTRUCTING, now=T0 + 9)
    assert (rec.view, rec.recording) == (None, "/runs/j.rrd")
    failed = store.update(job.job_id, "failed", error="reconstruct: no silhouette", now=T0 + 10)
    assert failed.state is JobState.FAILED and failed.error == "reconstruct: no silhouette"
    assert store.get(job.job_id) == failed


@pytest.mark.parametrize("final", [JobState.SUCCEEDED, JobState.FAILED, JobState.CANCELLED])
def test_a_finished_job_cannot_change_state(store, final):
    job, _ = store.add(request(), n_views=3, now=T0)
    done = store.update(job.job_id, final, now=T0 + 1)
    for other in (JobState.QUEUED, JobState.MOVING, JobState.FAILED if final != JobState.FAILED else JobState.SUCCEEDED):
        with pytest.raises(ValueError, match=f"is {final.value}.*cannot become {other.value}"):
            store.update(job.job_id, other, now=T0 + 2)
    with pytest.raises(ValueError, match=f"is {final.value}.*cannot become succeeded"):
        store.save_result(result(job.job_id), now=T0 + 2)
    assert store.get(job.job_id) == done and store.result(job.job_id) is None


def test_unknown_jobs_are_key_errors(store):
    with pytest.raises(KeyError, match="nope"):
        store.update("nope", JobState.MOVING, now=T0)
    with pytest.raises(KeyError, match="nope"):
        store.add_event(JobEvent(job_id="nope", state=JobState.MOVING, message="x", time=T0))
    with pytest.raises(KeyError, match="nope"):
        store.save_result(result("nope"), now=T0)


def test_events_come_back_in_order(store):
    job, _ = store.add(request(), n_views=3, now=T0)
    other, _ = store.add(request(), n_views=3, now=T0)
    events = [JobEvent(job_id=job.job_id, state=JobState.MOVING, view=v, message=f"view {v}", time=T0 + v)
              for v in (0, 1, 2)]
    for event in events:
        store.add_event(event)
    store.add_event(JobEvent(job_id=other.job_id, state=JobState.FAILED, message="gone", time=T0))
    # add() stores the job's first event with it.
    assert store.events(job.job_id) == [queued_event(job), *events]
    assert [e.message for e in store.events(other.job_id)] == ["queued", "gone"]
    assert store.events("nope") == []


def test_a_state_change_and_its_event_are_one_transaction(store):
    job, _ = store.add(request(), n_views=3, now=T0)
    moving = JobEvent(job_id=job.job_id, state=JobState.MOVING, view=0, message="moving to view 0", time=T0 + 1)
    store.update(job.job_id, JobState.MOVING, view=0, now=T0 + 1, event=moving)
    assert store.get(job.job_id).state is JobState.MOVING and store.events(job.job_id)[-1] == moving
    # An event for another job fails the whole transaction: the state is left as it was.
    stray = moving.model_copy(update={"job_id": "nope"})
    with pytest.raises(KeyError, match="nope"):
        store.update(job.job_id, JobState.CAPTURING, view=0, now=T0 + 2, event=stray)
    assert store.get(job.job_id).state is JobState.MOVING and len(store.events(job.job_id)) == 2


def test_the_succeeded_event_is_stored_without_its_result(store):
    job, _ = store.add(request(), n_views=3, now=T0)
    done = JobEvent(job_id=job.job_id, state=JobState.SUCCEEDED, message="reconstructed", time=T0 + 2,
                    result=result(job.job_id))
    store.save_result(result(job.job_id), now=T0 + 2, event=done)
    assert store.events(job.job_id)[-1] == done.model_copy(update={"result": None})
    assert store.result(job.job_id) == result(job.job_id)


def test_save_result_stores_it_and_marks_the_job_succeeded(store):
    job, _ = store.add(request(), n_views=3, now=T0)
    store.update(job.job_id, JobState.RECONSTRUCTING, now=T0 + 1)
    status = store.save_result(result(job.job_id, recording="/runs/j.rrd"), now=T0 + 2)
    assert (status.state, status.updated, status.recording) == (JobState.SUCCEEDED, T0 + 2, "/runs/j.rrd")
    assert store.result(job.job_id) == result(job.job_id, recording="/runs/j.rrd")
    assert store.result("nope") is None


def test_save_result_is_one_transaction(store):
    job, _ = store.add(request(), n_views=3, now=T0)
    # A result row that is already there makes the insert fail: the state must not change either.
    store._db.execute("INSERT INTO results (job_id, result) VALUES (?, '{}')", (job.job_id,))
    with pytest.raises(StoreError, match="UNIQUE constraint failed"):
        store.save_result(result(job.job_id), now=T0 + 1)
    assert store.get(job.job_id) == job and not store._db.in_transaction


def test_list_filters_and_orders_newest_first(store):
    ids = [store.add(request(), n_views=3, now=T0 + i)[0].job_id for i in range(5)]
    store.update(ids[1], JobState.MOVING, now=T0 + 10)
    store.update(ids[3], JobState.CANCELLED, now=T0 + 11)
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
        event = JobEvent(job_id=job.job_id, state=JobState.MOVING, view=0, message="moving", time=T0 + 1)
        store.add_event(event)
        done = store.save_result(result(job.job_id), now=T0 + 2)
        queued, _ = store.add(request(), n_views=2, now=T0 + 3)
    with JobStore(path) as store:
        assert store.list() == [queued, done]
        assert store.events(job.job_id) == [queued_event(job), event]
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
from wire.messages import ScanRequest
from cell.store import JobStore

store = JobStore(Path(sys.argv[1]))  # never closed: this process dies by SIGKILL
durable = sys.argv[2] == "durable"
for i in range(100_000):
    # As the daemon adds: synced at once, or committed at once and synced before the answer.
    status, _ = store.add(ScanRequest(request_id=f"r{i}", target=[0.5, 0, 0.1]), n_views=3, now=1.8e9 + i,
                          durable=durable)
    if not durable:
        store.sync()
    print(status.job_id, flush=True)
"""


def _read_lines(proc, until, timeout):
    """Lines from ``proc.stdout`` until ``until(lines)`` holds or the pipe closes; fails on timeout."""
    lines, buffer, deadline = [], b"", time.monotonic() + timeout
    while not until(lines):
        ready, _, _ = select.select([proc.stdout], [], [], max(0.0, deadline - time.monotonic()))
        if not ready:
            pytest.fail(f"no output within {timeout} s; got {len(lines)} lines")
        chunk = os.read(proc.stdout.fileno(), 65536)
        if not chunk:
            break
        buffer += chunk
        *complete, buffer = buffer.split(b"\n")
        lines += [line.decode() for line in complete]
    return lines


@pytest.mark.parametrize("kill_after, mode", [(1, "durable"), (40, "durable"), (40, "synced")])
def test_every_acknowledged_add_survives_kill_9(tmp_path, kill_after, mode):
    path = tmp_path / "jobs.sqlite"
    proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(path), mode], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        printed = _read_lines(proc, lambda lines: len(lines) >= kill_after, timeout=60)
        proc.send_signal(signal.SIGKILL)  # mid-stream: the writer is busy adding the next jobs
        assert proc.wait(timeout=10) == -signal.SIGKILL, proc.stderr.read().decode()
        printed += _read_lines(proc, lambda lines: False, timeout=10)  # whatever it printed before dying
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    assert len(printed) >= kill_after
    with JobStore(path) as store:
        for job_id in printed:
            assert store.get(job_id) is not None, job_id
        count = store.count(set(JobState))
        assert len(printed) <= count <= len(printed) + 1  # at most one committed but not yet printed
        assert [s.request.request_id for s in store.unfinished()] == [f"r{i}" for i in range(count)]


def test_a_store_of_version_1_is_upgraded_and_keeps_its_jobs(tmp_path):
    """Version 2 adds the error's kind; a run directory of an older robocell opens with its jobs."""
    path = tmp_path / "jobs.sqlite"
    db = sqlite3.connect(path, isolation_level=None)
    for statement in _SCHEMA:  # version 1: the same tables without jobs.error_kind
        db.execute(re.sub(r",(\s*--[^\n]*)?\n\s*error_kind TEXT\)", ")", statement))
    db.execute("PRAGMA user_version = 1")
    db.execute("INSERT INTO jobs (seq, job_id, state, n_views, error, created, updated, request) VALUES "
               "(1, '20261101-000001', 'failed', 3, 'moving to view 0: no robot', 1.0, 2.0, ?)",
               (ScanRequest(target=[0.6, 0.0, 0.05]).model_dump_json(),))
    db.close()
    with JobStore(path) as store:
        old = store.get("20261101-000001")
        assert old.state is JobState.FAILED and old.error == "moving to view 0: no robot" and old.error_kind is None
        status, _ = store.add(ScanRequest(target=[0.6, 0.0, 0.05]), n_views=3, now=3.0)
        failed = store.update(status.job_id, JobState.FAILED, error="capturing view 1: camera gone",
                              error_kind="CameraTimeout", now=4.0)
        assert failed.error_kind == "CameraTimeout"
    with contextlib.closing(sqlite3.connect(path)) as db:   # Python 3.13 warns of a connection left open
        assert db.execute("PRAGMA user_version").fetchone() == (2,)


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


def test_sync_when_the_journal_was_checkpointed_away_has_nothing_to_do(tmp_path):
    path = tmp_path / "jobs.sqlite"
    with JobStore(path) as store:
        status, _ = store.add(request(), n_views=3, now=T0, durable=False)
    assert not (tmp_path / "jobs.sqlite-wal").exists()  # the last connection closed: all in the database file
    with JobStore(path) as store:
        store.sync()
        assert store.get(status.job_id).state is JobState.QUEUED
