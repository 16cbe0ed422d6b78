"""Levenberg-Marquardt for the fits' small least-squares problems."""

from __future__ import annotations

import numpy as np
import pytest

from core_cy._least_squares_cy import damped_step
from core_cy.least_squares import Descent


def test_the_damped_step_solves_the_damped_normal_equations():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(30, 11))
    JtJ, Jtr = J.T @ J, J.T @ rng.normal(size=30)
    step = np.empty(11)
    assert damped_step(JtJ, Jtr, 0.1, step)
    np.testing.assert_allclose(step, np.linalg.solve(JtJ + 0.1 * np.diag(np.diag(JtJ) + 1e-12), -Jtr),
                               rtol=1e-10)
    indefinite = -np.eye(11)
    assert not damped_step(indefinite, Jtr, 0.1, step)
    with pytest.raises(ValueError, match="n <= 16"):
        damped_step(np.eye(17), np.zeros(17), 0.1, np.empty(17))


class _Circle:
    """Centre (cx, cy) and radius r of a circle through points: residuals |p - c| - r."""

    def __init__(self, points):
        self.points = points
        self.evaluations = 0

    def evaluate(self, x, JtJ, Jtr):
        self.evaluations += 1
        offsets = self.points - x[:2]
        distances = np.linalg.norm(offsets, axis=1)
        residuals = distances - x[2]
        J = np.column_stack([-offsets / distances[:, None], -np.ones(len(distances))])
        JtJ[:], Jtr[:] = J.T @ J, J.T @ residuals
        return 0.5 * float(residuals @ residuals)

    def keep(self, accepted):
        pass


def test_descent_finds_a_circle_and_stops():
    angles = np.linspace(0, 2 * np.pi, 20, endpoint=False)
    points = np.column_stack([3 + 2 * np.cos(angles), -1 + 2 * np.sin(angles)])
    problem = _Circle(points)
    descent = Descent(problem, [0.0, 0.0, 1.0], [-10, -10, 0.1], [10, 10, 10]).run(50)
    np.testing.assert_allclose(descent.x, [3, -1, 2], atol=1e-6)
    assert descent.converged and descent.iterations < 30
    assert descent.iterations + 1 == problem.evaluations  # one evaluation per step, plus the start


def test_descent_keeps_to_its_bounds_and_runs_in_instalments():
    angles = np.linspace(0, 2 * np.pi, 20, endpoint=False)
    points = np.column_stack([3 + 2 * np.cos(angles), -1 + 2 * np.sin(angles)])
    descent = Descent(_Circle(points), [0.0, 0.0, 1.0], [-10, -10, 0.1], [10, 10, 1.5])
    descent.run(2)
    assert descent.iterations == 2 and not descent.converged
    descent.run(50)
    # The radius is held at its bound; the centre still finds its place (to where a step would
    # lower the cost by less than 1e-4 of it).
    assert descent.x[2] == 1.5
    np.testing.assert_allclose(descent.x[:2], [3, -1], atol=0.01)
    assert descent.converged
