"""Access by role, as deploy/cell-host.toml sets it up: on loopback, with TLS and users.

The router runs as ``robocell router`` with the deployment example's own
``[zenoh.roles]``, the daemon as ``robocell cell``, except that the robot and
camera workers have users of their own (``robot1``, ``camera1``): so each part
runs on its own role's rules alone, and a rule missing from any role fails the
whole scan and pick. The robot, camera and reconstruction workers are the real
worker code in this process, each in a Zenoh session of its user, so that the
test can count what reaches them. Each test plays one user: a client scans,
picks, follows and cancels its jobs; an observer reads; and nobody may do what
their role does not allow: move the robot, take pictures, publish job events,
join the reconstruction pool, serve or beat under another worker's id, pose as
a worker, or submit.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

from robocell.cli.demo import free_port
from tests.cell_fixtures import LoopThread, accepts, wait_until
from tests.pki import router_tls_settings, tls_settings, write_pki
from robocell.wire import keys
from robocell.wire.access import ROLES, access_control, permissions
from robocell.wire.client import CellClient
from robocell.wire.config import CellConfig, load_config
from robocell.wire.errors import CellError, NoResponder
from robocell.wire.messages import CaptureRequest, JobEvent, JobState, MoveRequest, PickRequest, ScanRequest, WorkerLoad
from robocell.wire.transport import Transport
from robocell.workers.camera.backend import Camera
from robocell.workers.camera.worker import make_camera, serve_camera
from robocell.workers.reconstruct.worker import ReconstructWorker, reconstruct_request
from robocell.workers.robot.worker import serve_robot
from robocell.workers.sim.robot import SceneGripper, SimRobot
from robocell.workers.sim.scene import target_from_config

DEPLOY = Path(__file__).resolve().parents[1] / "deploy"
#: The users of the router's dictionary: those deploy/cell-host.toml gives roles, and one it does not.
USERS = ("cell1", "robot1", "camera1", "recon1", "recon2", "alice", "bob", "dashboard", "intruder")
#: The reconstruction worker: its user name is its worker id (deploy/README.md).
RECONSTRUCTOR = "recon1"
START_TIMEOUT_S = 60.0
JOB_TIMEOUT_S = 60.0


def _password(user: str) -> str:
    return f"{user}-password"


# --- the rules, without a router -------------------------------------------------------------------

@pytest.mark.parametrize("users, named", [
    ({"cell1": {"operator": ["alice"]}}, "unknown role 'operator': expected one of client, observer"),
    ({"_pool": {"client": ["alice"]}}, "cell id '_pool' must be letters"),
    ({"cell1": {"client": ["al:ice"]}}, r"user name 'al:ice' \(client in cell1\) must be non-empty, without ':'"),
    ({"cell1": {"client": []}}, "no user has a role: the router would refuse every session"),
])
def test_bad_roles_are_refused_naming_what_is_wrong(users, named):
    with pytest.raises(ValueError, match=named):
        access_control(users)


def test_only_the_daemon_and_reconstruct_workers_touch_the_pool():
    for role in ROLES:
        granted = {key for verb, key in permissions(role, "bay7")}
        pool = {key for key in granted if key.startswith("robocell/_pool/")}
        assert granted - pool <= {key for key in granted if key.startswith("robocell/bay7/")}
        assert bool(pool) == (role in {"daemon", "reconstruct"}) and (pool == granted) == (role == "reconstruct")


def test_each_reconstruct_user_is_a_subject_of_its_own_in_every_cell():
    block = access_control({"bay1": {"reconstruct": ["r1"], "client": ["a"]},
                            "bay2": {"reconstruct": ["r2", "r1"]}})
    assert [(s["id"], s["usernames"]) for s in block["subjects"]] == [("client@bay1", ["a"]),
                                                                      ("reconstruct:r1", ["r1"]),
                                                                      ("reconstruct:r2", ["r2"])]
    assert len({rule["id"] for rule in block["rules"]}) == len(block["rules"])
    served = {key for rule in block["rules"] if rule["id"].startswith("reconstruct:r2 ")
              and "declare_queryable" in rule["messages"] for key in rule["key_exprs"]}
    assert served == {keys.reconstructor("r2"), keys.reconstructor_info("r2")}


# --- the deployed cell ---------------------------------------------------------------------------

class CountingRobot(SimRobot):
    """The simulated robot, counting its moves; while held, a move waits (at most 30 s) to begin."""

    def __init__(self, config: CellConfig) -> None:
        super().__init__(config.robot, gripper=SceneGripper.from_config(config))
        self.moves = 0
        self.free = asyncio.Event()
        self.free.set()

    async def move(self, target, on_progress):
        self.moves += 1
        async with asyncio.timeout(30.0):
            await self.free.wait()
        return await super().move(target, on_progress)


class CountingCamera(Camera):
    """A camera that counts the pictures it takes."""

    def __init__(self, camera: Camera) -> None:
        self._camera = camera
        self.shots = 0

    @property
    def source(self) -> str:
        return self._camera.source

    async def open(self) -> None:
        await self._camera.open()

    async def close(self) -> None:
        await self._camera.close()

    async def snapshot(self):
        self.shots += 1
        return await self._camera.snapshot()


class Cell:
    """The cell: router and daemon as child processes, the workers here, and a session per user."""

    def __init__(self, directory: Path) -> None:
        self.pki = write_pki(directory, {user: _password(user) for user in USERS})
        self.config_path = self._write_config(directory)
        self.config: CellConfig = load_config(self.config_path)
        self.endpoint = self.config.zenoh.router
        self.loop = LoopThread()
        self.children: list[subprocess.Popen] = []
        self.clients: dict[str, CellClient] = {}
        self.sessions: list[Transport] = []
        self.robot = CountingRobot(self.config)
        self.camera: CountingCamera | None = None
        self.robot_session: Transport | None = None
        self.reconstructor: ReconstructWorker | None = None

    def _write_config(self, directory: Path) -> Path:
        """deploy/cell-host.toml, roles and all, on a free loopback port with the test's certificates,
        a simulated robot and camera, and short time-outs."""
        data = tomllib.loads((DEPLOY / "cell-host.toml").read_text())
        data["run_dir"] = str(directory / "run")
        data["zenoh"].update(router=f"tls/127.0.0.1:{free_port()}", settings=tls_settings(self.pki),
                             router_settings=router_tls_settings(self.pki))
        data["zenoh"]["roles"].update(robot=["robot1"], camera=["camera1"])
        data["robot"] = {"backend": "sim", "speed": 0.0, "rotation_speed_deg": 0.0}
        data["camera"] = {"backend": "sim"}
        data["timeouts"] = {"move_s": 10.0, "capture_s": 10.0, "reconstruct_s": 30.0, "worker_wait_s": 1.0}
        path = directory / "cell.json"
        path.write_text(json.dumps(data))
        return path

    def settings(self, user: str) -> dict[str, object]:
        return {**tls_settings(self.pki), "transport/auth/usrpwd/user": user,
                "transport/auth/usrpwd/password": _password(user)}

    # --- starting and stopping ---------------------------------------------------------------

    def start(self) -> None:
        environment = {**os.environ, "ROBOCELL_ZENOH_PASSWORD": _password(self.config.zenoh.user or "")}
        for command in ("router", "cell"):
            with open(self.config_path.with_name(f"{command}.log"), "ab") as log:
                self.children.append(subprocess.Popen(
                    [sys.executable, "-m", "robocell", "--config", str(self.config_path), command],
                    stdin=subprocess.DEVNULL, stdout=log, stderr=log, env=environment))
            if command == "router":  # a session that finds no router tries again only a second later
                wait_until(self._router_listening, timeout=START_TIMEOUT_S, interval=0.05, what="the router")
        self.loop.run(self._start_workers(), timeout=START_TIMEOUT_S)
        self.wait_for_parts(robot=True)

    def _router_listening(self) -> bool:
        assert self.children[0].poll() is None, f"the router exited; see {self.config_path.parent}"
        host, port = self.endpoint.removeprefix("tls/").rsplit(":", 1)
        return accepts(host, int(port))

    async def _start_workers(self) -> None:
        await self.start_robot()
        camera_session = await self.open("camera1")
        self.camera = CountingCamera(make_camera(self.config, camera_session))
        await self.camera.open()
        serve_camera(camera_session, self.config, self.camera)
        camera_session.declare_token(keys.alive(self.config.cell_id, "camera"))

        async def reconstruct(request_json: str, payload: bytes) -> tuple[str, bytes]:
            return await asyncio.to_thread(reconstruct_request, request_json, payload, RECONSTRUCTOR)

        self.reconstructor = ReconstructWorker(await self.open(RECONSTRUCTOR), RECONSTRUCTOR, 2, reconstruct)
        await self.reconstructor.start()

    async def start_robot(self) -> None:
        self.robot_session = await Transport.open(self.endpoint, settings=self.settings("robot1"), connect_timeout_s=20)
        serve_robot(self.robot_session, self.config, self.robot)
        self.robot_session.declare_token(keys.alive(self.config.cell_id, "robot"))

    async def stop_robot(self) -> None:
        assert self.robot_session is not None
        await self.robot_session.close()
        self.robot_session = None

    async def open(self, user: str) -> Transport:
        """A session of ``user``'s, closed with the cell."""
        session = await Transport.open(self.endpoint, settings=self.settings(user), connect_timeout_s=20)
        self.sessions.append(session)
        return session

    def wait_for_parts(self, *, robot: bool) -> None:
        """Until the daemon (asked by alice) sees the camera, the reconstructor, and the robot if ``robot``."""
        def ready() -> bool:
            for child in self.children:
                assert child.poll() is None, f"{child.args[-1]} exited; see {self.config_path.parent}"
            try:
                status = self.client("alice").cell_status()
            except CellError:
                return False
            return (status.workers.get("robot", False) == robot and status.workers.get("camera", False)
                    and any(r.worker == RECONSTRUCTOR for r in status.reconstructors))

        wait_until(ready, timeout=START_TIMEOUT_S, interval=0.1, what=f"the cell with the robot {'up' if robot else 'gone'}")

    def close(self) -> None:
        try:
            for client in self.clients.values():
                client.close()

            async def close_parts() -> None:
                if self.reconstructor is not None:
                    await self.reconstructor.close()
                if self.camera is not None:
                    await self.camera.close()
                for session in [*self.sessions, *([self.robot_session] if self.robot_session else [])]:
                    await session.close()

            self.loop.run(close_parts(), timeout=30)
        finally:
            self.loop.close()
            for child in self.children:
                child.terminate()
            for child in self.children:
                try:
                    child.wait(10)
                except subprocess.TimeoutExpired:
                    child.kill()
                    child.wait(10)

    # --- what the tests do -------------------------------------------------------------------

    def client(self, user: str) -> CellClient:
        """A blocking client of the cell, logged in as ``user``."""
        if user not in self.clients:
            self.clients[user] = CellClient(self.endpoint, self.config.cell_id, settings=self.settings(user),
                                            timeout=10.0)
        return self.clients[user]

    def request(self, **fields) -> ScanRequest:
        return ScanRequest(target=target_from_config(self.config.sim), **fields)

    @contextlib.contextmanager
    def robot_held(self):
        """The robot's next moves wait until the block ends."""
        self.loop.run(_call(self.robot.free.clear))
        try:
            yield
        finally:
            self.loop.run(_call(self.robot.free.set))

    def job_count(self) -> int:
        return sum(self.client("alice").cell_status().jobs.values())


