"""The job's state machine: every legal move works, every other raises at once."""

import asyncio
import itertools

import numpy as np
import pytest

from cell.job import TRANSITIONS, WORKING, IllegalTransition, Job
from cell.lane import MotionLane
from wire.messages import JobState, ScanRequest

S = JobState
REQUEST = ScanRequest(target=[0.6, 0.0, 0.05])


def job_in(state: JobState) -> Job:
    job = Job("20261130-000001", REQUEST, [np.eye(4)] * 3)
    job.state = state
    return job


def test_the_table_names_every_state_and_ends_are_final():
    assert set(TRANSITIONS) == set(JobState)
    for state in JobState:
        assert (TRANSITIONS[state] == frozenset()) == state.finished


@pytest.mark.parametrize("start, to", list(itertools.product(JobState, JobState)))
def test_each_transition_is_legal_exactly_when_the_table_says(start, to):
    job = job_in(start)
    if to in TRANSITIONS[start]:
        event = job.transition(to, "step", view=1, now=5.0)
        assert job.state is to and (event.state, event.view, event.time) == (to, 1, 5.0)
    else:
        with pytest.raises(IllegalTransition, match=f"is {start.value}: it cannot become {to.value}"):
            job.transition(to, "step", now=5.0)
        assert job.state is start  # nothing changed


def test_the_states_a_scan_goes_through_are_legal_and_a_queued_job_cannot_succeed():
    job = job_in(S.QUEUED)
    for state in (S.MOVING, S.CAPTURING, S.MOVING, S.CAPTURING, S.RECONSTRUCTING, S.SUCCEEDED):
        job.transition(state, "", now=0.0)
    assert S.SUCCEEDED not in TRANSITIONS[S.QUEUED]
    assert TRANSITIONS[S.CANCELLING] == {S.CANCELLED}


def test_cancel_is_a_transition():
    waiting = job_in(S.QUEUED)
    assert waiting.request_cancel(now=1.0).state is S.CANCELLED  # nothing to stop: at once
    for state in WORKING:
        working = job_in(state)
        working.view = 2
        event = working.request_cancel(now=1.0)
        assert (event.state, event.view) == (S.CANCELLING, 2) and working.state is S.CANCELLING
        with pytest.raises(IllegalTransition):
            working.transition(S.MOVING, "a step after the cancel", now=2.0)
        with pytest.raises(IllegalTransition):
            working.request_cancel(now=2.0)  # cancelling already
        working.transition(S.CANCELLED, "cancelled", now=3.0)
    for state in (S.SUCCEEDED, S.FAILED, S.CANCELLED):
        with pytest.raises(IllegalTransition, match=f"is {state.value}"):
            job_in(state).request_cancel(now=1.0)


def test_the_lane_serves_jobs_under_way_before_new_ones():
    async def scenario() -> list[str]:
        lane, order = MotionLane(), []

        async def user(name: str, urgent: bool) -> None:
            async with lane.hold(urgent=urgent):
                order.append(name)
                await asyncio.sleep(0.01)

        async with lane.hold():
            tasks = [asyncio.create_task(user("new 1", False)), asyncio.create_task(user("new 2", False))]
            await asyncio.sleep(0)
            tasks.append(asyncio.create_task(user("pick", True)))
            cancelled = asyncio.create_task(user("gone", False))
            await asyncio.sleep(0)
            cancelled.cancel()
            await asyncio.sleep(0)
        await asyncio.gather(*tasks)
        assert not lane.held
        return order

    assert asyncio.run(scenario()) == ["pick", "new 1", "new 2"]
