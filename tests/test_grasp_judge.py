"""The benchmark's grasp judge (workers/sim/judge.py) on cases worked out by hand.

The default gripper: 8.5 cm opening, 4.5 cm fingers with 2 cm pads, 2 cm wide,
8 mm thick, a 6 cm palm. From above (z down), the fingertips are 1 cm below the
grasp's origin and the palm 3.5 cm above it.
"""

import math

import numpy as np
import pytest

from robocell.workers.sim.judge import JudgeGripper, Part, judge, parts_from_truth

GRIPPER = JudgeGripper()
TABLE = [0.0, 0.0, 1.0, 0.0]


def pose(R, origin):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, origin
    return T


def turn_z(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def from_above(closing=(0.0, 1.0, 0.0)):
    """Grasp axes approaching straight down, closing along ``closing`` (horizontal)."""
    y, z = np.array(closing, float), np.array([0.0, 0.0, -1.0])
    return np.column_stack([np.cross(y, z), y, z])


BOX = [Part(np.array([0.03, 0.02, 0.025]), np.array([0.1, 0.1]), pose(np.eye(3), [0, 0, 0.025]))]  # 6x4x5 cm


def test_a_box_taken_across_its_narrow_side_holds_with_its_width():
    verdict = judge(pose(from_above(), [0, 0, 0.03]), BOX, GRIPPER, TABLE)
    assert verdict.holds and verdict.width == pytest.approx(0.04, abs=1e-6)
    across_the_wide_side = judge(pose(from_above((1, 0, 0)), [0, 0, 0.03]), BOX, GRIPPER, TABLE)
    assert across_the_wide_side.holds and across_the_wide_side.width == pytest.approx(0.06, abs=1e-6)


@pytest.mark.parametrize("origin_z, reason", [
    (0.013, "the palm cuts the object"),  # palm at 4.8 cm, the box's top at 5 cm
    (0.009, "a finger or palm corner is below the support plane"),  # fingertips at -1 mm
    (0.061, "the fingers close on nothing"),  # fingertips 1 mm above the box
])
def test_a_grasp_too_deep_or_too_high_fails_for_the_right_reason(origin_z, reason):
    verdict = judge(pose(from_above(), [0, 0, origin_z]), BOX, GRIPPER, TABLE)
    assert not verdict.holds and verdict.reason == reason


def test_a_ball_wider_than_the_opening_is_cut_by_the_open_fingers():
    ball = [Part(np.array([0.05] * 3), np.array([1.0, 1.0]), pose(np.eye(3), [0, 0, 0.05]))]  # 10 cm
    for origin_z in (0.05, 0.07):
        assert judge(pose(from_above(), [0, 0, origin_z]), ball, GRIPPER, TABLE).reason == "an open finger cuts the object"
    # With the fingertips 3 cm above the centre the chord (8 cm) fits, but the normal there
    # is asin(3/5) = 37 degrees off the closing line.
    high = judge(pose(from_above(), [0, 0, 0.09]), ball, GRIPPER, TABLE)
    assert high.reason.startswith("contacts not antipodal (37 degrees")


def test_a_ball_is_held_at_its_equator_but_not_far_above_it():
    # A 6 cm ball centred 3 cm up. With the fingertips 1 cm above the equator the contact
    # normal is asin(1/3) = 19.5 degrees off the closing line (inside the 26.6 degree cone);
    # 1.5 cm above, asin(1/2) = 30 degrees: outside.
    ball = [Part(np.array([0.03] * 3), np.array([1.0, 1.0]), pose(np.eye(3), [0, 0, 0.03]))]
    assert judge(pose(from_above(), [0, 0, 0.03]), ball, GRIPPER, TABLE).holds
    assert judge(pose(from_above(), [0, 0, 0.05]), ball, GRIPPER, TABLE).holds
    above = judge(pose(from_above(), [0, 0, 0.055]), ball, GRIPPER, TABLE)
    assert not above.holds and above.reason.startswith("contacts not antipodal (30 degrees")
    # The width at the fingertips' height: 2 sqrt(3^2 - 1.5^2) cm.
    assert above.width == pytest.approx(2 * math.sqrt(0.03 ** 2 - 0.015 ** 2), abs=1e-5)


def test_a_turned_thin_plate_fails_at_first_touch_but_holds_on_the_centre_line():
    # An 8 mm plate turned 10 degrees in the jaws: the pads first touch it at opposite ends
    # of the finger's 2 cm width, a line 68 degrees off the faces' normals.
    plate = [Part(np.array([0.03, 0.004, 0.025]), np.array([0.1, 0.1]), pose(turn_z(10), [0, 0, 0.025]))]
    grasp = pose(from_above(), [0, 0, 0.04])
    first_touch = judge(grasp, plate, GRIPPER, TABLE)
    assert not first_touch.holds and first_touch.reason.startswith("contacts not antipodal")
    assert judge(grasp, plate, GRIPPER, TABLE, contacts="centre-line").holds  # normals 10 degrees off
    straight = [Part(plate[0].size, plate[0].shape, pose(turn_z(1), [0, 0, 0.025]))]
    assert judge(grasp, straight, GRIPPER, TABLE).holds  # the soft pads take a 1 degree turn


def test_a_union_of_parts_the_palm_meets_the_ball_on_the_box():
    truth = {"parts": [
        {"size": [0.03, 0.02, 0.015], "shape": [0.1, 0.1], "T_world_object": pose(np.eye(3), [0, 0, 0.015]).tolist()},
        {"size": [0.015] * 3, "shape": [1.0, 1.0], "T_world_object": pose(np.eye(3), [0, 0, 0.044]).tolist()},
    ]}
    parts = parts_from_truth(truth)
    # Pads on the box (3 cm tall) from above: the palm at 4.5 cm cuts the ball (top at 5.9 cm).
    assert judge(pose(from_above((1, 0, 0)), [0, 0, 0.01]), parts, GRIPPER, TABLE).reason == "the palm cuts the object"
    # Across the ball itself (3 cm) at its equator: the fingertips stay above the box.
    on_the_ball = judge(pose(from_above(), [0, 0, 0.054]), parts, GRIPPER, TABLE)
    assert on_the_ball.holds and on_the_ball.width == pytest.approx(0.03, abs=1e-4)


def test_a_side_grasp_whose_palm_corner_goes_below_the_table_fails():
    # From the side (approach along +x, closing along y): the palm reaches 3 cm up and down.
    R = np.column_stack([[0, 0, 1.0], [0, 1.0, 0], [1.0, 0, 0]])  # x up = y cross z
    tall = [Part(np.array([0.02, 0.02, 0.05]), np.array([0.1, 0.1]), pose(np.eye(3), [0, 0, 0.05]))]
    assert judge(pose(R, [0, 0, 0.05]), tall, GRIPPER, TABLE).holds
    low = judge(pose(R, [0, 0, 0.025]), tall, GRIPPER, TABLE)
    assert low.reason == "a finger or palm corner is below the support plane"
