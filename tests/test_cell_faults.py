"""Faults and cancels, end to end: the daemon fails (or cancels) the job with a clear reason and stays up.

Router, robot worker, camera worker and daemon are child processes. The
simulated Axis camera (behind digest authentication) runs in the test
process, so that it can be told to fail; so does the only reconstruction
worker, which can be held at a gate to keep a job reconstructing.
"""

from __future__ import annotations

import dataclasses

import pytest

from wire.errors import RemoteError
from wire.messages import JobState

from tests.cell_fixtures import GatedReconstructor, InProcessSimCamera, RunningCell, cell_config, running_cell, wait_until

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
                         camera={"username": "root", "password": PASSWORD})
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
    ({"status": 500}, "answered HTTP 500 Internal Server Error: Simulated fault: HTTP 500; gave up after 2 attempts",
     "CameraResponseError"),
    ({"garbage": True}, "answered, but not a JPEG: the body does not start with the JPEG marker FF D8; "
                        "gave up after 2 attempts", "CameraResponseError"),
    ({"hang_s": 4.0}, "did not answer within 1 s; gave up after 2 attempts", "CameraTimeout"),
], ids=["500", "garbage", "nothing"])
def test_camera_fault_fails_the_job_after_bounded_retries(rig, fault, reason, kind):
    server = rig.camera.server
    attempts = rig.cell.config.camera.retries + 1
    server.fail_next(**fault, count=attempts)
    before = server.request_count
    job_id, error = rig.failed_job()
    assert error == f"capturing view 0: camera at {rig.camera.config.camera.url} {reason}"
    assert rig.cell.client.status(job_id).error_kind == kind  # the camera's error keeps its class
    assert server.request_count - before == attempts  # retried, and only so often
    assert rig.events(job_id)[-1] == ("failed", None)


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
        assert events[-1].time - events[-2].time >= cell.config.timeouts.worker_wait_s * 0.9
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
    rig.camera.server.fail_next(hang_s=3.0)  # the first attempt hangs (the camera worker gives up after 1 s)
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
