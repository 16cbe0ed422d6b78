"""Volume overlap and centre distance between superquadrics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robocell.core_cy.errors import CoreError
from robocell.core_cy.scoring import centre_error, volumetric_iou
from robocell.core_cy.superquadric import Superquadric, inside_outside


def pose(rotation=np.eye(3), translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rotation, translation
    return T


def rotation(axis: str, degrees: float) -> np.ndarray:
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


BASE = rotation("z", 30) @ rotation("y", -40) @ rotation("x", 75)


@pytest.mark.parametrize("shape", [(0.1, 0.1), (0.1, 1.0), (1.0, 1.0), (0.4, 1.6)], ids=str)
def test_identical_superquadrics_overlap_exactly(shape):
    sq = Superquadric([0.3, 0.2, 0.1], shape, pose(BASE, [1, 2, 3]))
    assert volumetric_iou(sq, sq) == 1.0


@pytest.mark.parametrize("e2", [0.1, 0.6, 1.0, 1.7])
def test_swapping_x_and_y_with_a_quarter_turn_is_the_same_solid(e2):
    # Object frame of b = frame of a turned +90 degrees about z: x_b = y_a, y_b = -x_a.
    a = Superquadric([0.3, 0.2, 0.1], [0.4, e2], pose(BASE, [1, 2, 3]))
    b = Superquadric([0.2, 0.3, 0.1], [0.4, e2], pose(BASE @ rotation("z", 90), [1, 2, 3]))
    assert volumetric_iou(a, b) > 0.999


def test_swapping_x_and_z_is_the_same_solid_when_the_exponents_agree():
    a = Superquadric([0.3, 0.2, 0.1], [0.3, 0.3], pose(BASE))
    b = Superquadric([0.1, 0.2, 0.3], [0.3, 0.3], pose(BASE @ rotation("y", 90)))
    assert volumetric_iou(a, b) > 0.999


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_half_turns_and_angle_wraps_are_the_same_solid(axis):
    a = Superquadric([0.3, 0.2, 0.1], [0.2, 1.0], pose(BASE, [0.5, 0, 0]))
    for degrees in (180, 360, -180):
        b = Superquadric([0.3, 0.2, 0.1], [0.2, 1.0],
                         pose(BASE @ rotation(axis, degrees), [0.5, 0, 0]))
        assert volumetric_iou(a, b) > 0.999


def test_disjoint_superquadrics_do_not_overlap():
    a = Superquadric([1.0, 1.0, 1.0], [0.1, 0.1], pose())
    b = Superquadric([1.0, 1.0, 1.0], [1.0, 1.0], pose(BASE, [2.5, 0.0, 0.0]))
    assert volumetric_iou(a, b) == 0.0


def test_nested_cubes_overlap_by_their_volume_ratio():
    big = Superquadric([2.0, 2.0, 2.0], [0.1, 0.1], pose(BASE, [1, 1, 1]))
    small = Superquadric([1.0, 1.0, 1.0], [0.1, 0.1], pose(BASE, [1, 1, 1]))
    # About 74,000 of the samples fall in the big cube: standard error about 0.0012.
    assert volumetric_iou(big, small) == pytest.approx(1 / 8, abs=0.005)
    assert volumetric_iou(small, big) == pytest.approx(1 / 8, abs=0.005)


def test_iou_is_deterministic_for_a_seed_and_validates_n():
    a = Superquadric([0.3, 0.2, 0.1], [0.5, 0.5], pose())
    b = Superquadric([0.3, 0.2, 0.1], [0.5, 0.5], pose(translation=[0.1, 0, 0]))
    assert volumetric_iou(a, b, seed=3) == volumetric_iou(a, b, seed=3)
    assert volumetric_iou(a, b, n=50_000, seed=1) == pytest.approx(
        volumetric_iou(a, b, n=50_000, seed=2), abs=0.01)
    with pytest.raises(CoreError, match="n must be a positive integer, got 0"):
        volumetric_iou(a, b, n=0)


@pytest.mark.parametrize("shape", [(0.1, 0.1), (0.1, 1.0), (1.0, 1.0), (0.4, 0.4), (1.8, 0.3)],
                         ids=str)
def test_volume_matches_a_monte_carlo_estimate(shape):
    rng = np.random.default_rng(0)
    size = np.array([0.3, 0.2, 0.1])
    sq = Superquadric(size, shape, pose())
    samples = rng.uniform(-1, 1, size=(400_000, 3)) * size  # the bounding box
    fraction = np.mean(inside_outside(samples, sq) <= 1)
    estimate = fraction * 8 * np.prod(size)
    # Standard error below 0.1 % of the estimate for fractions above 0.3.
    assert sq.volume == pytest.approx(estimate, rel=0.006)


def test_centre_error_is_the_distance_between_centres():
    a = Superquadric([1, 1, 1], [1, 1], pose(BASE, [1.0, 2.0, 3.0]))
    b = Superquadric([5, 1, 1], [0.1, 1], pose(np.eye(3), [4.0, 6.0, 3.0]))
    assert centre_error(a, b) == 5.0
    assert centre_error(b, a) == 5.0
