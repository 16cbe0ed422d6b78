"""Levenberg-Marquardt for the fits' small least-squares problems."""

from __future__ import annotations

import numpy as np
import pytest

from robocell.core_cy._least_squares_cy import bounded_step
from robocell.core_cy.least_squares import Descent


def test_the_step_solves_the_damped_normal_equations_within_bounds():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(30, 11))
    JtJ, Jtr = J.T @ J, J.T @ rng.normal(size=30)
    x, low, high, trial = np.zeros(11), np.full(11, -1e9), np.full(11, 1e9), np.empty(11)
    free = np.linalg.solve(JtJ + 0.1 * np.diag(np.diag(JtJ) + 1e-12), -Jtr)
    promise = bounded_step(JtJ, Jtr, 0.1, x, low, high, trial)
    np.testing.assert_allclose(trial, free, rtol=1e-10)
    assert promise == pytest.approx(-(Jtr @ free + 0.5 * free @ JtJ @ free))
    # A parameter on its bound, pushed beyond it, is held; the others solve without it.
    k = int(np.argmax(np.abs(free)))
    low[k] = high[k] = 0.0
    bounded_step(JtJ, Jtr, 0.1, x, low, high, trial)
    rest = [i for i in range(11) if i != k]
    held = np.linalg.solve((JtJ + 0.1 * np.diag(np.diag(JtJ) + 1e-12))[np.ix_(rest, rest)], -Jtr[rest])
    assert trial[k] == 0.0
    np.testing.assert_allclose(trial[rest], held, rtol=1e-10)
    # A far bound shortens the whole step to end on it.
    low[k], high[k] = -1e9, 1e9
    high[:] = np.where(free > 0, free / 2, 1e9)
    low[:] = np.where(free < 0, free / 2, -1e9)
    bounded_step(JtJ, Jtr, 0.1, x, low, high, trial)
    np.testing.assert_allclose(trial, free / 2, rtol=1e-10)
    assert trial[k] == (high[k] if free[k] > 0 else low[k])  # the bound that cut it short, to the bit
    assert bounded_step(-np.eye(11), Jtr, 0.1, x, low, high, trial) == -1.0  # not positive definite
    with pytest.raises(ValueError, match="n <= 66"):  # six parts of a union, 11 parameters each
        bounded_step(np.eye(67), np.zeros(67), 0.1, np.zeros(67), np.zeros(67), np.zeros(67), np.empty(67))


def test_a_parameter_a_rounding_error_inside_its_bound_is_on_it():
    """A step shortened to end on a bound lands on it only to within rounding: a parameter left a bit
    inside its bound, pushed out again, is held as one on it is, and does not cut the step to nothing
    (the descent would stop there, or go on, as the platform's last bit fell)."""
    rng = np.random.default_rng(1)
    J = rng.normal(size=(30, 11))
    JtJ, Jtr = J.T @ J, J.T @ rng.normal(size=30)
    free = np.linalg.solve(JtJ + 0.1 * np.diag(np.diag(JtJ) + 1e-12), -Jtr)
    k = int(np.argmax(np.abs(free)))
    low, high = np.full(11, -1e9), np.full(11, 1e9)
    x = np.zeros(11)
    bound = low if free[k] < 0 else high  # the one the free step pushes it beyond
    bound[k] = x[k] = 0.1
    on, on_promise = np.empty(11), bounded_step(JtJ, Jtr, 0.1, x, low, high, np.empty(11))
    bounded_step(JtJ, Jtr, 0.1, x, low, high, on)
    x[k] = np.nextafter(0.1, np.sign(-free[k]) * np.inf)  # one bit inside
    inside = np.empty(11)
    inside_promise = bounded_step(JtJ, Jtr, 0.1, x, low, high, inside)
    assert inside_promise == pytest.approx(on_promise, rel=1e-9) and on_promise > 0
    np.testing.assert_allclose(inside, on, rtol=1e-12, atol=1e-15)
    assert inside[k] == 0.1  # set on the bound


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
