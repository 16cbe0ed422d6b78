"""Failover, end to end: reconstruction workers killed, frozen, added and broken under a running cell.

Router, robot, simulated camera, camera worker, daemon and the reconstruction
workers are child processes. The workers are the real one
(``tests/scale_worker.py`` runs ``workers.reconstruct.main``), whose jobs the
test can hold in flight for as long as it needs (``RunningCell.hold``), so that
a job is caught there and the worker killed or frozen under it. A job is put on
a chosen worker by making it the only one in the pool when the job comes
(``RunningCell.put_job_on``): a free proven worker always takes the next job
(cell/pool.py), so nothing about timing could choose for the test. The tests
run in order, each leaving the pool as the next expects: a worker killed in one
is not there in the next.
"""

from __future__ import annotations

import signal

import pytest

from robocell.wire.messages import JobState
from robocell.wire.transport import RequestError

from tests.cell_fixtures import (SMALL_CAMERA, START_TIMEOUT_S, InProcessWorker, RunningCell, cell_config, running_cell,
                                 wait_until)

HEARTBEAT_S = 1.0


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    # A snapshot may take seconds on a loaded machine: this file is about the reconstruction pool.
    config = cell_config(tmp_path_factory.mktemp("scale-failover"), cell_id="failover",
                         camera={**SMALL_CAMERA, "timeout_s": 15.0},
                         timeouts={"heartbeat_s": HEARTBEAT_S, "reconstruct_s": 20.0, "outage_s": 5.0},
                         reconstruct={"max_attempts": 3})
    # The victim alone at first: the first test's job can go nowhere else. The others join there.
    with running_cell(config, reconstructors=0, workers={"victim": 0.0}) as running:
        try:
            yield running
        finally:
            for worker_id in running.worker_ids.values():
                running.release(worker_id)
            frozen = running.processes.child("frozen").process if "frozen" in running.worker_ids else None
            if frozen is not None and frozen.returncode is None:
                frozen.send_signal(signal.SIGCONT)  # whatever happened, nothing stays frozen


def _messages(cell: RunningCell, job_id: str) -> list[str]:
    return [e.message for e in cell.events(job_id)]


def _restart(cell: RunningCell, name: str) -> None:
    cell.loop.run(cell.processes.start_child(name, ready_timeout=START_TIMEOUT_S), timeout=START_TIMEOUT_S + 10)


def test_kill_9_a_reconstructor_during_a_job(cell):
    victim = cell.worker_ids["victim"]
    job_id = cell.put_job_on(victim)
    for name in ("fast", "frozen"):     # where the job may go once its worker is gone
        cell.worker_ids[name] = cell.start_worker(name)
    assert cell.loop.run(cell.processes.stop_child("victim", kill=True)) == -9
    final = cell.wait(job_id)
    assert final.state is JobState.SUCCEEDED, final.error
    result = cell.client.result(job_id)
    assert result.worker in (cell.worker_ids["fast"], cell.worker_ids["frozen"]) and result.attempts == 2
    assert f"attempt 1 on {victim}: the worker is gone (its liveliness token was withdrawn); trying again" \
        in _messages(cell, job_id)
    assert cell.reconstructor(victim) is None               # gone from the pool


