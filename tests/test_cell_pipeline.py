"""Several jobs in a row, cancels of queued and moving jobs, and a daemon killed mid-job.

Every part is a child process; the simulated robot takes a fixed time per
move, so that a job spends a while moving. What happened when is read from
the events the daemon stored, not from the test's clock.
"""

from __future__ import annotations

import asyncio
import random
import time

import pytest

from robocell.wire.errors import RemoteError
from robocell.wire.client import AsyncCellClient
from robocell.wire.messages import JobEvent, JobState, PickRequest

from tests.cell_fixtures import SMALL_CAMERA, cell_config, running_cell, wait_for_footer, wait_until

MOVE_TIME_S = 0.25


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    config = cell_config(tmp_path_factory.mktemp("cell-pipeline"), cell_id="pipeline", camera=SMALL_CAMERA,
                         robot={"move_time_s": MOVE_TIME_S}, timeouts={"outage_s": 5.0})
    with running_cell(config) as running:
        yield running


def _time(events: list[JobEvent], state: JobState, *, last: bool = False) -> float:
    times = [e.time for e in events if e.state is state]
    assert times, f"no {state.value} event in {[e.state.value for e in events]}"
    return times[-1] if last else times[0]


@pytest.fixture(scope="module")
def pipelined(cell):
    """Three jobs submitted at once, all run to the end."""
    ids = [cell.submit(label=f"pipelined {k}").job_id for k in range(3)]
    for job_id in ids:
        final = cell.wait(job_id)
        assert final.state is JobState.SUCCEEDED, final.error
    return ids


def test_reconstruction_overlaps_the_next_jobs_motion(cell, pipelined):
    events = [cell.events(job_id) for job_id in pipelined]
    for this, following in zip(events, events[1:]):
        reconstructing = (_time(this, JobState.RECONSTRUCTING), _time(this, JobState.SUCCEEDED))
        acquiring = (_time(following, JobState.MOVING), _time(following, JobState.RECONSTRUCTING))
        # One robot and one camera: the next job moves only once this one's pictures are taken ...
        assert acquiring[0] >= reconstructing[0]
        # ... but it does not wait for this one's reconstruction.
        assert max(reconstructing[0], acquiring[0]) < min(reconstructing[1], acquiring[1])


def test_jobs_moves_and_captures_do_not_interleave(cell, pipelined):
    spans = []
    for job_id in pipelined:
        events = cell.events(job_id)
        spans.append((_time(events, JobState.MOVING), _time(events, JobState.CAPTURING, last=True)))
    assert spans == sorted(spans)
    assert all(a[1] <= b[0] for a, b in zip(spans, spans[1:]))


def test_cancel_a_queued_job(cell):
    first = cell.submit(label="in front")
    queued = cell.submit(label="to cancel")
    cell.wait_state(first.job_id, {JobState.MOVING, JobState.CAPTURING})
    assert cell.client.status(queued.job_id).state is JobState.QUEUED
    cancelled = cell.client.cancel(queued.job_id)
    assert cancelled.state is JobState.CANCELLED
    assert cell.wait(first.job_id).state is JobState.SUCCEEDED
    assert [e.state for e in cell.events(queued.job_id)] == [JobState.QUEUED, JobState.CANCELLED]
    with pytest.raises(RemoteError, match="has no result: it is cancelled"):
        cell.client.result(queued.job_id)
    assert cell.client.cancel(queued.job_id).state is JobState.CANCELLED  # again: no harm


def test_cancel_a_moving_job(cell):
    status = cell.submit(label="cancel while moving")
    cell.wait_state(status.job_id, {JobState.MOVING})
    assert cell.client.cancel(status.job_id).state is JobState.CANCELLED  # the reply waits for the effect
    final = cell.wait(status.job_id, timeout=10)
    assert final.state is JobState.CANCELLED
    assert [(e.state, e.view) for e in cell.events(status.job_id)] == \
        [(JobState.QUEUED, None), (JobState.MOVING, 0), (JobState.CANCELLING, 0), (JobState.CANCELLED, None)]
    # The cell goes on with the next job.
    after = cell.submit(label="after the cancel")
    assert cell.wait(after.job_id).state is JobState.SUCCEEDED


def test_a_cancel_accepted_is_honoured_whenever_it_comes(cell):
    """Cancels at moments spread over a job's life, step boundaries included: each either comes
    too late (the job had ended) or ends the job cancelled; a lost cancel once let a job succeed."""
    rng = random.Random(3)
    for k in range(6):
        status = cell.submit(label=f"cancel {k}")
        cell.wait_state(status.job_id, {JobState.MOVING})
        time.sleep(rng.uniform(0.0, 3.5 * MOVE_TIME_S))
        try:
            reply = cell.client.cancel(status.job_id)
        except RemoteError as exc:
            assert "already succeeded: nothing to cancel" in str(exc)
            continue
        assert reply.state is JobState.CANCELLED, reply
        assert cell.wait(status.job_id, timeout=10).state is JobState.CANCELLED
        assert JobState.SUCCEEDED not in [e.state for e in cell.events(status.job_id)]


