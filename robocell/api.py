"""robocell's Python API: :class:`Client` for scripts, :class:`AsyncClient` for asyncio programs.

Both talk to a running cell (``robocell up``, or a deployment) over its Zenoh router, and return
the typed messages of ``wire.messages`` (pydantic models): :class:`ScanResult`,
:class:`JobStatus`, :class:`JobEvent`, :class:`CellStatus`. A job that fails or is cancelled
raises :class:`JobFailed`, whose ``kind`` is the error's class (``"EmergencyStop"``, say); an
error the cell answers with raises its class from ``wire.errors`` (:class:`MoveRefused`, ...),
all of them :class:`CellError`. A script::

    import robocell

    with robocell.Client("tcp/127.0.0.1:7447", cell="cell1") as cell:
        result = cell.scan([0.6, 0.0, 0.05])
        print(result.superquadric.size, len(result.grasps))
        picked = cell.pick([0.6, 0.0, 0.05], place=[0.6, 0.15])
        print(picked.pick.held)

Settings for a deployment (TLS, a Zenoh user) come from the cell's configuration file:
``robocell.Client.from_config("client.toml")`` (the password from ``ROBOCELL_ZENOH_PASSWORD``),
or as Zenoh configuration keys in ``settings``.

These wrap ``wire.client.AsyncCellClient``, which speaks the documented keys (README, "The wire
contract"); a program in another language does the same with any Zenoh binding.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import AsyncIterator, Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, TypeVar

from robocell.wire.client import AsyncCellClient, JobFailed
from robocell.wire.config import CellConfig, load_config
from robocell.wire.errors import CellError
from robocell.wire.messages import (CellStatus, JobEvent, JobState, JobStatus, PickRequest, ScanRequest, ScanResult,
                           ViewPlan)

__all__ = ["Client", "AsyncClient", "JobFailed", "CellError", "ScanRequest", "ScanResult", "JobStatus",
           "JobEvent", "JobState", "CellStatus"]

T = TypeVar("T")
#: How long a whole scan (or pick) may take before :meth:`AsyncClient.scan` gives up waiting.
DEFAULT_JOB_TIMEOUT_S = 120.0


def _request(target: Sequence[float] | None, poses, plan: dict | ViewPlan | None, pick: PickRequest | None,
             label: str, request_id: str | None) -> ScanRequest:
    if (target is None) == (poses is None):
        raise ValueError("give either a target point [x, y, z] or flange poses, not both")
    plan = ViewPlan.model_validate(plan) if isinstance(plan, dict) else plan
    return ScanRequest(target=None if target is None else list(target), flange_poses=poses, plan=plan, pick=pick,
                       label=label, request_id=request_id)


def _config(config: CellConfig | str | Path | None) -> CellConfig:
    return config if isinstance(config, CellConfig) else load_config(config)


class AsyncClient:
    """A cell, from an asyncio program. Open it with :meth:`connect` (or :meth:`from_config`),
    use it in ``async with``::

        async with await robocell.AsyncClient.connect("tcp/127.0.0.1:7447", cell="cell1") as cell:
            result = await cell.scan([0.6, 0.0, 0.05])
            async for event in cell.events():      # every job's events, as they happen
                print(event.job_id, event.state.value, event.message)
    """

    def __init__(self, client: AsyncCellClient) -> None:
        self._client = client

    @classmethod
    async def connect(cls, router: str = "tcp/127.0.0.1:7447", *, cell: str = "cell1",
                      settings: dict[str, Any] | None = None, timeout: float = 5.0) -> AsyncClient:
        """Connect to the cell ``cell`` through the router at ``router``.

        ``settings`` are Zenoh configuration keys (``{"transport/link/tls/root_ca_certificate":
        "ca.pem"}``, say); ``timeout`` bounds every query, in seconds.

        Raises
        ------
        CellError
            The router cannot be reached (the message says where, and why).
        """
        return cls(await AsyncCellClient.connect(router, cell, settings=settings, timeout=timeout))

    @classmethod
    async def from_config(cls, config: CellConfig | str | Path | None = None, *, timeout: float = 5.0) -> AsyncClient:
        """Connect as the cell's configuration says (``[zenoh]`` router, settings and user, ``cell_id``);
        a path is read as ``robocell --config`` reads it; None: the defaults."""
        config = _config(config)
        return await cls.connect(config.zenoh.router, cell=config.cell_id, settings=config.zenoh.client_settings(),
                                 timeout=timeout)

    @property
    def cell(self) -> str:
        return self._client.cell

    async def close(self) -> None:
        """Close the Zenoh session (a session left open holds the interpreter at exit)."""
        await self._client.close()

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    async def scan(self, target: Sequence[float] | None = None, *, poses: list | None = None,
                   plan: dict | ViewPlan | None = None, label: str = "", request_id: str | None = None,
                   timeout: float = DEFAULT_JOB_TIMEOUT_S,
                   on_event: Callable[[JobEvent], None] | None = None) -> ScanResult:
        """Scan the object at ``target`` (robot base frame, metres; views from the cell's plan, or
        ``plan``), or from the flange ``poses`` (4x4 flange-to-base each), and return its model.

        Raises
        ------
        JobFailed
            The job failed or was cancelled (``.kind`` says of what, ``.status`` is its last status).
        TimeoutError
            Not finished within ``timeout`` seconds (the job goes on: :meth:`cancel` stops it).
        """
        request = _request(target, poses, plan, None, label, request_id)
        return await self._client.scan(request, timeout=timeout, on_event=on_event)

    async def pick(self, target: Sequence[float] | None = None, *, place: Sequence[float] | None = None,
                   approach_m: float = 0.1, lift_m: float = 0.1, poses: list | None = None,
                   plan: dict | ViewPlan | None = None, label: str = "", request_id: str | None = None,
                   timeout: float = DEFAULT_JOB_TIMEOUT_S,
                   on_event: Callable[[JobEvent], None] | None = None) -> ScanResult:
        """Scan as :meth:`scan`, then pick the object up with the best grasp the robot can reach and
        lift it ``lift_m``; with ``place`` ([x, y]), set it down there. ``result.pick`` says how it went.

        Raises
        ------
        JobFailed, TimeoutError
            As :meth:`scan`.
        """
        pick = PickRequest(approach_m=approach_m, lift_m=lift_m, place=None if place is None else list(place))
        request = _request(target, poses, plan, pick, label, request_id)
        return await self._client.scan(request, timeout=timeout, on_event=on_event)

    async def submit(self, request: ScanRequest) -> JobStatus:
        """Queue a job without waiting for it; follow it with :meth:`wait`, :meth:`events`, :meth:`status`."""
        self._client.listen()  # so that a wait begun after the submit still hears the job's first events
        return await self._client.submit(request)

    async def wait(self, job_id: str, *, timeout: float = DEFAULT_JOB_TIMEOUT_S,
                   on_event: Callable[[JobEvent], None] | None = None) -> JobStatus:
        """The job's final status, once it has ended (succeeded, failed or cancelled).

        Raises
        ------
        TimeoutError
            It has not ended within ``timeout`` seconds.
        """
        return await self._client.wait(job_id, timeout=timeout, on_event=on_event)

    async def cancel(self, job_id: str) -> JobStatus:
        """Ask the cell to cancel a job: it stops at the end of its current step (``cancelling``, then
        ``cancelled``)."""
        return await self._client.cancel(job_id)

    async def status(self, job_id: str) -> JobStatus:
        """A job's status now."""
        return await self._client.status(job_id)

    async def result(self, job_id: str) -> ScanResult:
        """A succeeded job's result.

        Raises
        ------
        CellError
            The job has not succeeded (or does not exist).
        """
        return await self._client.result(job_id)

    async def jobs(self, states: set[JobState] | None = None, limit: int = 50) -> list[JobStatus]:
        """The cell's jobs, newest first; only those in ``states``, if given."""
        return await self._client.list(states, limit)

    async def cell_status(self, *, failures: int = 10) -> CellStatus:
        """The cell at a glance: workers, their load, the queue, jobs by state, recent failures."""
        return await self._client.cell_status(failures=failures)

    def events(self, job_id: str = "*") -> AsyncIterator[JobEvent]:
        """The events of one job (or of every job, ``"*"``) as they happen, until the caller stops."""
        return self._client.events(job_id)


