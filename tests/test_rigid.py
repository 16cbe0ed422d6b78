"""One rigid-pose check with one tolerance: a pose the daemon accepts at submit, every other part
accepts too, and one it refuses, every part refuses."""

import numpy as np
import pytest

from robocell.core_cy.calibrate import _check_poses
from robocell.core_cy.camera import Camera
from robocell.core_cy.errors import CalibrationError, CoreError
from robocell.core_cy.rigid import RIGID_TOLERANCE, rigid_error
from robocell.core_cy.superquadric import Superquadric
from robocell.wire.messages import MoveRequest
from robocell.workers.robot.kuka.e6pos import e6pos_from_pose

K = [[600.0, 0.0, 319.5], [0.0, 600.0, 239.5], [0.0, 0.0, 1.0]]


def flange(skew: float) -> np.ndarray:
    """A flange pose looking down, its rotation's first column stretched by ``skew``."""
    pose = np.eye(4)
    pose[:3, :3] = np.diag([1.0, -1.0, -1.0])
    pose[:3, 3] = [0.6, 0.1, 0.3]
    pose[0, 0] += skew
    return pose


def accepted_by_each(pose: np.ndarray) -> dict[str, bool]:
    def accepts(check) -> bool:
        try:
            check()
        except (ValueError, CoreError, CalibrationError):
            return False
        return True

    return {
        "message": accepts(lambda: MoveRequest(T_base_flange=pose.tolist())),
        "kuka bridge": accepts(lambda: e6pos_from_pose(pose)),
        "camera": accepts(lambda: Camera(K=K, T_world_cam=pose)),
        "superquadric": accepts(lambda: Superquadric(size=[0.1] * 3, shape=[1.0, 1.0], T_world_object=pose)),
        "calibration": accepts(lambda: _check_poses([pose], 1)),
    }


@pytest.mark.parametrize("skew, verdict", [(0.0, True), (0.2 * RIGID_TOLERANCE, True), (5 * RIGID_TOLERANCE, False),
                                           (1e-3, False)])
def test_every_part_gives_the_same_verdict(skew, verdict):
    verdicts = accepted_by_each(flange(skew))
    assert verdicts == dict.fromkeys(verdicts, verdict)
    assert (rigid_error(flange(skew)) is None) == verdict


def test_the_reasons():
    mirrored = flange(0.0)
    mirrored[:3, 0] *= -1
    assert "reflection" in rigid_error(mirrored)
    bad_row = flange(0.0)
    bad_row[3, 0] = 0.1
    assert "last row" in rigid_error(bad_row)
    assert rigid_error(np.eye(3)) == "must be a 4x4 matrix"
    assert rigid_error([[float("nan")] * 4] * 4) == "contains NaN or infinity"