async def _call(function):
    return function()


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    running = Cell(tmp_path_factory.mktemp("access"))
    try:
        running.start()
        yield running
    finally:
        running.close()


def _wait_state(client: CellClient, job_id: str, state: JobState) -> None:
    wait_until(lambda: client.status(job_id).state is state, timeout=JOB_TIMEOUT_S, interval=0.02,
               what=f"job {job_id} {state.value}")


def test_a_client_scans_follows_lists_and_cancels_its_jobs(cell):
    alice = cell.client("alice")
    heard: list[JobEvent] = []
    job = alice.submit(cell.request(label="alice's"))
    final = alice.wait(job.job_id, timeout=JOB_TIMEOUT_S, on_event=heard.append)
    assert final.state is JobState.SUCCEEDED, final.error
    result = alice.result(job.job_id)
    centre = np.asarray(result.superquadric.T_world_object)[:3, 3]
    assert np.linalg.norm(centre - target_from_config(cell.config.sim)) < 0.01
    assert result.worker == RECONSTRUCTOR
    assert {event.state for event in heard} >= {JobState.MOVING, JobState.CAPTURING}
    assert job.job_id in [status.job_id for status in alice.list()]

    with cell.robot_held():
        held = alice.submit(cell.request(label="to cancel"))
        _wait_state(alice, held.job_id, JobState.MOVING)
        assert alice.cancel(held.job_id).state is JobState.CANCELLED
    assert alice.wait(held.job_id, timeout=JOB_TIMEOUT_S).state is JobState.CANCELLED


