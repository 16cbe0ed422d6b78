"""A pick in the simulated cell, end to end: scan, plan grasps, approach, close, lift, place.

The simulated robot's gripper judges each grasp against the scene's true object
(``workers.sim.judge``, written apart from the planner), so "held" is the truth's verdict. The cell
is the one of tests/test_cell_backgrounds.py (tests/conftest.py). A pick
that finds no grasp is tested on the daemon in the test's process (tests/test_cell_inprocess.py).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocell.wire.errors import RemoteError
from robocell.wire.messages import PickRequest, ScanRequest
from robocell.workers.sim.scene import target_from_config

from robocell.cell.recording_files import recording_summary

from tests.cell_fixtures import wait_for_footer

PLACE = [0.55, 0.25]


@pytest.fixture(scope="module")
def cell(printed_box_cell):
    """The printed box's cell (tests/conftest.py)."""
    return printed_box_cell


def moves_of(cell, job_id: str) -> int:
    return sum("moved in" in line and f"for job {job_id}" in line for line in cell.log("robot").splitlines())


def test_a_box_is_picked_held_and_placed(cell):
    request = ScanRequest(target=target_from_config(cell.config.sim), pick=PickRequest(place=PLACE))
    result = cell.client.scan(request, timeout=120)
    assert result.grasps, "a box 5 cm across has grasps"
    pick = result.pick
    assert pick is not None and pick.held is True and pick.reason == "held" and pick.placed
    chosen = np.asarray(result.grasps[pick.grasp].T_world_grasp)
    flange = np.asarray(pick.T_base_flange)
    expected = chosen @ np.linalg.inv(np.asarray(cell.config.gripper.T_flange_grasp))
    assert np.allclose(flange[:3, 3], expected[:3, 3], atol=1e-6)   # the grasp frame where the plan put it
    events = [(e.state.value, e.message) for e in cell.events(result.job_id)]
    picking = [message for state, message in events if state == "picking" and not message.startswith("the gripper")]
    assert picking == ["choosing a grasp", "opening the gripper", "moving above the grasp", "approaching",
                       "closing the gripper", "lifting", "carrying it over", "putting it down", "letting go",
                       "backing away"]
    assert any("the gripper holds it" in message for _, message in events)
    assert moves_of(cell, result.job_id) == 3 + 6  # the views, and the pick's six moves
    grips = [line for line in cell.log("robot").splitlines() if f"for job {result.job_id}" in line and "gripper" in line]
    assert [line.split("gripper ")[1].split()[0] for line in grips] == ["open", "closed", "open"]
    assert "held" in events[-1][1] and events[-1][0] == "succeeded"
    # The recording shows the grippers of the grasps, the chosen one apart, and the pick's motion.
    wait_for_footer(Path(result.recording), timeout=20)
    entities = recording_summary(result.recording)
    grippers = [entity for entity in entities if entity.startswith("/world/grasps/")]
    assert "/world/grasps/chosen" in grippers and len(grippers) == len(result.grasps)
    assert "Boxes3D" in entities["/world/grasps/chosen"]


def test_a_scan_without_a_pick_still_carries_its_grasps_and_moves_only_for_its_views(cell):
    result = cell.client.scan(cell.scan_request(label="scan only"), timeout=120)
    assert result.grasps and result.pick is None
    assert moves_of(cell, result.job_id) == 3
    assert result.timings_ms["grasp"] > 0


def test_a_place_outside_the_workspace_is_refused_at_submit(cell):
    far = [2.0, 0.0]
    with pytest.raises(RemoteError, match=r"pick.place: x = 2 m is outside the workspace's 0.1 to 1 m"):
        cell.client.submit(ScanRequest(target=target_from_config(cell.config.sim), pick=PickRequest(place=far)))
