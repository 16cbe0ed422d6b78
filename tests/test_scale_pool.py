"""The reconstruction pool's decisions, in one process, on an in-memory network and a clock of the
test's own (``wire.fake_transport``, ``tests.virtual_time``): time-outs and heartbeats are timed
exactly, whatever the machine's load.

Reconstruction workers (``workers.reconstruct.ReconstructWorker``, each its own session, their work
a coroutine the test holds or lets go) and one or two pools (``cell.pool.ReconstructorPool``, as two
cell daemons use them). What the workers do is beside the point here, so their answers are empty
replies; the cell tests run the real core. What only a real router shows (a hung worker's token
lives on in Zenoh's threads) is tested over real Zenoh on loopback, at the end.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time

import pytest

from robocell.wire import keys
from robocell.wire.messages import ReconstructReply, ReconstructRequest, WorkerLoad
from robocell.cell.pool import AttemptFailed, NoReconstructor, ReconstructorPool
from robocell.wire.fake_transport import MemoryNetwork
from robocell.wire.transport import BaseTransport, Transport
from robocell.workers.reconstruct.worker import ReconstructWorker

from tests.cell_fixtures import LoopThread, free_port
from tests.virtual_time import run_virtual

HEARTBEAT_S = 1.0
LIMIT_S = 30.0      # no test may take longer: a hang fails instead


class Worker:
    """A worker whose requests wait at a gate: ``release(n)`` lets ``n`` of them answer."""

    def __init__(self, worker_id: str, capacity: int = 1, *, delay: float = 0.0) -> None:
        self.worker_id = worker_id
        self.capacity = capacity
        self.delay = delay
        self.tickets: list[str] = []
        self.answered: list[str] = []
        self.gate = asyncio.Semaphore(0)
        self.held = False
        self.transport: BaseTransport | None = None
        self.worker: ReconstructWorker | None = None

    async def start(self, network: MemoryNetwork) -> "Worker":
        self.transport = network.session()
        self.worker = ReconstructWorker(self.transport, self.worker_id, self.capacity, self.run)
        await self.worker.start()
        return self

    async def close(self) -> None:
        if self.transport is not None:
            await self.worker.close()
            await self.transport.close()
            self.transport = None

    def hold(self) -> None:
        self.held = True

    def release(self, n: int = 1000) -> None:
        self.held = False
        for _ in range(n):
            self.gate.release()

    async def run(self, request_json: str, payload: bytes) -> tuple[str, bytes]:
        request = ReconstructRequest.model_validate_json(request_json)
        self.tickets.append(request.ticket)
        if self.held:
            await self.gate.acquire()
        await asyncio.sleep(self.delay)
        self.answered.append(request.ticket)
        return ReconstructReply(job_id=request.job_id, worker=self.worker_id, ticket=request.ticket,
                                error=STAND_IN).model_dump_json(), b""


#: What the pool's stand-in workers answer: they schedule, they do not reconstruct.
STAND_IN = "a stand-in worker: no reconstruction"
_VIEWS = [{"camera": {"K": [[600, 0, 320], [0, 600, 240], [0, 0, 1]]},
           "T_world_cam": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "length": 2}] * 2


def _attachment(ticket: str) -> str:
    return ReconstructRequest(job_id=ticket, views=_VIEWS, ticket=ticket).model_dump_json()


class Net:
    """An in-memory router, and pools on sessions of their own (one per "cell")."""

    def __init__(self) -> None:
        self.network = MemoryNetwork()
        self.pools: list[ReconstructorPool] = []
        self._workers: list[Worker] = []

    async def pool(self, heartbeat_s: float = HEARTBEAT_S) -> ReconstructorPool:
        pool = ReconstructorPool(self.network.session(), heartbeat_s=heartbeat_s,
                                 clock=asyncio.get_running_loop().time)
        pool.start()
        self.pools.append(pool)
        return pool

    async def worker(self, *args, **kwargs) -> Worker:
        worker = await Worker(*args, **kwargs).start(self.network)
        self._workers.append(worker)
        return worker

    async def close(self) -> None:
        for worker in self._workers:
            worker.release()
            await worker.close()
        for pool in self.pools:
            await pool.close()


@contextlib.asynccontextmanager
async def network():
    net = Net()
    try:
        yield net
    finally:
        await net.close()


def run(coroutine):
    run_virtual(coroutine, limit_s=LIMIT_S)


def now() -> float:
    return asyncio.get_running_loop().time()


async def until(predicate, what: str, timeout: float = 10.0) -> None:
    deadline = now() + timeout
    while not predicate():
        if now() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        await asyncio.sleep(0.01)


async def sees(pool: ReconstructorPool, *workers: Worker) -> None:
    """Wait until ``pool`` knows every worker's capacity."""
    def known() -> bool:
        seen = {r.worker: r for r in pool.snapshot()}
        return all(w.worker_id in seen and seen[w.worker_id].capacity == w.capacity
                   and seen[w.worker_id].heartbeat_age_s is not None for w in workers)

    await until(known, f"the pool to see {[w.worker_id for w in workers]}")