def test_an_observer_reads_but_cannot_submit_or_cancel(cell):
    alice, dashboard = cell.client("alice"), cell.client("dashboard")
    with cell.robot_held():
        job = alice.submit(cell.request(label="watched"))
        _wait_state(dashboard, job.job_id, JobState.MOVING)
        with pytest.raises(NoResponder):
            dashboard.cancel(job.job_id)
        jobs = cell.job_count()
        with pytest.raises(NoResponder):
            dashboard.submit(cell.request(label="the observer's"))
        assert cell.job_count() == jobs
        assert dashboard.status(job.job_id).state is JobState.MOVING
    assert dashboard.wait(job.job_id, timeout=JOB_TIMEOUT_S).state is JobState.SUCCEEDED
    assert dashboard.result(job.job_id).job_id == job.job_id
    assert job.job_id in [status.job_id for status in dashboard.list()]
    assert dashboard.cell_status().workers == {"robot": True, "camera": True}


def test_a_denied_command_says_the_user_may_not_ask(cell, tmp_path, monkeypatch, capsys):
    """Zenoh drops a denied query unanswered: the command line names that reason beside a missing daemon."""
    from robocell.cli.main import main

    config = json.loads(cell.config_path.read_text())
    config["zenoh"]["user"] = "dashboard"
    path = tmp_path / "dashboard.json"
    path.write_text(json.dumps(config))
    monkeypatch.setenv("ROBOCELL_ZENOH_PASSWORD", _password("dashboard"))
    assert main(["--config", str(path), "cancel", "no-such-job"]) == 1
    assert capsys.readouterr().err == (
        f"robocell cancel: no cell daemon is running for cell {cell.config.cell_id} at {cell.endpoint}, or the "
        f"router's access control does not let user 'dashboard' ask it\n")


