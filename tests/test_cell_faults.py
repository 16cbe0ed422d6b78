"""Faults and cancels, end to end: the daemon fails (or cancels) the job with a clear reason and stays up.

Router, robot worker, camera worker and daemon are child processes. The
simulated Axis camera (behind digest authentication) runs in the test
process, so that it can be told to fail; so does the only reconstruction
worker, which can be held at a gate to keep a job reconstructing.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import pytest
from rerun.chunk import RrdReader

from robocell.wire.errors import NoResponder, RemoteError, StoreError
from robocell.wire.messages import (ACTIVITIES, POINTS_ENCODING, Blob, JobState, Reconstruction, ReconstructReply,
                           ReconstructRequest, Superquadric)
from robocell.wire.transport import Transport
from robocell.cell.recording import recording_problem
from robocell.cell.store import JobStore

from tests.cell_fixtures import (SMALL_CAMERA, GatedReconstructor, InProcessSimCamera, InProcessWorker, RunningCell,
                                 cell_config, running_cell, wait_until)

PASSWORD = "s3cret"


@dataclasses.dataclass
class Rig:
    cell: RunningCell
    camera: InProcessSimCamera
    reconstructor: GatedReconstructor

    def failed_job(self, **fields) -> tuple[str, str]:
        """Submit a scan that must fail; its id and error."""
        status = self.cell.submit(**fields)
        final = self.cell.wait(status.job_id)
        assert final.state is JobState.FAILED, final
        return final.job_id, final.error

    def events(self, job_id: str) -> list[tuple[str, int | None]]:
        return [(e.state.value, e.view) for e in self.cell.events(job_id)]


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    config = cell_config(tmp_path_factory.mktemp("cell-faults"), cell_id="faults",
                         camera={**SMALL_CAMERA, "username": "root", "password": PASSWORD, "timeout_s": 2.0})
    with running_cell(config, reconstructors=0, sim_camera=False) as cell:
        camera = InProcessSimCamera(config)
        try:
            camera.start()
            reconstructor = GatedReconstructor(cell.loop, cell.router)
            try:
                yield Rig(cell, camera, reconstructor)
            finally:
                reconstructor.close()
        finally:
            camera.close()


def test_scan_through_digest_authentication(rig):
    status = rig.cell.submit()
    assert rig.cell.wait(status.job_id).state is JobState.SUCCEEDED
    assert rig.cell.client.result(status.job_id).timings_ms["total"] > 0
    assert len(rig.reconstructor.received) == 1


@pytest.mark.parametrize("fault, reason, kind", [
    ({"status": 500}, "answered HTTP 500 Internal Server Error: Simulated fault: HTTP 500; gave up after 2 attempts"
                      " (waited 1 s for it)", "CameraResponseError"),
    ({"garbage": True}, "answered, but not a JPEG: the body does not start with the JPEG marker FF D8; "
                        "gave up after 2 attempts", "CameraResponseError"),
    ({"hang_s": 5.0}, "did not answer within 2 s; gave up after 2 attempts (waited 1 s for it)", "CameraTimeout"),
], ids=["500", "garbage", "nothing"])
def test_a_camera_fault_fails_the_job_once_the_outage_allowance_is_spent(rig, fault, reason, kind):
    """A camera that does not answer, or answers a server error, is waited for (1 s in this cell),
    then the job fails naming it; a camera that answers what is not a picture fails it at once."""
    server = rig.camera.server
    attempts = rig.cell.config.camera.retries + 1
    server.fail_next(**fault, count=100)
    before = server.request_count
    try:
        job_id, error = rig.failed_job()
    finally:
        server.clear_faults()
    assert error == f"capturing view 0: camera at {rig.camera.config.camera.url} {reason}"
    assert rig.cell.client.status(job_id).error_kind == kind  # the camera's error keeps its class
    tries = server.request_count - before
    if "garbage" in fault:
        assert tries == attempts  # retried by the camera worker, and only so often
    else:
        assert attempts <= tries <= 6 * attempts  # bounded: a try every 0.5 s for 1 s
    assert rig.events(job_id)[-1] == ("failed", None)


def test_a_camera_away_for_less_than_the_outage_allowance_costs_no_job(rig):
    server = rig.camera.server
    server.fail_next(status=503, count=3)   # the first capture's two tries, and one more
    status = rig.cell.submit()
    final = rig.cell.wait(status.job_id)
    assert final.state is JobState.SUCCEEDED, final.error
    messages = [e.message for e in rig.cell.events(status.job_id)]
    assert any("HTTP 503" in m and "waiting up to 1 s, then trying again" in m for m in messages), messages


def test_camera_refusing_the_password_fails_the_job_without_retrying(rig):
    rig.camera.restart(password="another password")  # the configured one is now wrong
    try:
        job_id, error = rig.failed_job()
        assert error == (f"capturing view 0: camera at {rig.camera.config.camera.url} refused the "
                         "credentials of user 'root' (HTTP 401)")
        assert PASSWORD not in error
    finally:
        rig.camera.restart()
    for name in ("camera", "daemon", "robot"):
        assert PASSWORD not in rig.cell.log(name)


def test_missing_camera_worker_makes_the_job_wait_then_fail(rig):
    cell = rig.cell
    cell.loop.run(cell.processes.stop_child("camera"))
    try:
        job_id, error = rig.failed_job()
        assert error == "capturing view 0: no camera worker is running (waited 1 s)"
        events = cell.events(job_id)
        assert [e.state.value for e in events[-2:]] == ["capturing", "failed"]
        assert events[-1].time - events[-2].time >= cell.config.timeouts.outage_s * 0.9
    finally:
        cell.loop.run(cell.processes.start_child("camera"))


def test_missing_reconstruction_worker_makes_the_job_wait_then_fail(rig):
    rig.reconstructor.withdraw()
    try:
        job_id, error = rig.failed_job()
        assert error == "reconstructing: no reconstruction worker is running (waited 1 s)"
    finally:
        rig.reconstructor.announce()


def test_cancel_while_capturing(rig):
    cell = rig.cell
    rig.camera.server.fail_next(hang_s=5.0)  # the first attempt hangs (the camera worker gives up after 2 s)
    status = cell.submit()
    cell.wait_state(status.job_id, {JobState.CAPTURING})
    assert cell.client.cancel(status.job_id).state is JobState.CANCELLED
    final = cell.wait(status.job_id, timeout=10)
    assert final.state is JobState.CANCELLED
    assert rig.events(status.job_id)[-3:] == [("capturing", 0), ("cancelling", 0), ("cancelled", None)]


def test_cancel_while_reconstructing(rig):
    cell = rig.cell
    rig.reconstructor.hold()
    try:
        status = cell.submit()
        cell.wait_state(status.job_id, {JobState.RECONSTRUCTING})
        assert rig.reconstructor.waiting.wait(10.0)
        assert cell.client.cancel(status.job_id).state is JobState.CANCELLED
        final = cell.wait(status.job_id, timeout=10)
    finally:
        rig.reconstructor.release()
    assert final.state is JobState.CANCELLED
    assert rig.events(status.job_id)[-3:] == [("reconstructing", None), ("cancelling", None), ("cancelled", None)]
    # The reconstructor's late answer changes nothing.
    wait_until(lambda: rig.reconstructor.answered == len(rig.reconstructor.received), timeout=30,
               what="the reconstructor's answer")
    again = cell.client.status(status.job_id)
    assert again.state is JobState.CANCELLED and again.updated == final.updated
    with pytest.raises(RemoteError, match="has no result: it is cancelled"):
        cell.client.result(status.job_id)


def test_after_every_fault_the_daemon_still_scans(rig):
    cell = rig.cell
    assert cell.daemon_running()
    status = cell.submit()
    assert cell.wait(status.job_id).state is JobState.SUCCEEDED
    assert cell.tracebacks() == {}


def test_a_daemon_killed_during_a_reconstruction_resumes_it_from_the_pictures(rig):
    """No job ends "interrupted": the pictures were taken and kept, so the restarted daemon sends
    them again instead of moving the robot."""
    cell = rig.cell
    rig.reconstructor.hold()
    sent = len(rig.reconstructor.received)
    try:
        status = cell.submit()
        cell.wait_state(status.job_id, {JobState.RECONSTRUCTING})
        assert rig.reconstructor.waiting.wait(10.0)
        pictures_taken = rig.camera.server.request_count
        assert cell.loop.run(cell.processes.stop_child("daemon", kill=True)) == -9
        cell.loop.run(cell.processes.start_child("daemon"))
        wait_until(lambda: any("the daemon restarted" in e.message for e in cell.events(status.job_id)),
                   timeout=30, what="the restarted daemon carrying the job on")
    finally:
        rig.reconstructor.release()  # the first request (whose asker is gone) ends; the job's waits behind it
    # Sent again from the kept pictures.
    wait_until(lambda: len(rig.reconstructor.received) == sent + 2, timeout=30, what="the reconstruction sent again")
    final = cell.wait(status.job_id)
    assert final.state is JobState.SUCCEEDED, final.error
    assert rig.camera.server.request_count == pictures_taken  # no picture taken again
    states = [e.state for e in cell.events(status.job_id)]
    assert states.count(JobState.MOVING) == 3 and states[-1] is JobState.SUCCEEDED
    with JobStore(cell.config.run_dir / "jobs.sqlite") as store:
        assert store.pictures(status.job_id) == []  # the recording keeps them


def test_a_daemon_killed_during_the_views_takes_them_again(rig):
    cell = rig.cell
    rig.camera.server.fail_next(hang_s=20.0)  # the first snapshot hangs: the job stays capturing
    status = cell.submit()
    cell.wait_state(status.job_id, {JobState.CAPTURING})
    assert cell.loop.run(cell.processes.stop_child("daemon", kill=True)) == -9
    rig.camera.server.clear_faults()
    cell.loop.run(cell.processes.start_child("daemon"))
    final = cell.wait(status.job_id)
    assert final.state is JobState.SUCCEEDED, final.error
    events = cell.events(status.job_id)
    again = [e for e in events if "the daemon restarted: carrying on from step 1 of 4" in e.message]
    assert len(again) == 1
    after = events[events.index(again[0]) + 1:]
    assert [(e.state.value, e.view) for e in after if e.state in (JobState.MOVING, JobState.CAPTURING)] == \
        [(s, v) for v in range(3) for s in ("moving", "capturing")]


def _cell_command(rig, config_path, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "robocell", "--config", str(config_path), "cell"],
                          capture_output=True, text=True, timeout=timeout)


def test_a_second_daemon_on_the_same_run_directory_or_cell_is_refused_and_touches_nothing(rig, tmp_path):
    cell = rig.cell
    rig.reconstructor.hold()
    try:
        status = cell.submit()
        cell.wait_state(status.job_id, {JobState.RECONSTRUCTING})
        before = cell.events(status.job_id)
        same_dir = _cell_command(rig, cell.processes.config_path)
        assert same_dir.returncode == 1
        assert f"the run directory {cell.config.run_dir} is in use by another cell daemon" in same_dir.stderr
        assert "Traceback" not in same_dir.stderr
        elsewhere = tmp_path / "other.json"
        elsewhere.write_text(cell.config.model_copy(update={"run_dir": tmp_path / "other-run"}).model_dump_json())
        same_cell = _cell_command(rig, elsewhere)
        assert same_cell.returncode == 1
        assert f"a daemon of cell {cell.config.cell_id} is already running on the router" in same_cell.stderr
        assert not (tmp_path / "other-run" / "jobs.sqlite").exists()
        assert cell.events(status.job_id) == before  # the running job was not touched
    finally:
        rig.reconstructor.release()
    assert cell.wait(status.job_id).state is JobState.SUCCEEDED


def test_a_query_through_a_wildcard_reaches_no_handler(rig):
    """One query on robocell/<cell>/** must not submit, move or capture: handlers answer only
    queries addressed to their own key."""
    cell = rig.cell
    jobs_before = len(cell.client.list(limit=1000))
    pose_before = cell.robot_state().T_base_flange
    shots_before = rig.camera.server.request_count
    body = cell.scan_request().model_dump_json()

    async def ask() -> None:
        async with await Transport.open(cell.router) as transport:
            await transport.query(f"robocell/{cell.config.cell_id}/**", body, timeout=5.0)

    with pytest.raises(NoResponder):
        cell.loop.run(ask())
    assert len(cell.client.list(limit=1000)) == jobs_before
    assert cell.robot_state().T_base_flange == pose_before
    assert rig.camera.server.request_count == shots_before


def test_a_recording_that_cannot_be_written_is_named_nowhere(rig):
    cell = rig.cell
    last = cell.client.list(limit=1)[0].job_id
    day, number = last.split("-")
    upcoming = f"{day}-{int(number) + 1:06d}"
    (cell.config.run_dir / f"{upcoming}.rrd").mkdir()  # where the next job's recording would go
    status = cell.submit()
    assert status.job_id == upcoming
    final = cell.wait(status.job_id)
    assert final.state is JobState.SUCCEEDED and final.recording is None
    result = cell.client.result(status.job_id)
    assert result.recording is None
    assert result.recording_error == (f"the recording {cell.config.run_dir / upcoming}.rrd cannot be written: "
                                      "Is a directory")


def test_a_made_up_reconstruction_is_refused(rig):
    """A worker that answers a superquadric no camera could have seen ([9.9, 9.9, 9.9] m around the
    cameras) does not make a job succeed."""
    cell = rig.cell

    async def liar(request_json: str, payload: bytes) -> tuple[str, bytes]:
        request = ReconstructRequest.model_validate_json(request_json)
        made_up = Reconstruction(
            superquadric=Superquadric(size=[9.9, 9.9, 9.9], shape=[1.0, 1.0],
                                      T_world_object=[[1, 0, 0, 0.6], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
            silhouette_iou=[1.0, 1.0, 1.0], residual=0.0, timings_ms={"total": 1.0}, centre=[0.6, 0, 0], radius=1.0)
        return ReconstructReply(job_id=request.job_id, result=made_up, worker="liar", ticket=request.ticket,
                                points=Blob(encoding=POINTS_ENCODING, length=0)).model_dump_json(), b""

    rig.reconstructor.withdraw()
    fake = InProcessWorker(cell.loop, cell.router, "liar", liar)
    try:
        wait_until(lambda: [r.worker for r in cell.status().reconstructors] == ["liar"], timeout=10,
                   what="only the liar in the pool")
        job_id, error = rig.failed_job()
    finally:
        fake.close()
        rig.reconstructor.announce()
    # Checked against the daemon's own pictures, refused, and sent again (to the liar: it is alone).
    assert error.startswith("reconstructing: gave up after 3 attempts: attempt 1 on liar: refused: "
                            "the model does not match the pictures: view 0 overlaps its silhouette by"), error
    assert error.count("refused: the model does not match the pictures") == 3, error
    # Drawn in the recording as it came, and taken out again when it was refused.
    recording = cell.config.run_dir / f"{job_id}.rrd"
    wait_until(lambda: recording_problem(recording) is None, timeout=20, what="the failed job's recording closed")
    rows = sorted((at, "Clear:is_recursive" in batch.schema.names)
                  for chunk in RrdReader(str(recording)).stream() if chunk.entity_path == "/world/fit"
                  for batch in [chunk.to_record_batch()] for at in batch.column("job").cast("int64").to_pylist())
    assert [cleared for _, cleared in rows] == [False, True] * 3, rows


def test_a_job_the_store_cannot_take_is_refused_and_the_cell_goes_on(rig):
    """While another writer holds the store (longer than the store waits for it), a submit gets
    the store's error, no job of it is left anywhere, and once the store is free the next job runs."""
    cell = rig.cell
    before = len(cell.client.list(limit=1000))
    with JobStore(cell.config.run_dir / "jobs.sqlite") as store, store._write():  # the write lock, held
        with pytest.raises(StoreError, match="the job store could not take the job: .*database is locked"):
            cell.submit()
    assert len(cell.client.list(limit=1000)) == before
    status = cell.submit()
    assert cell.wait(status.job_id).state is JobState.SUCCEEDED
    assert cell.status().queued == 0
    assert not cell.client.list({JobState.QUEUED, *ACTIVITIES, JobState.CANCELLING})
