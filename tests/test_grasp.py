"""The grasp planner on cases worked out by hand: exact models on a table at z = 0 (metres)."""

import json
import math

import numpy as np
import pytest

from robocell.core_cy.errors import CoreError, GripperError
from robocell.core_cy.grasp import plan_grasps
from robocell.core_cy.gripper import DEFAULT_GRIPPER, Gripper, grasps_to_json
from robocell.core_cy.superquadric import Superquadric, inside_outside

TABLE = [0.0, 0.0, 1.0, 0.0]
DOWN = np.array([0.0, 0.0, -1.0])


def standing(size, shape, yaw_deg=0.0, lying=False):
    """A superquadric resting on the table at (0.5, 0.1), turned yaw_deg about the vertical."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    if lying:  # the object's z axis along the world's x (before the yaw), its y axis up
        R = R @ np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0]])
    T = np.eye(4)
    T[:3, :3] = R
    up = R.T @ [0, 0, 1.0]
    T[:3, 3] = [0.5, 0.1, float(np.abs(up) @ size)]  # axis-aligned: the vertical semi-axis
    return Superquadric(size, shape, T)


def corners_world(grasp, gripper=DEFAULT_GRIPPER):
    T = grasp.T_world_grasp
    return gripper.corners() @ T[:3, :3].T + T[:3, 3]


def test_a_box_is_taken_across_its_narrow_side_from_above():
    box = standing([0.03, 0.02, 0.025], [0.1, 0.1], yaw_deg=30)  # 6 x 4 x 5 cm
    best = plan_grasps(box, TABLE)[0]
    R = best.T_world_grasp[:3, :3]
    narrow = box.T_world_object[:3, 1]
    assert best.approach == "top" and np.allclose(R[:, 2], DOWN)
    assert abs(R[:, 1] @ narrow) == pytest.approx(1.0)  # closing along the 4 cm side
    assert best.width == pytest.approx(0.04, abs=1e-3)
    # The pads' centre inside the box, below its top (5 cm), the fingertips above the table.
    origin = best.T_world_grasp[:3, 3]
    assert np.allclose(origin[:2], [0.5, 0.1]) and 0.0 < origin[2] < 0.05
    assert origin[2] - DEFAULT_GRIPPER.pad_length / 2 > 0


def test_a_standing_cylinder_is_taken_across_its_diameter():
    cylinder = standing([0.025, 0.025, 0.05], [0.1, 1.0])  # 5 cm across, 10 cm tall
    grasps = plan_grasps(cylinder, TABLE)
    assert grasps and all(g.width == pytest.approx(0.05, abs=1e-3) for g in grasps[:3])
    best = grasps[0]
    assert best.approach == "top"
    assert abs(best.T_world_grasp[:3, 1] @ [0, 0, 1.0]) < 1e-9  # closing horizontally
    # Several directions around the round axis are offered, not one.
    closings = {tuple(np.round(np.abs(g.T_world_grasp[:3, 1]), 3)) for g in grasps if g.approach == "top"}
    assert len(closings) >= 3


def test_a_lying_cylinder_is_taken_across_its_diameter_from_above():
    cylinder = standing([0.02, 0.02, 0.06], [0.1, 1.0], yaw_deg=20, lying=True)  # 4 cm across, 12 long
    best = plan_grasps(cylinder, TABLE)[0]
    axis = cylinder.T_world_object[:3, 2]
    assert best.approach == "top" and np.allclose(best.T_world_grasp[:3, 2], DOWN, atol=1e-9)
    assert abs(best.T_world_grasp[:3, 1] @ axis) < 1e-9  # closing across the axis, horizontally
    assert best.width == pytest.approx(0.04, abs=1e-3)


def test_a_standing_plate_is_taken_from_its_edge():
    plate = standing([0.05, 0.004, 0.03], [0.1, 0.1], yaw_deg=-40)  # 10 cm long, 8 mm thick, 6 cm tall
    best = plan_grasps(plate, TABLE)[0]
    assert best.approach == "top"
    assert abs(best.T_world_grasp[:3, 1] @ plate.T_world_object[:3, 1]) == pytest.approx(1.0)
    assert best.width == pytest.approx(0.008, abs=5e-4)
    # From the top edge down: the pads' centre in the plate's upper part, the palm above it.
    origin = best.T_world_grasp[:3, 3]
    assert 0.03 < origin[2] < 0.06
    assert origin[2] - DEFAULT_GRIPPER.palm > 0.06


def test_a_ball_too_big_for_the_opening_gives_an_empty_list():
    assert plan_grasps(standing([0.06, 0.06, 0.06], [1.0, 1.0]), TABLE) == []
    # The same ball fits a gripper that opens wider.
    wide = Gripper(max_opening=0.16, finger_length=0.09, pad_length=0.04)
    assert plan_grasps(standing([0.06, 0.06, 0.06], [1.0, 1.0]), TABLE, wide)


def test_no_finger_or_palm_corner_cuts_the_table():
    # A 2 cm thick lying cylinder: pads centred on its axis (1 cm up) would put the
    # fingertips into the table, so the grasps sit higher.
    low = standing([0.01, 0.01, 0.05], [0.1, 1.0], lying=True)
    grasps = plan_grasps(low, TABLE)
    assert grasps
    for grasp in grasps:
        assert corners_world(grasp)[:, 2].min() >= 0.0
    # Without the table, the best grasp goes lower than that.
    free = plan_grasps(low, None)
    assert min(corners_world(g)[:, 2].min() for g in free) < 0.0


def test_a_candidate_whose_finger_would_cut_the_table_is_refused():
    # A 3 cm cube: from the side, the palm reaches 3 cm either way of the pads' centre
    # (palm_width / 2) and would go below the table; only grasps from above remain.
    cube = standing([0.015, 0.015, 0.015], [0.1, 0.1])
    grasps = plan_grasps(cube, TABLE, max_grasps=50)
    assert grasps and {g.approach for g in grasps} == {"top"}
    # On a stand 10 cm tall, the side grasps come back.
    T = cube.T_world_object.copy()
    T[2, 3] += 0.1
    raised = Superquadric(cube.size, cube.shape, T)
    assert "side" in {g.approach for g in plan_grasps(raised, TABLE, max_grasps=50)}


def test_the_grasp_frame_convention_on_a_known_pose():
    box = standing([0.03, 0.02, 0.025], [0.1, 0.1])
    best = plan_grasps(box, TABLE)[0]
    T = best.T_world_grasp
    R, origin = T[:3, :3], T[:3, 3]
    assert np.allclose(R.T @ R, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
    assert np.allclose(np.cross(R[:, 1], R[:, 2]), R[:, 0])  # x = y cross z
    assert np.allclose(R[:, 2], DOWN)  # z: the approach, palm to fingertips
    # The origin is midway between the pads: +-width/2 along y lands on the box's faces.
    pads = origin + np.outer([-0.5, 0.5], best.width * R[:, 1])
    assert inside_outside(pads, box) == pytest.approx([1.0, 1.0], abs=1e-6)
    # Fingertips at z = +pad_length/2, the palm at pad_length/2 - finger_length (grasp frame).
    g = DEFAULT_GRIPPER
    corners = g.corners()
    assert set(np.round(corners[:, 2], 9)) == {round(g.pad_length / 2, 9), round(g.pad_length / 2 - g.finger_length, 9)}
    tips_world = origin + (g.pad_length / 2) * R[:, 2]
    assert tips_world[2] == pytest.approx(origin[2] - g.pad_length / 2)


def test_the_palm_keeps_clear_of_hull_points_the_model_leaves_out():
    # The model is a 4 cm cube; the hull also holds a 4 cm ball on its top, which the
    # model leaves out: from above, the palm cannot come near enough to reach the cube.
    box = standing([0.02, 0.02, 0.02], [0.1, 0.1])
    direction = np.random.default_rng(0).normal(size=(300, 3))
    ball = [0.5, 0.1, 0.06] + 0.02 * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    assert "top" in {g.approach for g in plan_grasps(box, TABLE, max_grasps=50)}
    guarded = plan_grasps(box, TABLE, points=ball, max_grasps=50)
    assert "top" not in {g.approach for g in guarded}
    g = DEFAULT_GRIPPER
    for grasp in guarded:
        T = grasp.T_world_grasp
        local = (ball - (T[:3, 3] + g.palm * T[:3, 2])) @ T[:3, :3]  # about the palm's centre
        footprint = (np.abs(local[:, 0]) <= g.palm_width / 2) & (np.abs(local[:, 1]) <= g.max_opening / 2 + g.finger_thickness)
        assert np.all(local[footprint, 2] > 0)  # in front of the palm


def test_grasps_are_repeatable_ranked_and_serialise_to_the_design_json():
    sq = standing([0.03, 0.02, 0.025], [0.3, 0.6], yaw_deg=10)
    first = plan_grasps(sq, TABLE, residual=0.003, silhouette_iou=[0.93, 0.95, 0.9])
    second = plan_grasps(sq, TABLE, residual=0.003, silhouette_iou=[0.93, 0.95, 0.9])
    assert json.dumps(grasps_to_json(first)) == json.dumps(grasps_to_json(second))
    scores = [g.score for g in first]
    assert all(0 <= s <= 1 for s in scores) and scores[0] >= max(scores) - 0.05
    assert set(grasps_to_json(first)[0]) == {"T_world_grasp", "width", "score"}
    # A larger model error lowers the scores.
    unsure = plan_grasps(sq, TABLE, residual=0.012, silhouette_iou=[0.7, 0.75, 0.72])
    assert not unsure or unsure[0].score < first[0].score


@pytest.mark.parametrize("change, field", [
    ({"max_opening": 0}, "max_opening"),
    ({"finger_length": -0.01}, "finger_length"),
    ({"pad_length": 0.05}, "pad_length"),
    ({"finger_width": 0.1}, "finger_width"),
    ({"palm_width": "wide"}, "palm_width"),
    ({"finger_thickness": True}, "finger_thickness"),
    ({"friction": 3.0}, "friction"),
    ({"fingers": 3}, "fingers"),
])
def test_a_bad_gripper_is_a_one_line_error_naming_the_field(change, field):
    with pytest.raises(GripperError, match=field) as caught:
        Gripper.from_dict({**DEFAULT_GRIPPER.to_dict(), **change})
    assert "\n" not in str(caught.value)


def test_a_gripper_file_missing_a_field_or_not_json_is_refused():
    d = DEFAULT_GRIPPER.to_dict()
    del d["pad_length"], d["friction"]
    with pytest.raises(GripperError, match="missing pad_length"):
        Gripper.from_json(json.dumps(d))
    with pytest.raises(GripperError, match="not JSON"):
        Gripper.from_json("{max_opening: 0.08")
    with pytest.raises(GripperError, match="JSON object"):
        Gripper.from_json("[0.08]")
    # friction is optional: 0.5.
    d["pad_length"] = 0.02
    assert Gripper.from_json(json.dumps(d)).friction == 0.5


def test_bad_arguments_are_refused():
    box = standing([0.03, 0.02, 0.025], [0.1, 0.1])
    with pytest.raises(CoreError, match="support_plane"):
        plan_grasps(box, [0, 0, 0, 1])
    with pytest.raises(CoreError, match="max_grasps"):
        plan_grasps(box, TABLE, max_grasps=0)
    with pytest.raises(CoreError, match="silhouette_iou"):
        plan_grasps(box, TABLE, silhouette_iou=[1.5])
    with pytest.raises(CoreError, match="points"):
        plan_grasps(box, TABLE, points=[[0, 0, np.nan]])