def send(pool: ReconstructorPool, ticket: str, *, timeout: float = 10.0, wait_s: float = 5.0,
         avoid: set[str] = frozenset()) -> asyncio.Task:
    return asyncio.ensure_future(pool.run(ticket, b"ab" * 2, _attachment(ticket), timeout=timeout, wait_s=wait_s,
                                          avoid=avoid))


def test_work_goes_where_capacity_is_free_and_waits_when_none_is():
    async def check():
        async with network() as net:
            pool = await net.pool()
            small, big = await net.worker("small", 1), await net.worker("big", 3)
            small.hold()
            big.hold()
            await sees(pool, small, big)
            first = [send(pool, f"t{k}") for k in range(4)]
            await until(lambda: len(small.tickets) + len(big.tickets) == 4, "four requests at the workers")
            # Lowest in_flight / capacity first: 1 of 1 on the small one, 3 of 3 on the big one.
            assert (len(small.tickets), len(big.tickets)) == (1, 3)
            late = send(pool, "t-late")
            await asyncio.sleep(0.5)
            assert not late.done() and pool.waiting == 1       # every slot taken: it waits
            small.release(1)
            worker, reply = await late
            assert worker == "small" and ReconstructReply.model_validate_json(reply.attachment).ticket == "t-late"
            big.release()
            assert sorted(w for w, _ in await asyncio.gather(*first)) == ["big", "big", "big", "small"]

    run(check())


def test_load_is_shared_between_the_pools_of_two_cells():
    """A worker's load comes from its own heartbeat, so one cell's pool sees the other's work."""
    async def check():
        async with network() as net:
            cell_a, cell_b = await net.pool(), await net.pool()
            one, two = await net.worker("one"), await net.worker("two")
            one.hold()
            two.hold()
            await sees(cell_a, one, two)
            await sees(cell_b, one, two)
            from_a = send(cell_a, "a/1")
            await until(lambda: len(one.tickets) + len(two.tickets) == 1, "cell a's request at a worker")
            busy = "one" if one.tickets else "two"
            await until(lambda: {r.worker: r.in_flight for r in cell_b.snapshot()}[busy] == 1,
                        "cell b to hear of cell a's request")
            from_b = send(cell_b, "b/1")
            await until(lambda: len(one.tickets) + len(two.tickets) == 2, "cell b's request at a worker")
            assert one.tickets != [] and two.tickets != []          # b took the other worker
            again = send(cell_b, "b/2")
            await asyncio.sleep(0.3)
            assert not again.done()                                 # both full, whoever filled them
            one.release()
            two.release()
            workers = [w for w, _ in await asyncio.gather(from_a, from_b, again)]
            assert workers[0] == busy and workers[1] != busy

    run(check())


def test_a_worker_that_leaves_fails_its_attempt_at_once():
    async def check():
        async with network() as net:
            pool = await net.pool()
            leaving = await net.worker("leaving")
            leaving.hold()
            await sees(pool, leaving)
            attempt = send(pool, "t1")
            await until(lambda: leaving.tickets, "the request at the worker")
            began = now()
            await leaving.close()  # its session, and so its liveliness token, goes
            with pytest.raises(AttemptFailed) as failed:
                await attempt
            assert failed.value.worker == "leaving"
            assert "gone" in failed.value.reason or "nobody answers" in failed.value.reason
            assert now() - began < HEARTBEAT_S  # at once: its heartbeat's silence is not waited for
            assert pool.snapshot() == []

    run(check())


