"""A job's lifecycle table, and the one path of its changes (cell.job, cell.handle): every legal
move works, every other raises at once; each change reaches the store, then the listeners, then the
recording; what must survive a crash is synced before anyone hears of it."""

import asyncio

import numpy as np
import pytest

from robocell.cell.handle import JobHandle
from robocell.cell.job import TRANSITIONS, Checkpoint, IllegalTransition, Job
from robocell.cell.lane import MotionLane
from robocell.cell.pick import ChooseGrasp, Gripper, PickMove
from robocell.cell.plan import job_steps, step_from_spec
from robocell.cell.steps import Reconstruct, View
from robocell.wire.errors import StoreError
from robocell.wire.messages import JobState, Lifecycle, PickRequest, Progress, ScanRequest, ScanResult

L = Lifecycle
REQUEST = ScanRequest(target=[0.6, 0.0, 0.05])

# Written out by hand, not read from the table: the moves a job's life may make.
LEGAL = {
    (L.QUEUED, L.RUNNING), (L.QUEUED, L.FAILED), (L.QUEUED, L.CANCELLED),
    (L.RUNNING, L.CANCELLING), (L.RUNNING, L.SUCCEEDED), (L.RUNNING, L.FAILED),
    (L.CANCELLING, L.CANCELLED), (L.CANCELLING, L.FAILED),
}
# And by hand too, the moves that must never happen (every other pair of different states).
ILLEGAL = {
    (L.QUEUED, L.CANCELLING), (L.QUEUED, L.SUCCEEDED),
    (L.RUNNING, L.QUEUED), (L.RUNNING, L.CANCELLED),
    (L.CANCELLING, L.QUEUED), (L.CANCELLING, L.RUNNING), (L.CANCELLING, L.SUCCEEDED),
    (L.SUCCEEDED, L.QUEUED), (L.SUCCEEDED, L.RUNNING), (L.SUCCEEDED, L.CANCELLING), (L.SUCCEEDED, L.FAILED),
    (L.SUCCEEDED, L.CANCELLED),
    (L.FAILED, L.QUEUED), (L.FAILED, L.RUNNING), (L.FAILED, L.CANCELLING), (L.FAILED, L.SUCCEEDED),
    (L.FAILED, L.CANCELLED),
    (L.CANCELLED, L.QUEUED), (L.CANCELLED, L.RUNNING), (L.CANCELLED, L.CANCELLING), (L.CANCELLED, L.SUCCEEDED),
    (L.CANCELLED, L.FAILED),
}
T0 = 1_795_000_000.0


class Books:
    """A store, listeners and a recording that write down what reaches them, in one list."""

    def __init__(self, *, refuse: bool = False) -> None:
        self.log: list[tuple[str, str, bool | None]] = []
        self.refuse = refuse

    async def store(self, event, *, sync, error_kind, checkpoint) -> None:
        await asyncio.sleep(0)  # a real store answers from its thread, later
        if self.refuse:
            raise StoreError("job store: database or disk is full")
        self.log.append(("store", event.lifecycle.value, sync))

    def publish(self, event) -> None:
        self.log.append(("event", event.lifecycle.value, None))

    def record_event(self, job, event) -> None:
        self.log.append(("recording", event.lifecycle.value, None))


def handle_in(lifecycle: Lifecycle, books: Books | None = None) -> JobHandle:
    job = Job("20261130-000001", REQUEST, job_steps(REQUEST, [np.eye(4)] * 3), lifecycle=lifecycle)
    return JobHandle(job, books or Books(), clock=lambda: T0)


def picking(step: int = 4) -> Progress:
    return Progress(activity=JobState.PICKING, doing="approaching", step=step, steps=10)


def result() -> ScanResult:
    return ScanResult(job_id="20261130-000001", superquadric={"size": [0.1] * 3, "shape": [1.0, 1.0],
                      "T_world_object": np.eye(4).tolist()}, silhouette_iou=[1.0] * 3, residual=0.0,
                      timings_ms={}, T_base_cam=[np.eye(4).tolist()] * 3)


def test_the_hand_written_moves_cover_every_pair_and_agree_with_the_table():
    pairs = {(a, b) for a in Lifecycle for b in Lifecycle if a is not b}
    assert LEGAL | ILLEGAL == pairs and not LEGAL & ILLEGAL
    assert {(a, b) for a, targets in TRANSITIONS.items() for b in targets} == LEGAL


@pytest.mark.parametrize("start, to", sorted(LEGAL))
def test_a_legal_move_changes_the_job_and_says_so(start, to):
    handle = handle_in(start)
    event = asyncio.run(handle.change("moved", lifecycle=to, result=result() if to is L.SUCCEEDED else None))
    assert handle.job.lifecycle is to and (event.lifecycle, event.message, event.time) == (to, "moved", T0)
    assert event.state.value == (to.value if to is not L.RUNNING else "moving")  # what clients of schema 1 read


