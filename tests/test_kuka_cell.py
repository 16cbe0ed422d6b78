"""A whole scan and pick on the simulated KUKA controller, through each of its real protocols.

The controller is ``robocell sim kuka`` with the cell's configuration: its gripper's
input confirms a hold when the configuration's gripper, closed where the flange
stands, holds the scene's true object (``workers.sim.judge``). The KUKA bridge
only sees that input, so "held" here is what a real cell's bridge could tell.
"""

import subprocess
import sys
import time

import numpy as np
import pytest

from robocell.wire.messages import JobState, PickRequest, ScanRequest
from robocell.workers.sim.scene import target_from_config, truth_from_config
from robocell.core_cy.scoring import volumetric_iou
from robocell.core_cy.superquadric import Superquadric

from robocell.cell.pick import pick_poses

from tests.cell_fixtures import cell_config, free_port, running_cell

PLACE = [0.55, 0.25]


@pytest.fixture(params=["kvp", "opc"])
def kuka_config(request, tmp_path):
    """A cell configuration with a KUKA robot, and `robocell sim kuka` serving it as a child process."""
    protocol, port = request.param, free_port()
    config = cell_config(tmp_path / "run", robot={"backend": "kuka",
                                                  "kuka": {"protocol": protocol, "port": port,
                                                           "override": 30, "max_override": 30}},
                         sim={"shape": "box", "size": [0.04, 0.025, 0.05], "position": [0.6, 0.0], "yaw_deg": 20},
                         timeouts={"move_s": 30.0})
    config_path = tmp_path / "cell.json"
    config_path.write_text(config.model_dump_json())
    log = open(tmp_path / "sim-kuka.log", "wb")
    process = subprocess.Popen([sys.executable, "-m", "robocell", "--config", str(config_path), "sim", "kuka",
                                "--protocol", protocol, "--port", str(port), "--speed", "10000",
                                "--rotation-speed", "3000"], stdout=log, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 30
        while b"simulated KUKA controller" not in (tmp_path / "sim-kuka.log").read_bytes():
            assert process.poll() is None, (tmp_path / "sim-kuka.log").read_text()
            assert time.monotonic() < deadline, "the simulated controller did not start"
            time.sleep(0.05)
        yield config
    finally:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        log.close()


def test_scan_and_pick_on_the_simulated_kuka(kuka_config):
    config = kuka_config
    with running_cell(config, sim_camera=True) as cell:
        request = ScanRequest(target=target_from_config(config.sim), pick=PickRequest(place=PLACE))
        job = cell.client.submit(request)
        final = cell.wait(job.job_id)
        assert final.state is JobState.SUCCEEDED, final.error
        result = cell.client.result(job.job_id)
        truth = Superquadric.from_dict(truth_from_config(config.sim))
        assert volumetric_iou(Superquadric.from_dict(result.superquadric.model_dump()), truth) > 0.7
        # The gripper's input confirmed the hold; the arm carried the object over and let go.
        pick = result.pick
        assert pick is not None and pick.held is True and pick.placed, pick
        assert pick.reason.startswith("held: $IN[1] confirmed it in") and pick.width is None
        grips = [line for line in cell.log("robot").splitlines()
                 if f"for job {job.job_id}" in line and "gripper" in line]
        assert [line.split("gripper ")[1].split()[0] for line in grips] == ["open", "closed", "open"]
        # The controller says the flange ended where the pick backs away from the place (to 1 mm).
        poses = pick_poses(np.asarray(result.grasps[pick.grasp].T_world_grasp), request.pick, config)
        flange = np.asarray(cell.robot_state().T_base_flange)
        np.testing.assert_allclose(flange[:3, 3], poses["away"][:3, 3], atol=1e-3)