def test_a_worker_whose_loop_hangs_is_passed_over_and_its_late_answer_ignored():
    """Its token stays (see the real-router test below); only its heartbeat stops."""
    async def check():
        async with network() as net:
            pool = await net.pool()
            hung, healthy = await net.worker("hung"), await net.worker("healthy")
            hung.hold()
            healthy.hold()
            await sees(pool, hung, healthy)
            attempt = send(pool, "t1", avoid={"healthy"})
            await until(lambda: hung.tickets, "the request at the worker to hang")
            net.network.freeze(hung.transport)
            began = now()
            with pytest.raises(AttemptFailed) as failed:
                await attempt
            waited = now() - began
            assert failed.value.worker == "hung" and failed.value.reason.startswith("no heartbeat for")
            # Silent since its last heartbeat, which came at most a period before it hung.
            assert HEARTBEAT_S - keys.HEARTBEAT_PERIOD_S <= waited <= HEARTBEAT_S + 0.25 + 0.01
            assert {r.worker: r.healthy for r in pool.snapshot()} == {"hung": False, "healthy": True}
            retry = send(pool, "t2", avoid={"hung"})
            await until(lambda: healthy.tickets, "the retry at the healthy worker")
            hung.release()
            net.network.thaw(hung.transport)   # it wakes and answers t1: nobody listens
            await until(lambda: hung.answered == ["t1"], "the woken worker's late answer")
            await until(lambda: {r.worker: r.healthy for r in pool.snapshot()}.get("hung"),
                        "the woken worker's heartbeat")
            healthy.release()
            assert (await retry)[0] == "healthy"

    run(check())


def test_a_time_out_fails_the_attempt():
    async def check():
        async with network() as net:
            pool = await net.pool()
            slow = await net.worker("slow", delay=3.0)
            await sees(pool, slow)
            with pytest.raises(AttemptFailed, match="slow: no answer within 0.5 s"):
                await send(pool, "t1", timeout=0.5)
            assert pool.snapshot()[0].failed == 1

    run(check())


def test_without_workers_a_caller_waits_then_gives_up_and_a_newcomer_takes_waiting_work():
    async def check():
        async with network() as net:
            pool = await net.pool()
            began = now()
            with pytest.raises(NoReconstructor, match=r"no reconstruction worker is running \(waited 0.5 s\)"):
                await send(pool, "t1", wait_s=0.5)
            assert now() - began == pytest.approx(0.5)
            waiting = send(pool, "t2", wait_s=10.0)
            await asyncio.sleep(0.2)
            newcomer = await net.worker("newcomer")
            assert (await waiting)[0] == "newcomer"
            assert newcomer.answered == ["t2"]

    run(check())


def test_the_heartbeat_carries_capacity_load_and_tickets():
    async def check():
        async with network() as net:
            worker = await net.worker("w", 2)
            worker.hold()
            listener = net.network.session()
            try:
                beats = listener.subscribe(keys.reconstructor_heartbeat("w"))
                pool = await net.pool()
                await sees(pool, worker)
                attempt = send(pool, "cell/job/1")
                while True:
                    load = WorkerLoad.model_validate_json((await beats.get(timeout=5.0)).payload)
                    if load.in_flight:
                        break
                assert (load.worker, load.capacity, load.in_flight, load.tickets) == ("w", 2, 1, ["cell/job/1"])
                assert load.period_s == keys.HEARTBEAT_PERIOD_S
                info = WorkerLoad.model_validate_json(
                    (await listener.query(keys.reconstructor_info("w"), timeout=5.0)).payload)
                assert info.tickets == ["cell/job/1"]
                worker.release()
                await attempt
                beats.close()
            finally:
                await listener.close()

    run(check())