def test_a_client_cannot_move_the_robot_or_take_pictures(cell):
    moves, shots = cell.robot.moves, cell.camera.shots
    home = cell.config.robot.home

    async def try_parts() -> None:
        alice = await cell.open("alice")
        with pytest.raises(NoResponder):
            await alice.query(keys.robot_move(cell.config.cell_id), MoveRequest(T_base_flange=home).model_dump_json(),
                              timeout=5.0)
        with pytest.raises(NoResponder):
            await alice.query(keys.camera_capture(cell.config.cell_id), CaptureRequest(view=0).model_dump_json(),
                              timeout=5.0)

    cell.loop.run(try_parts())
    assert (cell.robot.moves, cell.camera.shots) == (moves, shots)
    # The daemon still may: a scan moves the robot and takes a picture at each of its views.
    job = cell.client("alice").submit(cell.request())
    assert cell.client("alice").wait(job.job_id, timeout=JOB_TIMEOUT_S).state is JobState.SUCCEEDED
    views = len(cell.client("alice").result(job.job_id).T_base_cam)
    assert (cell.robot.moves - moves, cell.camera.shots - shots) == (views, views)


def test_a_client_cannot_publish_job_events(cell):
    alice = cell.client("alice")
    heard: list[JobEvent] = []

    async def listen() -> None:
        subscription = (await cell.open("dashboard")).subscribe(keys.events(cell.config.cell_id))

        async def follow() -> None:
            async for sample in subscription:
                heard.append(JobEvent.model_validate_json(sample.payload))

        asyncio.ensure_future(follow())

    cell.loop.run(listen())
    with cell.robot_held():
        job = alice.submit(cell.request(label="followed"))
        wait_until(lambda: any(e.job_id == job.job_id for e in heard), timeout=JOB_TIMEOUT_S,
                   what="the dashboard hearing the job's first event")
        forged = JobEvent(job_id=job.job_id, state=JobState.SUCCEEDED, message="made up by alice", time=time.time())

        async def forge() -> None:
            (await cell.open("alice")).put(keys.events(cell.config.cell_id, job.job_id), forged.model_dump_json())

        cell.loop.run(forge())
    assert alice.wait(job.job_id, timeout=JOB_TIMEOUT_S).state is JobState.SUCCEEDED
    wait_until(lambda: any(e.job_id == job.job_id and e.state is JobState.SUCCEEDED for e in heard),
               timeout=JOB_TIMEOUT_S, what="the dashboard hearing the job succeed")
    succeeded = [e for e in heard if e.job_id == job.job_id and e.state is JobState.SUCCEEDED]
    assert len(succeeded) == 1 and succeeded[0].message != forged.message and succeeded[0].result is not None


