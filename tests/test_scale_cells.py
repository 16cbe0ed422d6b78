"""Two cells on one router share one pool of reconstruction workers; nothing submitted is lost.

Cell "north" (router, robot, simulated camera, camera worker, daemon) and
cell "south" (its own robot, cameras and daemon, on north's router) are child
processes, and so are the two reconstruction workers they share (the real
worker, whose jobs the test can hold there: load is seen on holds, not on
timing). South's queue holds two jobs. North's daemon is killed with SIGKILL in the middle of a
burst, and restarted.
"""

from __future__ import annotations

import subprocess
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

import pytest

from robocell.wire.client import CellClient
from robocell.wire.errors import RemoteError
from robocell.wire.messages import JobState, ScanRequest
from robocell.workers.sim.scene import target_from_config
from robocell.cell.store import JobStore

from tests.cell_fixtures import SMALL_CAMERA, RunningCell, cell_config, running_cell, wait_until

JOB_WAIT_S = 60.0   # a job's views and its way to a worker, on a loaded machine


@pytest.fixture(scope="module")
def cells(tmp_path_factory):
    root = tmp_path_factory.mktemp("scale-cells")
    north = cell_config(root / "north", cell_id="north", camera=SMALL_CAMERA, timeouts={"outage_s": 5.0})
    south = cell_config(root / "south", cell_id="south", camera=SMALL_CAMERA, zenoh={"router": north.zenoh.router},
                        max_queued=2, timeouts={"outage_s": 5.0})
    with running_cell(north, reconstructors=0, workers={"shared-a": 0.0, "shared-b": 0.0}) as n:
        with running_cell(south, with_router=False, reconstructors=0) as s:
            yield n, s


def _pool(cell: RunningCell) -> dict[str, tuple[int, int]]:
    """Each worker's (in flight from every cell, of which this cell's), as the cell's daemon sees it."""
    return {r.worker: (r.in_flight, r.in_flight_here) for r in cell.status().reconstructors}


def test_two_cells_share_the_workers_and_see_each_others_load(cells):
    """South's job held at one shared worker: north sees that worker busy with a job not its own, and
    sends its own job to the other one. The workers hold their jobs while the test says (no timing)."""
    north, south = cells
    shared = set(north.worker_ids.values())
    wait_until(lambda: set(_pool(south)) == shared, timeout=10.0, what="south to see the shared workers")
    for worker in shared:
        north.hold(worker)
    try:
        first = south.submit(label="south first")

        def busy() -> str | None:  # the worker with south's job, once north hears of it from the worker
            seen = _pool(north)
            return next((w for w, (load, ours) in seen.items() if load == 1 and ours == 0), None)

        taken = wait_until(busy, timeout=JOB_WAIT_S, interval=0.02, what="north to see south's job at a worker")
        assert _pool(south)[taken] == (1, 1)
        other = (shared - {taken}).pop()
        second = north.submit(label="north second")
        wait_until(lambda: _pool(north).get(other) == (1, 1), timeout=JOB_WAIT_S, interval=0.02,
                   what="north's job at the other worker")
        assert _pool(north)[taken] == (1, 0)   # south's job still there, held
    finally:
        for worker in shared:
            north.release(worker)
    assert north.wait(second.job_id).state is JobState.SUCCEEDED
    assert south.wait(first.job_id).state is JobState.SUCCEEDED
    assert south.client.result(first.job_id).worker == taken
    assert north.client.result(second.job_id).worker == other   # not the busy one


def test_a_full_queue_refuses_clearly_then_accepts_again(cells):
    _, south = cells
    accepted, refusal = [], None
    for k in range(8):
        try:
            accepted.append(south.submit(label=f"fill {k}").job_id)
        except RemoteError as exc:
            refusal = str(exc)
            break
    assert refusal == "the queue is full (2 jobs waiting): try again later"
    assert 3 <= len(accepted) <= 4     # two waiting, and one or two taken by the robot already
    for job_id in accepted:
        assert south.wait(job_id).state is JobState.SUCCEEDED
    assert south.wait(south.submit(label="after").job_id).state is JobState.SUCCEEDED
    assert len({*accepted}) == len(accepted)


