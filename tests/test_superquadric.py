"""Superquadric model, inside-outside function, mesh, support function and fit."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from robocell.core_cy._superquadric_cy import objective
from robocell.core_cy.errors import CoreError, FitError
from robocell.core_cy.scoring import volumetric_iou
from robocell.core_cy.superquadric import (
    Superquadric,
    _Objective,
    fit_superquadric,
    inside_outside,
    mesh,
    surface_points,
)

FAMILIES = {
    "box": (0.1, 0.1),
    "cylinder": (0.1, 1.0),
    "ellipsoid": (1.0, 1.0),
    "rounded box": (0.4, 0.4),
}


def euler_zyx(z_deg: float, y_deg: float, x_deg: float) -> np.ndarray:
    z, y, x = np.radians([z_deg, y_deg, x_deg])
    Rz = np.array([[math.cos(z), -math.sin(z), 0], [math.sin(z), math.cos(z), 0], [0, 0, 1]])
    Ry = np.array([[math.cos(y), 0, math.sin(y)], [0, 1, 0], [-math.sin(y), 0, math.cos(y)]])
    Rx = np.array([[1, 0, 0], [0, math.cos(x), -math.sin(x)], [0, math.sin(x), math.cos(x)]])
    return Rz @ Ry @ Rx


def pose(rotation: np.ndarray, translation) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rotation, translation
    return T


def sample_surface(sq: Superquadric, n: int, rng: np.random.Generator,
                   noise: float = 0.005) -> np.ndarray:
    """Points on the surface along random directions from the centre, plus Gaussian
    noise of ``noise`` times the mean size; world frame."""
    directions = rng.normal(size=(n, 3))
    # F is homogeneous, F(s X) = s^(2/e1) F(X): scale each direction onto F = 1.
    F = inside_outside(directions, Superquadric(sq.size, sq.shape, np.eye(4)))
    local = directions * F[:, None] ** (-sq.shape[0] / 2)
    local += rng.normal(size=local.shape) * noise * sq.size.mean()
    T = sq.T_world_object
    return local @ T[:3, :3].T + T[:3, 3]


# --- the model -------------------------------------------------------------------------


def test_inside_outside_hand_worked_values():
    sq = Superquadric([1.0, 2.0, 3.0], [1.0, 1.0], np.eye(4))
    on_axes = [[1, 0, 0], [-1, 0, 0], [0, 2, 0], [0, -2, 0], [0, 0, 3], [0, 0, -3]]
    np.testing.assert_allclose(inside_outside(on_axes, sq), 1.0, rtol=1e-12)
    np.testing.assert_allclose(inside_outside([[2, 0, 0]], sq), [4.0], rtol=1e-12)  # (2/1)^2
    assert inside_outside([[0, 0, 0]], sq)[0] == pytest.approx(0.0, abs=1e-12)
    # e1 = 0.5, e2 = 1 at (0.5, 1, 1.5): ((0.5^2 + 0.5^2)^2) + 0.5^4 = 0.25 + 0.0625
    flat = Superquadric([1.0, 2.0, 3.0], [0.5, 1.0], np.eye(4))
    np.testing.assert_allclose(inside_outside([[0.5, 1.0, 1.5]], flat), [0.3125], rtol=1e-12)


def test_inside_outside_is_invariant_to_the_pose():
    rng = np.random.default_rng(0)
    local = rng.normal(size=(200, 3))
    T = pose(euler_zyx(30, -50, 110), [0.4, -2.0, 7.0])
    for shape in FAMILIES.values():
        at_origin = Superquadric([0.5, 1.0, 1.5], shape, np.eye(4))
        posed = Superquadric([0.5, 1.0, 1.5], shape, T)
        world = local @ T[:3, :3].T + T[:3, 3]
        np.testing.assert_allclose(inside_outside(world, posed), inside_outside(local, at_origin),
                                   rtol=1e-9)


def test_to_dict_round_trip_is_plain_json():
    sq = Superquadric([0.1, 0.2, 0.3], [0.4, 1.2], pose(euler_zyx(10, 20, 30), [1, 2, 3]))
    d = json.loads(json.dumps(sq.to_dict()))
    assert set(d) == {"size", "shape", "T_world_object"}
    back = Superquadric.from_dict(d)
    np.testing.assert_array_equal(back.size, sq.size)
    np.testing.assert_array_equal(back.shape, sq.shape)
    np.testing.assert_array_equal(back.T_world_object, sq.T_world_object)


def test_ellipsoid_volume_and_support_closed_forms():
    sq = Superquadric([1.0, 2.0, 3.0], [1.0, 1.0], pose(np.eye(3), [1, 1, 1]))
    assert sq.volume == pytest.approx(4 / 3 * np.pi * 6, rel=1e-12)
    v = np.array([1.0, -2.0, 0.5])
    # Ellipsoid: h(v) = c.v + |diag(a) v|.
    assert sq.support(v) == pytest.approx(v.sum() + np.linalg.norm([1.0, -4.0, 1.5]), rel=1e-12)


@pytest.mark.parametrize("shape", list(FAMILIES.values()) + [(1.6, 0.3)], ids=str)
def test_support_matches_dense_surface_sampling(shape):
    rng = np.random.default_rng(1)
    sq = Superquadric([0.05, 0.03, 0.02], shape, pose(euler_zyx(20, 35, -60), [0.1, 0.2, 0.3]))
    surface = surface_points(sq, n_eta=300, n_omega=600)
    centre = sq.T_world_object[:3, 3]
    for normal in rng.normal(size=(10, 3)):
        sampled = (surface - centre) @ normal
        h = sq.support(normal) - centre @ normal
        assert h >= sampled.max() - 1e-12  # the exact maximum bounds every sample
        assert h == pytest.approx(sampled.max(), rel=0.01)


@pytest.mark.parametrize("shape", list(FAMILIES.values()) + [(1.9, 0.1)], ids=str)
def test_mesh_is_closed_outward_and_on_the_surface(shape):
    sq = Superquadric([0.5, 1.0, 1.5], shape, pose(euler_zyx(40, 10, -20), [3, -1, 2]))
    vertices, triangles = mesh(sq, n_eta=24, n_omega=48)
    assert vertices.shape == (24 * 48 + 2, 3)
    assert triangles.dtype == np.int32 and triangles.shape == (2 * 24 * 48, 3)
    assert triangles.min() >= 0 and triangles.max() < len(vertices)
    assert np.abs(inside_outside(vertices, sq) - 1).max() < 1e-6
    # Closed: every directed edge appears once and its reverse once.
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    directed = {tuple(e) for e in edges.tolist()}
    assert len(directed) == len(edges)
    assert all((b, a) in directed for a, b in directed)
    # Outward: positive enclosed volume, close to the closed form for a fine mesh.
    a, b, c = (vertices[triangles[:, k]] - vertices[0] for k in range(3))
    enclosed = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
    assert enclosed > 0
    if shape == (1.0, 1.0):
        assert enclosed == pytest.approx(sq.volume, rel=0.02)


def test_surface_points_are_the_mesh_vertices():
    sq = Superquadric([1.0, 1.0, 2.0], [0.5, 1.0], np.eye(4))
    np.testing.assert_array_equal(surface_points(sq, 5, 7), mesh(sq, 5, 7)[0])


# --- the objective's gradient ----------------------------------------------------------


NO_PLANE = np.zeros(4)


def numerical_gradient(f, x: np.ndarray) -> np.ndarray:
    grad = np.empty_like(x)
    for k in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[k]))
        up, down = x.copy(), x.copy()
        up[k] += h
        down[k] -= h
        grad[k] = (f(up) - f(down)) / (2 * h)
    return grad


@pytest.mark.parametrize("shape", FAMILIES.values(), ids=FAMILIES.keys())
@pytest.mark.parametrize("cauchy", [False, True], ids=["squared", "cauchy"])
def test_objective_gradient_matches_central_differences(shape, cauchy):
    rng = np.random.default_rng(2)
    points = rng.normal(size=(300, 3))
    for _ in range(4):
        R0 = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        x = np.concatenate([rng.uniform(0.5, 1.5, 3), np.multiply(shape, rng.uniform(0.9, 1.1, 2)),
                            rng.normal(scale=0.2, size=3), rng.uniform(-1, 1, 3)])
        grad = np.empty(11)
        objective(x, R0, points, 10.0, cauchy, 0.1, NO_PLANE, 0.0, grad)
        expected = numerical_gradient(
            lambda y: objective(y, R0, points, 10.0, cauchy, 0.1, NO_PLANE, 0.0, np.empty(11)), x)
        assert np.linalg.norm(grad - expected) < 1e-5 * np.linalg.norm(expected)


@pytest.mark.parametrize("shape", FAMILIES.values(), ids=FAMILIES.keys())
def test_support_plane_penalty_gradient_matches_central_differences(shape):
    rng = np.random.default_rng(3)
    points = rng.normal(size=(100, 3))
    plane = np.array([0.2, -0.3, 1.0, 0.0]) / np.linalg.norm([0.2, -0.3, 1.0])
    f = _Objective(points, np.eye(3), 10.0, True, 0.1, plane, step_scale=0.1)
    for _ in range(4):
        x = np.concatenate([rng.uniform(0.5, 1.5, 3), np.multiply(shape, rng.uniform(0.9, 1.1, 2)),
                            rng.normal(scale=0.2, size=3), rng.uniform(-1, 1, 3)])
        cost, grad = f(x / 0.1)
        without_plane = _Objective(points, np.eye(3), 10.0, True, 0.1, None, step_scale=0.1)
        assert cost > without_plane(x / 0.1)[0]  # the superquadric dips below the plane
        expected = numerical_gradient(lambda y: f(y)[0], x / 0.1)
        assert np.linalg.norm(grad - expected) < 1e-5 * np.linalg.norm(expected)


# --- the fit ---------------------------------------------------------------------------

TRUTH_POSES = [
    pose(euler_zyx(25, 40, -70), [0.4, -0.2, 0.1]),
    pose(euler_zyx(-120, -15, 35), [-1.0, 0.5, 0.3]),
]


@pytest.mark.parametrize("T", TRUTH_POSES, ids=["pose0", "pose1"])
@pytest.mark.parametrize("shape", FAMILIES.values(), ids=FAMILIES.keys())
def test_fit_recovers_each_family_in_any_units(shape, T):
    rng = np.random.default_rng(4)
    truth = Superquadric([0.05, 0.035, 0.025], shape, T)
    points = sample_surface(truth, 800, rng)
    ious = []
    for unit in (1.0, 1000.0, 1e-3):  # metres, millimetres, kilometres
        scaled_truth = Superquadric(truth.size * unit, shape, pose(T[:3, :3], T[:3, 3] * unit))
        fit = fit_superquadric(points * unit)
        T_fit = fit.superquadric.T_world_object
        assert np.linalg.det(T_fit[:3, :3]) == pytest.approx(1.0, abs=1e-9)
        assert np.all(fit.superquadric.size > 0)
        ious.append(volumetric_iou(fit.superquadric, scaled_truth))
    assert min(ious) > 0.98, ious
    assert max(ious) - min(ious) < 2e-3, ious


def test_fit_result_fields_and_determinism():
    rng = np.random.default_rng(5)
    truth = Superquadric([2.0, 1.5, 1.0], (0.4, 0.4), pose(euler_zyx(10, 20, 30), [5, 5, 5]))
    points = sample_surface(truth, 600, rng, noise=0.0)
    fit = fit_superquadric(points)
    again = fit_superquadric(points)
    np.testing.assert_array_equal(fit.superquadric.T_world_object,
                                  again.superquadric.T_world_object)
    assert fit.iterations > 0 and fit.axis_order in (0, 1, 2)
    assert fit.residual < 0.01 and fit.cost < 1e-3
    assert volumetric_iou(fit.superquadric, truth) > 0.99
    sub = fit_superquadric(points, subsample=200)
    assert volumetric_iou(sub.superquadric, truth) > 0.98


def test_plain_jaklic_cost_fits_a_clean_ellipsoid():
    rng = np.random.default_rng(6)
    truth = Superquadric([3.0, 2.0, 1.0], (1.0, 1.0), pose(euler_zyx(0, 30, 60), [0, 0, 0]))
    points = sample_surface(truth, 400, rng, noise=0.0)
    fit = fit_superquadric(points, inside_weight=1.0, outside_loss="squared")
    assert volumetric_iou(fit.superquadric, truth) > 0.995
    # RMS of F^e1 - 1 (about twice the relative radial error) below 0.1 %.
    assert fit.residual / math.sqrt(np.prod(fit.superquadric.size)) < 1e-3


def test_support_plane_keeps_the_bottom_on_the_table():
    """An upright cylinder (radius 3 cm, height 10 cm) standing on z = 0, seen as a hull
    whose side runs on 2 cm below the table and has no bottom cap."""
    rng = np.random.default_rng(7)
    radius, half_height = 0.03, 0.05
    z = rng.uniform(-0.02, 2 * half_height, 800)
    phi = rng.uniform(0, 2 * np.pi, 800)
    side = np.c_[radius * np.cos(phi), radius * np.sin(phi), z]
    rho, phi = radius * np.sqrt(rng.uniform(0, 1, 200)), rng.uniform(0, 2 * np.pi, 200)
    top = np.c_[rho * np.cos(phi), rho * np.sin(phi), np.full(200, 2 * half_height)]
    points = np.r_[side, top] + rng.normal(scale=2e-4, size=(1000, 3)) + [0.3, 0.1, 0.0]
    truth = Superquadric([radius, radius, half_height], (0.1, 1.0),
                         pose(np.eye(3), [0.3, 0.1, half_height]))

    free = fit_superquadric(points).superquadric
    assert -free.support([0, 0, -1]) < -0.01  # without the plane it sinks into the table
    for plane, unit in (([0, 0, 1, 0], 1.0), ([0, 0, 2.0, 0], 1.0), ([0, 0, 1, 0], 1000.0)):
        fit = fit_superquadric(points * unit, support_plane=plane).superquadric
        bottom = -fit.support([0, 0, -1]) / unit
        assert abs(bottom) < 1e-3  # within 1 mm of the table
        scaled_truth = Superquadric(truth.size * unit, truth.shape,
                                    pose(np.eye(3), truth.T_world_object[:3, 3] * unit))
        assert volumetric_iou(fit, scaled_truth) > 0.97


# --- errors ----------------------------------------------------------------------------

CUBE = np.random.default_rng(8).uniform(-1, 1, size=(50, 3))


@pytest.mark.parametrize("points, message", [
    (CUBE[:10], "at least 11 points"),
    (np.where(np.arange(150).reshape(50, 3) == 7, np.nan, CUBE), "NaN or infinity"),
    (CUBE[:, :2], r"\(N, 3\) array of 3D points, got shape \(50, 2\)"),
    (CUBE.ravel(), r"\(N, 3\) array of 3D points, got shape \(150,\)"),
    (np.zeros((20, 3)), "all points coincide"),
])
def test_fit_rejects_bad_points(points, message):
    with pytest.raises(FitError, match=message):
        fit_superquadric(points)


@pytest.mark.parametrize("options, message", [
    ({"outside_loss": "huber"}, "outside_loss must be 'cauchy' or 'squared', got 'huber'"),
    ({"inside_weight": 0.0}, "inside_weight must be a positive number"),
    ({"cauchy_scale": -1.0}, "cauchy_scale must be a positive number"),
    ({"shape_bounds": (0.1, 2.5)}, r"0 < low <= high < 2"),
    ({"max_iterations": 0}, "max_iterations must be a positive integer"),
    ({"subsample": 5}, "subsample must be None or an integer >= 11"),
    ({"support_plane": [0, 0, 1]}, r"support_plane must be 4 finite numbers, got shape \(3,\)"),
    ({"support_plane": [0, 0, 0, 1]}, "normal .* must not be zero"),
])
def test_fit_rejects_bad_options(options, message):
    with pytest.raises(FitError, match=message):
        fit_superquadric(CUBE, **options)


def test_errors_are_value_errors_with_clear_messages():
    with pytest.raises(ValueError, match="at least 11 points"):
        fit_superquadric(CUBE[:3])
    sq = Superquadric([1, 1, 1], [1, 1], np.eye(4))
    with pytest.raises(CoreError, match=r"\(N, 3\) array of 3D points, got shape \(3,\)"):
        inside_outside([1.0, 2.0, 3.0], sq)
    with pytest.raises(CoreError, match="size and shape must be positive"):
        Superquadric([1, -1, 1], [1, 1], np.eye(4))
    with pytest.raises(CoreError, match=r"size must be 3 finite numbers, got shape \(2,\)"):
        Superquadric([1, 1], [1, 1], np.eye(4))
    with pytest.raises(CoreError, match="T_world_object is not a rigid transform"):
        Superquadric([1, 1, 1], [1, 1], np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(CoreError, match="keys 'size', 'shape' and 'T_world_object'"):
        Superquadric.from_dict({"size": [1, 1, 1]})
    with pytest.raises(CoreError, match="exponents below 2"):
        Superquadric([1, 1, 1], [2.5, 1], np.eye(4)).support([0, 0, 1])
    with pytest.raises(CoreError, match="n_eta >= 1 and n_omega >= 3"):
        mesh(sq, n_eta=0)
