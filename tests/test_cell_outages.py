"""Outages of a whole cell's parts, end to end: the router restarts, a worker is away for a while.

Every part is a child process; the router too, so that it can be killed and started again.
"""

from __future__ import annotations

import os
import signal
import time

import pytest

from robocell.cell.store import JobStore
from robocell.wire.messages import JobState

from tests.cell_fixtures import JOB_TIMEOUT_S, SMALL_CAMERA, cell_config, running_cell, wait_until


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    config = cell_config(tmp_path_factory.mktemp("outages"), cell_id="outages", camera=SMALL_CAMERA,
                         robot={"move_time_s": 0.2}, timeouts={"outage_s": 30.0})
    with running_cell(config) as running:
        yield running


def test_jobs_queued_across_a_router_restart_all_succeed(cell):
    """The router is killed while jobs wait and move, and stays away until the daemon has seen it
    gone (a job notes it): a step whose link drops waits for it and repeats its query; none fails,
    none is stuck."""
    ids = [cell.submit(label=f"across the outage {k}").job_id for k in range(4)]
    cell.wait_state(ids[0], {JobState.MOVING, JobState.CAPTURING})
    assert cell.loop.run(cell.processes.stop_child("router", kill=True)) == -9

    def link_down_noted() -> bool:  # read from the daemon's store: nothing reaches the daemon meanwhile
        with JobStore(cell.config.run_dir / "jobs.sqlite") as store:
            return any("the link to the Zenoh router is down" in e.message for job_id in ids
                       for e in store.events(job_id))

    wait_until(link_down_noted, timeout=JOB_TIMEOUT_S, interval=0.05, what="the daemon to see the router gone")
    cell.loop.run(cell.processes.start_child("router"), timeout=60)
    finals = [cell.wait(job_id) for job_id in ids]
    assert [f.state for f in finals] == [JobState.SUCCEEDED] * 4, [f.error for f in finals]
    notes = [e.message for job_id in ids for e in cell.events(job_id)]
    assert any("the link to the Zenoh router is down" in m for m in notes), notes
    assert cell.tracebacks() == {}


def test_a_robot_worker_away_for_a_while_costs_no_job(cell):
    ids = [cell.submit(label=f"robot away {k}").job_id for k in range(2)]
    assert cell.loop.run(cell.processes.stop_child("robot")) == 0
    # Away until the daemon has seen it go; then away as long as a robot worker takes to start.
    wait_until(lambda: not cell.status().workers["robot"], timeout=JOB_TIMEOUT_S, interval=0.05,
               what="the daemon to see the robot worker gone")
    cell.loop.run(cell.processes.start_child("robot"), timeout=60)
    finals = [cell.wait(job_id) for job_id in ids]
    assert [f.state for f in finals] == [JobState.SUCCEEDED] * 2, [f.error for f in finals]


def test_a_camera_restarted_costs_no_job(cell):
    """The simulated camera (an HTTP server) is away for 3 s: the camera worker, still up, answers
    that it cannot connect, and the daemon tries again until the camera is back."""
    ids = [cell.submit(label=f"camera away {k}").job_id for k in range(3)]
    cell.loop.run(cell.processes.stop_child("sim-camera"))
    time.sleep(3.0)
    cell.loop.run(cell.processes.start_child("sim-camera"), timeout=60)
    finals = [cell.wait(job_id) for job_id in ids]
    assert [f.state for f in finals] == [JobState.SUCCEEDED] * 3, [f.error for f in finals]


def test_a_reconstructor_paused_for_a_while_costs_no_job(cell):
    """The only reconstructor stops (SIGSTOP) until the daemon no longer counts on it (its heartbeat
    silent, or its session dropped by the router, whichever the daemon hears of first): its job is
    taken from it (if it had not answered yet), and waits, with the queued ones, for a worker that
    answers."""
    child = cell.processes.child("reconstruct-0")
    worker, worker_id = child.process, child.argv[-1]
    ids = [cell.submit(label=f"reconstructor paused {k}").job_id for k in range(3)]
    cell.wait_state(ids[0], {JobState.RECONSTRUCTING})
    os.kill(worker.pid, signal.SIGSTOP)
    try:
        def given_up() -> bool:
            seen = cell.reconstructor(worker_id)
            return seen is None or not seen.healthy

        wait_until(given_up, timeout=cell.config.timeouts.heartbeat_s + JOB_TIMEOUT_S, interval=0.05,
                   what=f"the daemon to give up on {worker_id}")
    finally:
        os.kill(worker.pid, signal.SIGCONT)
    finals = [cell.wait(job_id) for job_id in ids]
    assert [f.state for f in finals] == [JobState.SUCCEEDED] * 3, [f.error for f in finals]