def test_daemon_killed_mid_job_restarts_keeping_results(cell, pipelined):
    done = pipelined[0]
    result_before = cell.client.result(done)
    interrupted = cell.submit(label="interrupted")
    queued = [cell.submit(label=f"queued {k}").job_id for k in range(2)]
    cell.wait_state(interrupted.job_id, {JobState.MOVING, JobState.CAPTURING})
    # Its recording opens at its first picture, or 0.2 s into its first move: killed after that,
    recording = cell.config.run_dir / f"{interrupted.job_id}.rrd"
    wait_until(lambda: recording.exists() and recording.stat().st_size > 0, timeout=10, interval=0.01,
               what="the interrupted job's recording to be opened")
    assert cell.loop.run(cell.processes.stop_child("daemon", kill=True)) == -9
    # the daemon's recorder notices, and closes what the daemon was recording.
    wait_for_footer(recording, timeout=20)
    cell.loop.run(cell.processes.start_child("daemon"))

    assert cell.client.result(done) == result_before
    # The job caught during its views carries on from its checkpoint: no job ends "interrupted".
    final = cell.wait(interrupted.job_id)
    assert final.state is JobState.SUCCEEDED, final.error
    events = cell.events(interrupted.job_id)
    carried = [k for k, e in enumerate(events) if "the daemon restarted: carrying on from step" in e.message]
    assert len(carried) == 1
    before_kill = {e.view for e in events[:carried[0]] if e.state is JobState.CAPTURING}
    after_kill = [e.view for e in events[carried[0]:] if e.state is JobState.CAPTURING]
    assert sorted(before_kill - {max(before_kill, default=None)} | set(after_kill)) == [0, 1, 2]
    assert len(cell.client.result(interrupted.job_id).T_base_cam) == 3
    for job_id in queued:
        status = cell.wait(job_id)
        assert status.state is JobState.SUCCEEDED, status.error
        assert cell.client.result(job_id).job_id == job_id
    assert cell.tracebacks() == {}


def test_daemon_stopped_mid_job_commands_the_robot_no_further(cell):
    """A daemon stopped (SIGTERM) while the robot moves for a job ends that job's steps with it:
    no capture, no next move. Restarted, it carries the job on from the view it was moving to."""
    status = cell.submit(label="stopped mid-move")
    moving = cell.wait_state(status.job_id, {JobState.MOVING})
    moves_of_the_job = lambda: cell.log("robot").count(f"for job {status.job_id}")  # noqa: E731
    before = moves_of_the_job()
    assert cell.loop.run(cell.processes.stop_child("daemon")) == 0
    time.sleep(3 * MOVE_TIME_S)  # long enough for a capture and the next move, had the job gone on
    assert moves_of_the_job() <= before + 1  # the move under way may end; no other begins
    assert cell.events(status.job_id)[-1].state is JobState.MOVING
    assert [e.view for e in cell.events(status.job_id) if e.state is JobState.MOVING][-1] == moving.view
    assert cell.tracebacks() == {}
    cell.loop.run(cell.processes.start_child("daemon"))
    final = cell.wait(status.job_id)
    assert final.state is JobState.SUCCEEDED, final.error
    assert moves_of_the_job() >= before + 3 - moving.view  # from the view it was moving to, on


def test_daemon_killed_during_a_pick_does_not_pick_again(cell):
    """The gripper may hold the object when the daemon dies during a pick: the restarted daemon
    fails the job, and moves the arm no further for it. The pick is seen starting from its event
    only (a status query would make the daemon write down what it holds back)."""
    request = cell.scan_request(label="killed during its pick", pick=PickRequest())

    async def submit_and_kill_at_the_pick() -> str:
        async with await AsyncCellClient.connect(cell.router, cell.config.cell_id) as client:
            client.listen()
            job_id = (await client.submit(request)).job_id
            async with asyncio.timeout(60):
                async for event in client.events(job_id):
                    if event.state is JobState.PICKING and event.message != "choosing a grasp":
                        break
            assert await cell.processes.stop_child("daemon", kill=True) == -9
            return job_id

    job_id = cell.loop.run(submit_and_kill_at_the_pick())
    moves_before = cell.log("robot").count(f"for job {job_id}")
    cell.loop.run(cell.processes.start_child("daemon"))
    final = cell.wait(job_id)
    assert final.state is JobState.FAILED and final.error_kind == "PickInterrupted", final
    assert "the gripper may still hold the object" in final.error
    time.sleep(2 * MOVE_TIME_S)
    assert cell.log("robot").count(f"for job {job_id}") <= moves_before + 1  # the move under way may end
    assert cell.tracebacks() == {}