def test_a_frozen_reconstructor_loses_its_job_and_its_late_answer_is_ignored(cell):
    frozen, fast = cell.worker_ids["frozen"], cell.worker_ids["fast"]
    cell.loop.run(cell.processes.stop_child("fast"))        # the frozen one alone: the job goes there
    job_id = cell.put_job_on(frozen)
    _restart(cell, "fast")                                  # where it goes once the frozen one is given up
    process = cell.processes.child("frozen").process
    process.send_signal(signal.SIGSTOP)
    try:
        final = cell.wait(job_id)
        assert final.state is JobState.SUCCEEDED, final.error
        seen = cell.reconstructor(frozen)
        assert seen is None or not seen.healthy
    finally:
        cell.release(frozen)
        process.send_signal(signal.SIGCONT)
    result = cell.client.result(job_id)
    assert (result.worker, result.attempts) == (fast, 2)
    # Its heartbeat's silence gave it away, not its liveliness token (which a stopped process keeps
    # until its lease runs out): the timing itself is tested on a clock of the test's own
    # (tests/test_scale_pool.py).
    assert any(m.startswith(f"attempt 1 on {frozen}: no heartbeat for ") for m in _messages(cell, job_id))
    # Awake again, it finishes the job it held and answers; its heartbeat says so. Nobody listens.
    wait_until(lambda: (r := cell.reconstructor(frozen)) is not None and r.healthy and r.in_flight == 0,
               timeout=20.0, interval=0.1, what="the woken worker's answer")
    again = cell.client.status(job_id)
    assert again.state is JobState.SUCCEEDED and again.updated == final.updated
    assert cell.client.result(job_id) == result
    assert [e.state for e in cell.events(job_id)].count(JobState.SUCCEEDED) == 1


def test_a_worker_added_mid_burst_takes_waiting_work(cell):
    """Only a busy worker is left; reconstructions queue up behind it, then a new worker joins."""
    busy = cell.worker_ids["frozen"]
    cell.loop.run(cell.processes.stop_child("fast"))
    cell.hold(busy)                     # its slots fill with the burst's first jobs, and stay full
    ids = [cell.submit(label=f"burst {k}").job_id for k in range(6)]
    wait_until(lambda: cell.status().waiting_for_reconstructor >= 1, timeout=60.0, interval=0.05,
               what="reconstructions waiting for the busy worker")
    cell.worker_ids["newcomer"] = newcomer = cell.start_worker("newcomer")
    # While the busy one holds its jobs, every job that ends was the newcomer's.
    wait_until(lambda: sum(cell.client.status(j).state is JobState.SUCCEEDED for j in ids) >= 2, timeout=60.0,
               interval=0.1, what="two jobs of the burst done by the newcomer")
    cell.release(busy)
    done_by: dict[str, int] = {}
    for job_id in ids:
        final = cell.wait(job_id)
        assert final.state is JobState.SUCCEEDED, final.error
        worker = cell.client.result(job_id).worker
        done_by[worker] = done_by.get(worker, 0) + 1
    assert set(done_by) <= {busy, newcomer}
    assert done_by.get(newcomer, 0) >= 2, done_by
    status = cell.status()
    assert {r.worker for r in status.reconstructors} == {busy, newcomer}
    assert status.waiting_for_reconstructor == 0


def test_a_job_is_tried_at_most_max_attempts_times_then_fails_naming_each(cell):
    for name in ("newcomer", "frozen"):
        cell.loop.run(cell.processes.stop_child(name))

    async def broken(request_json: str, payload: bytes) -> tuple[str, bytes]:
        raise RequestError("broken on purpose")

    workers = [InProcessWorker(cell.loop, cell.router, f"broken-{k}", broken) for k in range(2)]
    try:
        wait_until(lambda: {r.worker for r in cell.status().reconstructors} == {"broken-0", "broken-1"},
                   timeout=10.0, interval=0.05, what="the broken workers")
        status = cell.submit(label="doomed")
        final = cell.wait(status.job_id)
    finally:
        for worker in workers:
            worker.close()
    assert final.state is JobState.FAILED
    attempts = final.error.removeprefix("reconstructing: gave up after 3 attempts: ").split("; ")
    assert len(attempts) == 3, final.error
    used = []
    for k, attempt in enumerate(attempts, 1):
        prefix, _, reason = attempt.partition(": ")
        assert reason == "answered with an error: broken on purpose", final.error
        used.append(prefix.removeprefix(f"attempt {k} on "))
    assert used[0] != used[1] and set(used) == {"broken-0", "broken-1"}   # another worker first
    failures = cell.status().recent_failures
    assert failures[0].job_id == status.job_id and failures[0].error == final.error
    assert cell.tracebacks() == {}
