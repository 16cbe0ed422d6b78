"""The simulated robot's gripper (``workers.sim.robot.SceneGripper``) judges a pick of every shape the
simulator draws (``robocell sim scans --shape``), cup stacks and lumpy figures included.

The cup stack's width between the closed pads is scored against the stack's own dimensions (two
truncated cones); every other shape only has to be judged without an error, and a gripper closed far
from the object holds nothing.
"""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from robocell.cli.sim import SHAPES, _make_object, add_arguments
from robocell.wire.config import GripperConfig
from robocell.workers.sim.objects import CupStack
from robocell.workers.sim.robot import SceneGripper

GRIPPER = GripperConfig().dimensions()
PLANE = [0.0, 0.0, 1.0, 0.0]


def _object(shape: str):
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return _make_object(parser.parse_args(["--shape", shape]))


def _from_above(x: float, y: float, z: float) -> np.ndarray:
    """A grasp pose (grasp-to-world) approaching straight down (its z), closing along the world's y."""
    T = np.eye(4)
    T[:3, :3] = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]).T
    T[:3, 3] = [x, y, z]
    return T


def _over_the_top(truth: dict) -> np.ndarray:
    """Over the middle of the object's box: the fingertips 4 cm below its top, the palm 5 mm above it."""
    low, high = np.array(truth["bbox_min"]), np.array(truth["bbox_max"])
    middle = (low + high) / 2
    # The palm is finger_length - pad_length / 2 behind the pads' centre, the tips pad_length / 2 ahead.
    return _from_above(middle[0], middle[1], high[2] - 0.04 + GRIPPER["pad_length"] / 2)


@pytest.mark.parametrize("shape", SHAPES)
def test_a_pick_of_every_simulated_shape_is_judged(shape):
    obj = _object(shape)
    truth = obj.truth()
    if "bbox_min" not in truth:  # a superquadric or a union of them: its box from its mesh
        vertices = obj.mesh()[0]
        truth = {**truth, "bbox_min": vertices.min(axis=0).tolist(), "bbox_max": vertices.max(axis=0).tolist()}
    gripper = SceneGripper([obj.truth()], GRIPPER, support_plane=PLANE)
    grip = gripper.close_at(_over_the_top(truth))
    assert grip.closed and isinstance(grip.holding, bool) and grip.reason
    far = np.array(truth["bbox_max"]) + [0.3, 0.3, 0.0]
    missed = gripper.close_at(_from_above(far[0], far[1], 0.03))
    assert missed.holding is False and missed.reason == "the fingers close on nothing"


@pytest.mark.parametrize("inverted", [True, False])
def test_a_cup_stack_is_held_with_the_width_of_its_cups(inverted):
    rb, rt, h = 0.025, 0.038, 0.06
    cups = CupStack((0.6, 0.0), rb, rt, h, top_inverted=inverted, nest_offset=0.02)
    gripper = SceneGripper([cups.truth()], GRIPPER, support_plane=PLANE)
    grip = gripper.close_at(_over_the_top(cups.truth()))
    # The fingers reach from 4 cm below the top to the palm above it, across the cups' axis.
    if inverted:  # the upper cup upside down, its narrow end the top (2 h): widest 4 cm down
        expected = 2 * (rb + (rt - rb) * 0.04 / h)
    else:  # the upper cup nested upright, its rim the top: the rim's width
        expected = 2 * rt
    assert grip.holding is True, grip.reason
    assert grip.width == pytest.approx(expected, abs=5e-4)
