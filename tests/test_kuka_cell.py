"""A whole scan on the simulated KUKA controller, through each of its real protocols."""

import subprocess
import sys
import time

import numpy as np
import pytest

from wire.messages import JobState
from workers.sim.scene import target_from_config, truth_from_config
from core_cy.scoring import volumetric_iou
from core_cy.superquadric import Superquadric

from tests.cell_fixtures import cell_config, free_port, running_cell


@pytest.fixture(params=["kvp", "opc"])
def simulated_kuka(request, tmp_path):
    """`robocell sim kuka` as a child process, on a free port."""
    port = free_port()
    log = open(tmp_path / "sim-kuka.log", "wb")
    process = subprocess.Popen([sys.executable, "-m", "robocell", "sim", "kuka", "--protocol", request.param,
                                "--port", str(port), "--speed", "10000", "--rotation-speed", "3000"], stdout=log, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 30
        while b"simulated KUKA controller" not in (tmp_path / "sim-kuka.log").read_bytes():
            assert process.poll() is None, (tmp_path / "sim-kuka.log").read_text()
            assert time.monotonic() < deadline, "the simulated controller did not start"
            time.sleep(0.05)
        yield request.param, port
    finally:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        log.close()


def test_scan_on_the_simulated_kuka(simulated_kuka, tmp_path):
    protocol, port = simulated_kuka
    config = cell_config(tmp_path / "run", robot={"backend": "kuka",
                                                  "kuka": {"protocol": protocol, "port": port,
                                                           "override": 30, "max_override": 30}},
                         timeouts={"move_s": 30.0})
    with running_cell(config, sim_camera=True) as cell:
        job = cell.submit(target=target_from_config(config.sim))
        final = cell.wait(job.job_id)
        assert final.state is JobState.SUCCEEDED, final.error
        result = cell.client.result(job.job_id)
        truth = Superquadric.from_dict(truth_from_config(config.sim))
        assert volumetric_iou(Superquadric.from_dict(result.superquadric.model_dump()), truth) > 0.7
        # The last picture was taken from where the controller says the flange is (to 1 mm).
        flange = np.asarray(cell.robot_state().T_base_flange)
        np.testing.assert_allclose(flange @ config.hand_eye, result.T_base_cam[-1], atol=1e-3)