def test_a_client_cannot_join_the_reconstruction_pool(cell):
    """The attack of issue 12: a fake worker that got the pictures of jobs and answered them."""
    received: dict[str, list[str]] = {}

    async def start_fake(user: str, worker_id: str) -> ReconstructWorker:
        received[worker_id] = []

        async def made_up(request_json: str, payload: bytes) -> tuple[str, bytes]:
            received[worker_id].append(request_json)
            return await asyncio.to_thread(reconstruct_request, request_json, payload, worker_id)

        worker = ReconstructWorker(await cell.open(user), worker_id, 8, made_up)
        await worker.start()
        return worker

    def listed(worker: str) -> bool:
        return any(r.worker == worker for r in cell.client("alice").cell_status().reconstructors)

    # A reconstruct user joins the pool under its own id (its user name); so it is the role that keeps others out.
    began = time.monotonic()
    genuine = cell.loop.run(start_fake("recon2", "recon2"))
    wait_until(lambda: listed("recon2"), timeout=START_TIMEOUT_S, what="the daemon seeing a reconstruct user's worker")
    joined_s = time.monotonic() - began
    cell.loop.run(genuine.close())
    wait_until(lambda: not listed("recon2"), timeout=START_TIMEOUT_S, what="the worker leaving the pool")

    # A client's worker, and a reconstruct user's worker under another id than its own, are kept out.
    fakes = [cell.loop.run(start_fake("alice", "fake-alice")), cell.loop.run(start_fake("recon2", "fake-recon2"))]
    try:
        time.sleep(2 * joined_s + keys.HEARTBEAT_PERIOD_S)  # twice what the genuine one took to join, and a beat
        assert not listed("fake-alice") and not listed("fake-recon2")
        # Idle with 8 slots, the fakes would get both jobs were they in the pool (ties go to the least used).
        jobs = [cell.client("alice").submit(cell.request(label=f"pool {i}")).job_id for i in range(2)]
        for job_id in jobs:
            assert cell.client("alice").wait(job_id, timeout=JOB_TIMEOUT_S).state is JobState.SUCCEEDED
            assert cell.client("alice").result(job_id).worker == RECONSTRUCTOR
        assert received["fake-alice"] == received["fake-recon2"] == []
    finally:
        for fake in fakes:
            cell.loop.run(fake.close())


