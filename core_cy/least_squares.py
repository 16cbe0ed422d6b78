"""Levenberg-Marquardt for the fits' small robust least-squares problems (11 parameters).

A problem gives, for parameters x, its cost and the Gauss-Newton normal
equations (J^T W J and J^T W r, W the weights of its robust loss);
:class:`Descent` steps it with Marquardt's damping (relative to the normal
matrix's diagonal, so the parameters' units do not matter) within bounds, and
can be run in instalments: a few steps for each of several starts, then on
from the best.
"""

from __future__ import annotations

from typing import Generic, Protocol, TypeVar

import numpy as np

from ._least_squares_cy import bounded_step

__all__ = ["Problem", "Descent"]

_DAMPING = 1e-3  # the first step's damping, relative to the normal matrix's diagonal
_RELATIVE_DECREASE = 1e-4  # converged when the next step promises less than this share of the cost


class Problem(Protocol):
    """What :class:`Descent` needs from a least-squares problem."""

    def evaluate(self, x: np.ndarray, JtJ: np.ndarray, Jtr: np.ndarray) -> float:
        """The cost at x, filling ``JtJ`` (n, n) and ``Jtr`` (n,); inf where x is not allowed."""
        ...

    def keep(self, accepted: bool) -> None:
        """Called after each trial: whether the parameters last evaluated were kept."""
        ...


ProblemT = TypeVar("ProblemT", bound=Problem)


class Descent(Generic[ProblemT]):
    """Levenberg-Marquardt on ``problem`` from ``x`` within ``[low, high]``; :meth:`run` continues.

    Attributes ``x``, ``cost`` (of ``x``), ``iterations`` (steps tried) and
    ``converged``: ``x`` is not allowed, or the next step promises to lower
    the cost by less than 1e-4 of it plus ``tolerance`` (in the cost's units:
    what counts as nothing where the cost itself is near 0).
    """

    def __init__(self, problem: ProblemT, x, low, high, tolerance: float = 0.0):
        self.problem, self.tolerance = problem, float(tolerance)
        self.low = np.ascontiguousarray(low, dtype=np.float64)
        self.high = np.ascontiguousarray(high, dtype=np.float64)
        self.x = np.clip(np.asarray(x, dtype=np.float64), self.low, self.high)
        n = len(self.x)
        self.JtJ, self.Jtr = np.empty((n, n)), np.empty(n)
        self._trial_JtJ, self._trial_Jtr = np.empty((n, n)), np.empty(n)
        self.cost = problem.evaluate(self.x, self.JtJ, self.Jtr)
        problem.keep(True)
        self.damping, self.iterations = _DAMPING, 0
        self.converged = not np.isfinite(self.cost)

    def run(self, iterations: int) -> Descent[ProblemT]:
        """Take up to ``iterations`` more steps; returns self."""
        stop = self.iterations + iterations
        while not self.converged and self.iterations < stop:
            trial = np.empty_like(self.x)
            promise = bounded_step(self.JtJ, self.Jtr, self.damping, self.x, self.low, self.high, trial)
            if promise < _RELATIVE_DECREASE * self.cost + self.tolerance:
                self.converged = True  # no step promises (almost) anything, or none can be taken
                break
            self.iterations += 1
            trial_cost = self.problem.evaluate(trial, self._trial_JtJ, self._trial_Jtr)
            accepted = trial_cost < self.cost
            self.problem.keep(accepted)
            if accepted:
                self.x, self.cost = trial, trial_cost
                self.JtJ, self._trial_JtJ = self._trial_JtJ, self.JtJ
                self.Jtr, self._trial_Jtr = self._trial_Jtr, self.Jtr
                self.damping /= 3
            else:
                self.damping *= 4
        return self
