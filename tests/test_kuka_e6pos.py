"""E6POS <-> 4x4 poses: round trips, cases worked out by hand, gimbal lock, and the KRL text parser."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocell.workers.robot.kuka.e6pos import (E6Pos, abc_from_rotation, e6pos_from_pose, format_e6pos, parse_e6axis,
                                parse_e6pos, parse_krl_struct, pose_from_e6pos, rotation_from_abc)


def random_poses(count: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    for rotation in Rotation.random(count, random_state=seed).as_matrix():
        pose = np.eye(4)
        pose[:3, :3] = rotation
        pose[:3, 3] = rng.uniform(-2.0, 2.0, 3)
        yield pose


def test_pose_round_trip_on_random_poses():
    for pose in random_poses(2000):
        back = pose_from_e6pos(e6pos_from_pose(pose))
        np.testing.assert_allclose(back, pose, rtol=0, atol=1e-9)


def test_angles_round_trip_away_from_gimbal_lock():
    rng = np.random.default_rng(1)
    for a, b, c in zip(rng.uniform(-179.9, 180, 500), rng.uniform(-89.9, 89.9, 500), rng.uniform(-179.9, 180, 500)):
        np.testing.assert_allclose(abc_from_rotation(rotation_from_abc(a, b, c)), (a, b, c), rtol=0, atol=1e-9)


def test_a_turns_about_z_x_axis_maps_to_y():
    rotation = rotation_from_abc(90, 0, 0)
    np.testing.assert_allclose(rotation, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)


def test_b_turns_about_y_z_axis_maps_to_x():
    rotation = rotation_from_abc(0, 90, 0)
    np.testing.assert_allclose(rotation, [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-15)


def test_c_turns_about_x_y_axis_maps_to_z():
    rotation = rotation_from_abc(0, 0, 90)
    np.testing.assert_allclose(rotation, [[1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-15)


def test_combined_case_rotates_about_z_last():
    # Rz(90) @ Ry(90): tool x -> base -z... worked out column by column:
    # Ry(90) sends x->-z, y->y, z->x; then Rz(90) sends x->y, y->-x, z->z.
    rotation = rotation_from_abc(90, 90, 0)
    np.testing.assert_allclose(rotation, [[0, -1, 0], [0, 0, 1], [-1, 0, 0]], atol=1e-15)
    assert abc_from_rotation(rotation) == pytest.approx((90, 90, 0), abs=1e-12)


def test_flange_looking_down_is_c_180_and_units_are_millimetres():
    pose = np.array([[1.0, 0, 0, 0.4], [0, -1, 0, 0.0], [0, 0, -1, 0.6], [0, 0, 0, 1]])
    position = e6pos_from_pose(pose)
    assert (position.x, position.y, position.z) == pytest.approx((400, 0, 600))
    assert (position.a, position.b, position.c) == pytest.approx((0, 0, 180))


@pytest.mark.parametrize("b", [90.0, -90.0])
def test_gimbal_lock_keeps_the_rotation_and_puts_the_turn_into_a(b):
    for a, c in [(30.0, 0.0), (10.0, 25.0), (-170.0, 100.0)]:
        rotation = rotation_from_abc(a, b, c)
        a2, b2, c2 = abc_from_rotation(rotation)
        assert b2 == pytest.approx(b, abs=1e-9) and c2 == 0.0
        np.testing.assert_allclose(rotation_from_abc(a2, b2, c2), rotation, atol=1e-12)
        # B = +90 fixes A - C, B = -90 fixes A + C.
        expected = a - c if b > 0 else a + c
        assert math.remainder(a2 - expected, 360.0) == pytest.approx(0.0, abs=1e-9)


def test_angles_are_wrapped_into_the_kuka_range():
    a, b, c = abc_from_rotation(rotation_from_abc(-180, 0, -180))
    assert a == pytest.approx(180) and c == pytest.approx(180) and b == pytest.approx(0)


@pytest.mark.parametrize("bad", [np.eye(3), np.full((4, 4), np.nan), np.diag([1, 1, -1, 1.0]),
                                 np.diag([2.0, 1, 1, 1]), np.array([[1.0, 0, 0, 0]] * 4)])
def test_non_rigid_poses_are_refused(bad):
    with pytest.raises(ValueError):
        e6pos_from_pose(bad)


def test_text_round_trip_to_a_micrometre():
    for pose in random_poses(200, seed=3):
        back = pose_from_e6pos(parse_e6pos(format_e6pos(e6pos_from_pose(pose, s=2, t=35))))
        np.testing.assert_allclose(back[:3, 3], pose[:3, 3], atol=1e-9)
        np.testing.assert_allclose(back[:3, :3], pose[:3, :3], atol=1e-7)


def test_parser_reads_what_kukavarproxy_returns():
    text = ("{E6POS: X 1.0, Y 2.0, Z 3.0, A 0.0, B 90.0, C 0.0, S 2, T 35, "
            "E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}")
    assert parse_e6pos(text) == E6Pos(1.0, 2.0, 3.0, 0.0, 90.0, 0.0, s=2, t=35, external=(0.0,) * 6)


@pytest.mark.parametrize("text", [
    "{E6POS: X 1.0,Y 2.0,Z 3.0,A 0.0,B 90.0,C 0.0}",
    "  {e6pos:x 1, y 2E0 , z 3.000, a 0, b 9.0e1, c -0.0}\r\n",
    "{X 1.0, Y 2.0, Z 3.0, A 0.0, B 90.0, C 0.0}",
    "{POS: X 1.0, Y 2.0, Z 3.0, A 0.0, B 90.0, C 0.0, S 'B010', T 'B100011'}",
    "{FRAME: X 1.0, Y 2.0, Z 3.0, A 0.0, B 90.0, C 0.0}",
])
def test_parser_is_tolerant(text):
    position = parse_e6pos(text)
    assert (position.x, position.y, position.z, position.a, position.b, position.c) == (1, 2, 3, 0, 90, 0)


def test_bit_literals_for_status_and_turn():
    position = parse_e6pos("{POS: X 0, Y 0, Z 0, A 0, B 0, C 0, S 'B010', T 'B100011'}")
    assert (position.s, position.t) == (2, 35)


@pytest.mark.parametrize("text, message", [
    ("", "not a KRL structure"),
    ("X 1.0, Y 2.0", "not a KRL structure"),
    ("{E6POS: X 1.0, Y 2.0, Z 3.0, A 0.0, B 90.0}", "C missing"),
    ("{E6POS: X 1.0, Y two, Z 3.0, A 0.0, B 90.0, C 0}", "Y is not a number"),
    ("{E6POS: X nan, Y 2, Z 3.0, A 0.0, B 90.0, C 0}", "X is not finite"),
    ("{E6POS: X 1.0 Y 2.0}", "cannot read"),
])
def test_parser_says_what_is_wrong(text, message):
    with pytest.raises(ValueError, match=message):
        parse_e6pos(text)


def test_axis_angles():
    axes = parse_e6axis("{E6AXIS: A1 10.5, A2 -90.0, A3 90.0, A4 0.0, A5 45.0, A6 -3.0, E1 0.0, E2 0.0}")
    assert axes.axes == (10.5, -90.0, 90.0, 0.0, 45.0, -3.0) and axes.external == (0.0, 0.0)
    with pytest.raises(ValueError, match="A6 missing"):
        parse_e6axis("{AXIS: A1 0, A2 0, A3 0, A4 0, A5 0}")


def test_struct_without_components():
    assert parse_krl_struct("{E6POS: }") == ("E6POS", {})