def test_submitting_is_idempotent_with_a_request_id(cells):
    north, _ = cells
    request = ScanRequest(target=target_from_config(north.config.sim), request_id="idempotent-1")
    with ThreadPoolExecutor(4) as threads:   # at the same moment, from four clients
        clients = [CellClient(north.router, "north", timeout=10.0) for _ in range(4)]
        try:
            ids = list(threads.map(lambda client: client.submit(request).job_id, clients))
        finally:
            for client in clients:
                client.close()
    assert len(set(ids)) == 1
    final = north.wait(ids[0])
    assert final.state is JobState.SUCCEEDED
    again = north.client.submit(request)
    assert (again.job_id, again.state) == (ids[0], JobState.SUCCEEDED)
    with JobStore(north.config.run_dir / "jobs.sqlite") as store:
        assert store.find_request("idempotent-1").job_id == ids[0]
        assert sum(s.request.request_id == "idempotent-1" for s in store.list(limit=1000)) == 1
    with pytest.raises(ValueError, match="needs a request_id"):
        north.client.submit(ScanRequest(target=target_from_config(north.config.sim)), retry_s=5.0)


def test_daemon_killed_mid_burst_loses_nothing(cells):
    """A client submits a burst with request ids, retrying through the crash; every job it was told
    of ends succeeded (result fetchable), exactly once in the store: the restarted daemon carries
    on the job it was working on (its views again, or its reconstruction from the kept pictures)."""
    north, _ = cells
    n_jobs = 10
    requests = [ScanRequest(target=target_from_config(north.config.sim), request_id=f"burst-{k}", label=f"burst {k}")
                for k in range(n_jobs)]
    acknowledged: dict[str, str] = {}
    errors: list[BaseException] = []
    killed = threading.Event()

    def submit_all() -> None:
        client = CellClient(north.router, "north", timeout=3.0)
        try:
            for k, request in enumerate(requests):
                if k == 3:  # the rest of the burst goes through the crash, however fast the first came
                    killed.wait(30.0)
                acknowledged[request.request_id] = client.submit(request, retry_s=30.0).job_id
        except BaseException as exc:  # reported by the test below
            errors.append(exc)
        finally:
            client.close()

    submitter = threading.Thread(target=submit_all)
    submitter.start()
    try:
        wait_until(lambda: len(acknowledged) >= 3 or errors, timeout=20.0, what="three jobs submitted")
        assert north.loop.run(north.processes.stop_child("daemon", kill=True)) == -9
        killed_after = len(acknowledged)
        killed.set()
        north.loop.run(north.processes.start_child("daemon"))
    finally:
        submitter.join(60.0)
    assert not errors and not submitter.is_alive(), errors
    assert killed_after == 3 and set(acknowledged) == {r.request_id for r in requests}

    finals = {request_id: north.wait(job_id) for request_id, job_id in acknowledged.items()}
    for final in finals.values():
        assert final.state is JobState.SUCCEEDED, final
        assert north.client.result(final.job_id).job_id == final.job_id
    # Sent again, every request id gives back its job, as it ended: nothing is made twice.
    for request in requests:
        again = north.client.submit(request)
        assert again.job_id == acknowledged[request.request_id] and again.state.finished
    with JobStore(north.config.run_dir / "jobs.sqlite") as store:
        burst = [s for s in store.list(limit=1000) if (s.request.request_id or "").startswith("burst-")]
    assert sorted(s.job_id for s in burst) == sorted(acknowledged.values())
    status = north.status()
    assert status.queued == 0
    assert north.tracebacks() == {}


def test_status_command_shows_workers_load_queue_jobs_and_failures(cells):
    north, _ = cells
    base = [sys.executable, "-m", "robocell", "--config", str(north.processes.config_path)]
    shown = subprocess.run([*base, "status"], capture_output=True, text=True, timeout=60)
    assert shown.returncode == 0, shown.stderr
    text = shown.stdout
    assert text.startswith("cell north: daemon up ")
    assert "workers: robot up, camera up" in text
    assert "reconstructors: 2 live, capacity 2, " in text
    for worker in north.worker_ids.values():
        assert any(line.split()[:2] == [worker, "1"] for line in text.splitlines())   # id, capacity
    assert "queue: 0 waiting for the robot (at most 100), 0 for a reconstructor" in text
    status = north.status()
    assert "jobs: " + ", ".join(f"{state} {n}" for state, n in status.jobs.items()) in text
    failures = status.recent_failures
    if failures:   # the burst's interrupted jobs
        assert "recent failures:" in text and failures[0].job_id in text
    some_job = north.client.list(limit=1)[0].job_id
    job = subprocess.run([*base, "job", some_job], capture_output=True, text=True, timeout=60)
    assert job.returncode == 0 and f'"job_id": "{some_job}"' in job.stdout