class Client:
    """A cell, from a script: every method of :class:`AsyncClient`, blocking. Use it in ``with`` (or
    call :meth:`close`): it closes the Zenoh session, which otherwise holds the interpreter at exit."""

    def __init__(self, router: str = "tcp/127.0.0.1:7447", *, cell: str = "cell1",
                 settings: dict[str, Any] | None = None, timeout: float = 5.0) -> None:
        """As :meth:`AsyncClient.connect`."""
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="robocell-client", daemon=True)
        self._thread.start()
        try:
            self._async = self._call(AsyncClient.connect(router, cell=cell, settings=settings, timeout=timeout))
        except BaseException:
            self._stop_loop()
            raise

    @classmethod
    def from_config(cls, config: CellConfig | str | Path | None = None, *, timeout: float = 5.0) -> Client:
        """As :meth:`AsyncClient.from_config`."""
        config = _config(config)
        return cls(config.zenoh.router, cell=config.cell_id, settings=config.zenoh.client_settings(), timeout=timeout)

    def _call(self, coroutine, timeout: float | None = None):
        future = asyncio.run_coroutine_threadsafe(coroutine, self._loop)
        try:
            return future.result(timeout)
        except TimeoutError:
            future.cancel()
            raise

    def _stop_loop(self) -> None:
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5)
        self._loop.close()

    @property
    def cell(self) -> str:
        return self._async.cell

    def close(self) -> None:
        try:
            self._call(self._async.close(), timeout=10)
        finally:
            self._stop_loop()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def scan(self, target: Sequence[float] | None = None, **options: Any) -> ScanResult:
        """As :meth:`AsyncClient.scan`."""
        return self._call(self._async.scan(target, **options))

    def pick(self, target: Sequence[float] | None = None, **options: Any) -> ScanResult:
        """As :meth:`AsyncClient.pick`."""
        return self._call(self._async.pick(target, **options))

    def submit(self, request: ScanRequest) -> JobStatus:
        return self._call(self._async.submit(request))

    def wait(self, job_id: str, *, timeout: float = DEFAULT_JOB_TIMEOUT_S,
             on_event: Callable[[JobEvent], None] | None = None) -> JobStatus:
        return self._call(self._async.wait(job_id, timeout=timeout, on_event=on_event))

    def cancel(self, job_id: str) -> JobStatus:
        return self._call(self._async.cancel(job_id))

    def status(self, job_id: str) -> JobStatus:
        return self._call(self._async.status(job_id))

    def result(self, job_id: str) -> ScanResult:
        return self._call(self._async.result(job_id))

    def jobs(self, states: set[JobState] | None = None, limit: int = 50) -> list[JobStatus]:
        return self._call(self._async.jobs(states, limit))

    def cell_status(self, *, failures: int = 10) -> CellStatus:
        return self._call(self._async.cell_status(failures=failures))

    def events(self, job_id: str = "*", *, timeout: float | None = None) -> Iterator[JobEvent]:
        """The events of one job (or of every job), as they happen; each waited for at most
        ``timeout`` seconds (then ``TimeoutError``, which ends the iteration), or for ever. Stop
        iterating to stop listening."""
        events = self._async.events(job_id)
        try:
            while True:
                try:
                    yield self._call(_next(events), timeout)
                except StopAsyncIteration:
                    return
        finally:
            self._call(_close(events), timeout=5)


async def _next(events: AsyncIterator[JobEvent]) -> JobEvent:
    return await events.__anext__()


async def _close(events: AsyncIterator[JobEvent]) -> None:
    close = getattr(events, "aclose", None)
    if close is not None:
        await close()