def test_a_reconstruct_user_cannot_make_another_worker_look_busy(cell):
    """Issue 23: busy heartbeats under the real worker's id took 4 of 5 jobs elsewhere."""
    busy = WorkerLoad(worker=RECONSTRUCTOR, capacity=1, in_flight=99, period_s=0.1, time=time.time(),
                      started=time.time())

    async def forge() -> None:
        session = await cell.open("recon2")
        for _ in range(20):
            # Under recon1's key the router drops it; under its own, every daemon ignores it.
            session.put(keys.reconstructor_heartbeat(RECONSTRUCTOR), busy.model_dump_json())
            session.put(keys.reconstructor_heartbeat("recon2"), busy.model_dump_json())
            await asyncio.sleep(0.05)

    cell.loop.run(forge())
    seen = {r.worker: r for r in cell.client("alice").cell_status().reconstructors}[RECONSTRUCTOR]
    assert (seen.capacity, seen.in_flight) == (2, 0)


def test_a_client_scans_and_picks_with_every_part_on_its_own_roles_rules(cell):
    """Issue 23: under deploy/'s access control ``scan --pick`` always failed (no rule for the
    gripper). Here the daemon, robot, camera and reconstruction worker each have a user and role
    of their own; alice scans and picks, and the dashboard follows and reads it."""
    alice, dashboard = cell.client("alice"), cell.client("dashboard")
    moves = cell.robot.moves
    heard: list[JobEvent] = []
    result = alice.scan(cell.request(label="pick", pick=PickRequest(place=[0.55, 0.25])), timeout=JOB_TIMEOUT_S,
                        on_event=heard.append)
    assert result.pick is not None and result.pick.held is True, result.pick
    assert result.pick.placed and result.worker == RECONSTRUCTOR
    assert cell.robot.moves - moves == len(result.T_base_cam) + 6    # the views, and the pick's six moves
    assert JobState.PICKING in {event.state for event in heard}
    assert dashboard.status(result.job_id).state is JobState.SUCCEEDED
    assert dashboard.result(result.job_id).pick == result.pick


def test_a_client_cannot_pose_as_the_robot(cell):
    alice = cell.client("alice")

    async def pose_as_robot() -> None:
        (await cell.open("alice")).declare_token(keys.alive(cell.config.cell_id, "robot"))

    cell.loop.run(pose_as_robot())
    cell.loop.run(cell.stop_robot())
    try:
        cell.wait_for_parts(robot=False)  # the daemon sees the robot go, alice's token notwithstanding
        job = alice.submit(cell.request(label="without a robot"))
        final = alice.wait(job.job_id, timeout=JOB_TIMEOUT_S)
        assert final.state is JobState.FAILED and "no robot worker" in (final.error or "")
    finally:
        cell.loop.run(cell.start_robot())
        cell.wait_for_parts(robot=True)


@pytest.mark.parametrize("user", ["recon1", "robot1", "camera1", "dashboard", "intruder"],
                         ids=["a reconstruct worker", "the robot", "the camera", "an observer", "a user without a role"])
def test_only_clients_submit(cell, user):
    jobs = cell.job_count()
    with pytest.raises(NoResponder):
        cell.client(user).submit(cell.request(label=f"{user}'s"))
    assert cell.job_count() == jobs
    if user == "intruder":
        with pytest.raises(NoResponder):
            cell.client(user).list()