def test_callers_waiting_for_a_slot_give_up_when_every_worker_is_gone():
    async def check():
        async with network() as net:
            pool = await net.pool()
            only = await net.worker("only")
            only.hold()
            await sees(pool, only)
            first = send(pool, "t1")
            await until(lambda: only.tickets, "the first request at the worker")
            second = send(pool, "t2", wait_s=0.5)
            await asyncio.sleep(0.2)
            assert pool.waiting == 1
            await only.close()
            with pytest.raises(AttemptFailed):
                await first
            began = now()
            with pytest.raises(NoReconstructor, match=r"no reconstruction worker is running \(waited 0.5 s\)"):
                await second
            assert now() - began == pytest.approx(0.5)
            assert pool.waiting == 0

    run(check())


class RealNet:
    """A Zenoh router on loopback, and pools and stand-in workers on sessions of their own."""

    def __init__(self, endpoint: str) -> None:
        self.endpoint = endpoint
        self._transports: list[Transport] = []
        self._workers: list[ReconstructWorker] = []
        self._gates: list[Worker] = []

    async def pool(self) -> ReconstructorPool:
        transport = await Transport.open(self.endpoint, connect_timeout_s=10.0)
        self._transports.append(transport)
        pool = ReconstructorPool(transport, heartbeat_s=HEARTBEAT_S)
        pool.start()
        return pool

    async def worker(self, worker_id: str) -> Worker:
        worker = Worker(worker_id)
        worker.transport = transport = await Transport.open(self.endpoint, connect_timeout_s=10.0)
        self._transports.append(transport)
        worker.worker = ReconstructWorker(transport, worker_id, 1, worker.run)
        await worker.worker.start()
        self._gates.append(worker)
        return worker

    async def close(self) -> None:
        for gate in self._gates:
            gate.release()
            await gate.worker.close()
        for transport in reversed(self._transports):
            await transport.close()


@contextlib.asynccontextmanager
async def real_network():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = await Transport.open(endpoint, mode="router")
    net = RealNet(endpoint)
    try:
        yield net
    finally:
        try:
            await net.close()
        finally:
            await router.close()


async def until_real(predicate, what: str, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        await asyncio.sleep(0.01)


def test_over_a_real_router_a_hung_worker_keeps_its_token_and_is_passed_over_for_its_silence():
    """Its Zenoh session (and liveliness) lives on in Zenoh's threads; only the heartbeat stops."""
    async def check():
        async with real_network() as net:
            pool = await net.pool()
            hung_loop = LoopThread()
            unblock = threading.Event()
            try:
                async def block(request_json: str, payload: bytes) -> tuple[str, bytes]:
                    request = ReconstructRequest.model_validate_json(request_json)
                    unblock.wait(LIMIT_S)     # blocks the worker's whole event loop
                    return ReconstructReply(job_id=request.job_id, worker="hung", ticket=request.ticket,
                                            error=STAND_IN).model_dump_json(), b""

                transport = hung_loop.run(Transport.open(net.endpoint, connect_timeout_s=10.0))
                worker = ReconstructWorker(transport, "hung", 1, block)
                hung_loop.run(worker.start())
                healthy = await net.worker("healthy")
                healthy.hold()
                await until_real(lambda: len(pool.snapshot()) == 2 and all(r.heartbeat_age_s is not None
                                                                      for r in pool.snapshot()), "both workers")
                attempt = send(pool, "t1", avoid={"healthy"})
                with pytest.raises(AttemptFailed) as failed:
                    await attempt
                assert failed.value.worker == "hung" and failed.value.reason.startswith("no heartbeat for")
                assert [r.worker for r in pool.snapshot()] == ["healthy", "hung"]  # its token lives on
                assert {r.worker: r.healthy for r in pool.snapshot()} == {"hung": False, "healthy": True}
                retry = send(pool, "t2", avoid={"hung"})
                await until_real(lambda: healthy.tickets, "the retry at the healthy worker")
                unblock.set()                      # the hung worker wakes and answers t1: nobody listens
                await until_real(lambda: {r.worker: r.healthy for r in pool.snapshot()}.get("hung"),
                            "the woken worker's heartbeat")
                healthy.release()
                assert (await retry)[0] == "healthy"
            finally:
                unblock.set()
                with contextlib.suppress(Exception):
                    hung_loop.run(worker.close(), timeout=10)
                    hung_loop.run(transport.close(), timeout=10)
                hung_loop.close()

    asyncio.run(asyncio.wait_for(check(), LIMIT_S))