@pytest.mark.parametrize("start, to", sorted(ILLEGAL))
def test_an_illegal_move_raises_and_changes_nothing(start, to):
    books = Books()
    handle = handle_in(start, books)
    with pytest.raises(IllegalTransition, match=f"is {start.value}: it cannot become {to.value}"):
        asyncio.run(handle.change("moved", lifecycle=to))
    assert handle.job.lifecycle is start and books.log == []


def test_picking_cannot_go_back_to_queued():
    handle = handle_in(L.RUNNING)
    asyncio.run(handle.change("approaching", progress=picking()))
    with pytest.raises(IllegalTransition, match="is running: it cannot become queued"):
        asyncio.run(handle.change("again", lifecycle=L.QUEUED))
    assert handle.job.progress == picking()


@pytest.mark.parametrize("end", [L.SUCCEEDED, L.FAILED, L.CANCELLED])
def test_each_end_is_stored_and_synced_then_published_then_recorded(end):
    books = Books()
    handle = handle_in(L.CANCELLING if end is L.CANCELLED else L.RUNNING, books)
    asyncio.run(handle.change("the end", lifecycle=end, result=result() if end is L.SUCCEEDED else None))
    assert books.log == [("store", end.value, True), ("event", end.value, None), ("recording", end.value, None)]


def test_what_is_synced_before_anyone_hears_of_it():
    books = Books()
    handle = handle_in(L.QUEUED, books)

    async def scenario() -> None:
        moving = Progress(activity=JobState.MOVING, doing="moving to view 0", view=0, step=0, steps=10)
        await handle.change("moving to view 0", lifecycle=L.RUNNING, progress=moving)
        await handle.change("a note")
        await handle.change("choosing a grasp", progress=picking(4))   # the pick begins
        await handle.change("approaching", progress=picking(5))        # it goes on

    asyncio.run(scenario())
    assert [sync for kind, _, sync in books.log if kind == "store"] == [False, False, True, False]


def test_a_change_the_store_refuses_is_told_to_nobody_and_changes_nothing():
    books = Books(refuse=True)
    handle = handle_in(L.RUNNING, books)
    with pytest.raises(StoreError, match="disk is full"):
        asyncio.run(handle.change("reconstructed", lifecycle=L.SUCCEEDED, result=result()))
    assert books.log == [] and handle.job.lifecycle is L.RUNNING


def test_a_change_is_carried_through_when_its_caller_is_cancelled():
    books = Books()
    handle = handle_in(L.RUNNING, books)

    async def scenario() -> None:
        step = asyncio.create_task(handle.change("capturing view 1"))
        await asyncio.sleep(0)  # the store has it: the change is under way
        step.cancel()
        with pytest.raises(asyncio.CancelledError):
            await step
        await handle.change("cancelled", lifecycle=L.CANCELLING)  # after it, not beside it

    asyncio.run(scenario())
    assert [(kind, state) for kind, state, _ in books.log] == [
        ("store", "running"), ("event", "running"), ("recording", "running"),
        ("store", "cancelling"), ("event", "cancelling"), ("recording", "cancelling")]


def test_cancel_is_a_transition():
    assert asyncio.run(handle_in(L.QUEUED).request_cancel()).lifecycle is L.CANCELLED  # nothing to stop: at once
    running = handle_in(L.RUNNING)
    asyncio.run(running.change("approaching", progress=picking()))
    event = asyncio.run(running.request_cancel())
    assert (event.lifecycle, event.state, event.progress) == (L.CANCELLING, JobState.CANCELLING, picking())
    with pytest.raises(IllegalTransition):
        asyncio.run(running.request_cancel())  # cancelling already
    for end in (L.SUCCEEDED, L.FAILED, L.CANCELLED):
        with pytest.raises(IllegalTransition, match=f"is {end.value}"):
            asyncio.run(handle_in(end).request_cancel())


def test_a_plan_is_written_down_and_read_back_step_for_step():
    pick = ScanRequest(target=[0.6, 0.0, 0.05], pick=PickRequest(place=[0.5, 0.3]))
    poses = [np.eye(4) * (k + 1) for k in range(3)]
    plan = job_steps(pick, poses)
    kinds = [type(step) for step in plan]
    assert kinds == [View, View, View, Reconstruct, ChooseGrasp, Gripper, PickMove, PickMove, Gripper, PickMove,
                     PickMove, PickMove, Gripper, PickMove]
    point = Checkpoint.model_validate_json(Checkpoint(plan=[s.spec() for s in plan], done=5, began=5)
                                           .model_dump_json())
    again = [step_from_spec(spec) for spec in point.plan]
    assert [s.describe() for s in again] == [s.describe() for s in plan]
    assert [s.spec() for s in again] == [s.spec() for s in plan] and (point.done, point.began) == (5, 5)
    assert np.array_equal(again[2].pose, poses[2]) and again[12].places
    with pytest.raises(ValueError, match="unknown step 'dance' in a checkpoint"):
        step_from_spec({"kind": "dance"})
    with pytest.raises(ValueError, match="step 'view' in a checkpoint"):
        step_from_spec({"kind": "view", "view": 0})


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
