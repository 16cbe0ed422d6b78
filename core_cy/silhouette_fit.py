"""Fit a superquadric to the silhouettes themselves (DESIGN.md §1, step 7).

What the cameras saw is each silhouette's edge: the ray through an edge point
just touches the object. For the superquadric that means: among the planes
that contain the ray, the one its outline (seen from that camera) says is
tangent must be tangent to it, so its support function h along the plane's
normal m meets the plane, ``h(m) = m . c``. The residual of an edge sample is
the gap ``h(m) - m . c`` turned into pixels (through the sample's depth): the
signed distance, in the image, from the sample to the superquadric's outline
(positive inside). The normal comes from the outline where it passes nearest
the sample, re-taken at every step; since the gap is stationary in the plane's
tilt about the ray at the true tangent (an envelope), the step's Jacobian
needs only h's derivatives at a fixed m, which the support function gives in
closed form.

Every sample of every view is one residual under the same robust loss, so a
view added is evidence added, with nothing to retune; the support plane, when
given, is one more tangent plane (the object stands on it). Levenberg-Marquardt
from a start (the point fit) minimises the sum.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ._silhouette_fit_cy import normal_equations, project, surface, tangent_planes
from .camera import Camera
from .errors import FitError
from .superquadric import Superquadric, _rotation

__all__ = ["SilhouetteFit", "fit_to_silhouettes"]

# The outline is the convex hull of the surface on this grid (signed powers put the points where
# the surface bends, so a box's edges are as well drawn as an ellipsoid's rim).
_ETA = -np.pi / 2 + np.pi * np.arange(1, 17) / 17
_OMEGA = -np.pi + 2 * np.pi * np.arange(40) / 40
_SHAPE_BOUNDS = (0.1, 1.9)
# The polygon outline's normals are off by up to half its angle between vertices (a few degrees):
# the residual tries the plane turned about the ray by this much either way (radians).
_TILT = 0.05
# Levenberg-Marquardt: the damping, relative to the normal matrix's diagonal, starts here; the
# fit stops when the next step promises to lower the cost by less than _RTOL of it.
_DAMPING = 1e-3
_RTOL = 1e-4
# With several starts, each takes this many steps before the best goes on.
_SEARCH_ITERATIONS = 4


@dataclass(frozen=True, eq=False)
class SilhouetteFit:
    """Result of :func:`fit_to_silhouettes`.

    Attributes
    ----------
    superquadric : Superquadric
    rms_px : float
        RMS distance (pixels) of the edge samples from the superquadric's outlines.
    iterations : int
        Levenberg-Marquardt steps tried.
    """

    superquadric: Superquadric
    rms_px: float
    iterations: int


class _Problem:
    """The samples and cameras; turns parameters about a start into tangent planes and the normal equations.

    ``depths`` are the object's depth in each view: they turn the planes'
    gaps into pixels, the same for every start so that costs compare.
    """

    def __init__(self, start: Superquadric, views, samples: int, support_plane, plane_weight, loss_scale):
        self.R0 = np.ascontiguousarray(start.T_world_object[:3, :3])
        self.t0 = start.T_world_object[:3, 3].copy()
        self.scale = float(np.mean(start.size))
        self.views, self.samples = views, samples
        self.support_plane, self.plane_weight, self.loss_scale = support_plane, plane_weight, loss_scale
        self.surface = np.empty((len(_ETA) * len(_OMEGA) + 2, 3))
        self.uv = np.empty((len(self.surface), 2), np.float32)
        self.planes = np.empty((samples, 9))

    def start(self, superquadric: Superquadric) -> np.ndarray:
        return np.concatenate([np.log(superquadric.size), np.clip(superquadric.shape, *_SHAPE_BOUNDS), np.zeros(6)])

    def superquadric(self, x: np.ndarray) -> Superquadric:
        T = np.eye(4)
        T[:3, :3] = _rotation(self.R0, x[8:11])
        T[:3, 3] = self.t0 + self.scale * x[5:8]
        return Superquadric(np.exp(x[:3]), x[3:5], T)

    def planes_at(self, x: np.ndarray) -> bool:
        """Tangent planes of every sample for the superquadric x; False if it reaches behind a camera."""
        R = np.ascontiguousarray(_rotation(self.R0, x[8:11]))
        surface(np.exp(x[:3]), np.ascontiguousarray(x[3:5]), R, self.t0 + self.scale * x[5:8], _ETA, _OMEGA,
                self.surface)
        row = 0
        for projection, samples, K, R_cam, centre, pixels_per_unit in self.views:
            if not project(self.surface, projection, self.uv):
                return False
            hull = cv2.convexHull(self.uv).reshape(-1, 2)
            tangent_planes(hull, samples, K, R_cam, centre, pixels_per_unit, self.planes[row:row + len(samples)])
            row += len(samples)
        return True

    def cost(self, x, JtJ, Jtr, jacobian=True) -> float:
        return normal_equations(x, self.R0, self.t0, self.scale, self.planes, self.loss_scale,
                                self.support_plane, self.plane_weight, _TILT, JtJ, Jtr, jacobian)


class _Descent:
    """Levenberg-Marquardt on one problem from one start; :meth:`run` continues where it stopped."""

    def __init__(self, problem: _Problem, start: Superquadric):
        self.problem = problem
        self.x = problem.start(start)
        self.JtJ, self.Jtr = np.empty((11, 11)), np.empty(11)
        self.trial_JtJ, self.trial_Jtr = np.empty((11, 11)), np.empty(11)
        self.cost = problem.cost(self.x, self.JtJ, self.Jtr) if problem.planes_at(self.x) else np.inf
        self.damping, self.iterations, self.converged = _DAMPING, 0, not np.isfinite(self.cost)
        self.low, self.high = np.full(11, -np.inf), np.full(11, np.inf)
        self.low[3:5], self.high[3:5] = _SHAPE_BOUNDS
        # Sizes stay within a factor e^4 (55) of the start's: a size collapsing to 0 is no object.
        self.low[0:3], self.high[0:3] = self.x[0:3] - 4.0, self.x[0:3] + 4.0

    def run(self, iterations: int) -> None:
        problem, stop = self.problem, self.iterations + iterations
        if not self.converged:
            problem.planes_at(self.x)
        while not self.converged and self.iterations < stop:
            JtJ, Jtr = self.JtJ, self.Jtr
            step = np.linalg.solve(JtJ + self.damping * np.diag(np.diag(JtJ) + 1e-12), -Jtr)
            trial = np.clip(self.x + step, self.low, self.high)
            step = trial - self.x
            # Converged when even the Gauss-Newton model of the cost promises (almost) nothing.
            if -(Jtr @ step + 0.5 * step @ JtJ @ step) < _RTOL * self.cost:
                self.converged = True
                break
            self.iterations += 1
            trial_cost = (problem.cost(trial, self.trial_JtJ, self.trial_Jtr) if problem.planes_at(trial)
                          else np.inf)
            if trial_cost < self.cost:
                self.x, self.cost = trial, trial_cost
                self.JtJ, self.trial_JtJ, self.Jtr, self.trial_Jtr = self.trial_JtJ, JtJ, self.trial_Jtr, Jtr
                self.damping /= 3
            else:
                problem.planes_at(self.x)  # back to the planes of the kept parameters
                self.damping *= 4


def _views(cameras, edges, reference: np.ndarray):
    """Per view with samples: (projection, samples, K, R, centre, 1 / depth of ``reference``)."""
    views, scales = [], []
    for camera, samples in zip(cameras, edges):
        samples = np.ascontiguousarray(samples, dtype=np.float64).reshape(-1, 2)
        (_, depth) = camera.project(reference[None])
        if depth[0] <= 0:
            raise FitError("the object lies behind the camera", view=camera.view)
        scales.append(camera.focal_length / depth[0])
        if len(samples):
            views.append((camera.projection, samples, camera.K, np.ascontiguousarray(camera.T_world_cam[:3, :3]),
                          np.ascontiguousarray(camera.center), 1.0 / depth[0]))
    return views, float(np.mean(scales))


def fit_to_silhouettes(starts, cameras, edges, *, support_plane=None, loss_scale: float = 1.0,
                       max_iterations: int = 40) -> SilhouetteFit:
    """Refine a superquadric until its outline in every view runs through that view's edge samples.

    Parameters
    ----------
    starts : Superquadric or sequence of Superquadric
        Where to start (the point fit's candidates); each must lie in front
        of every camera. With several, each takes a few steps and the one
        whose outlines then fit best goes on.
    cameras : sequence of Camera
        Ideal pinhole cameras of the views.
    edges : sequence of (N_i, 2) array_like
        Each view's edge samples, pixels of the ideal pinhole image
        (:func:`core_cy.edges.edge_samples`); a view may have none.
    support_plane : (4,) array_like, optional
        ``[nx, ny, nz, d]`` with a unit normal: the object stands on it, where
        ``n . x + d >= 0``.
    loss_scale : float
        Residuals (pixels) up to about this size count quadratically, larger
        ones linearly: the edge's noise, not a property of the views.
    max_iterations : int
        Levenberg-Marquardt steps at most, after the choice among the starts.

    Returns
    -------
    SilhouetteFit

    Raises
    ------
    FitError
        If there are fewer than 11 samples in all, or a start lies behind a camera.
    """
    starts = [starts] if isinstance(starts, Superquadric) else list(starts)
    if not starts:
        raise FitError("need at least one start")
    if len(cameras) != len(edges):
        raise FitError(f"got {len(cameras)} cameras but {len(edges)} sets of edge samples")
    views, pixel_scale = _views(cameras, edges, starts[0].T_world_object[:3, 3])
    samples = sum(len(view[1]) for view in views)
    if samples < 11:
        raise FitError(f"need at least 11 edge samples (one per parameter), got {samples}")
    if support_plane is None:
        plane, plane_weight = np.zeros(4), 0.0
    else:
        # The support plane is as sure as a whole view's samples, each seen at the views' mean scale.
        plane = np.asarray(support_plane, dtype=np.float64)
        plane_weight = pixel_scale * math.sqrt(samples / len(views))
    descents = [_Descent(_Problem(start, views, samples, plane, plane_weight, float(loss_scale)), start)
                for start in starts]
    if len(descents) > 1:
        for descent in descents:
            descent.run(_SEARCH_ITERATIONS)
    best = min(descents, key=lambda descent: descent.cost)
    if not np.isfinite(best.cost):
        raise FitError("every start reaches behind a camera")
    best.run(max_iterations)
    rms = math.sqrt(2 * best.cost / samples) if best.cost > 0 else 0.0
    return SilhouetteFit(best.problem.superquadric(best.x), rms, best.iterations)
