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
from a start (the point fit) minimises the sum. A sample where the segmentation
cannot confirm the edge (``auto``'s unsure pixels: a shadow taken in, a dark face
left out) counts alike while near the model's outline, but its pull fades as it
lies farther: one view's doubtful stretch of outline cannot drag the model from
what the other views say. Held at rest on the support plane (``resting``), each part turns only
about the plane's normal.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from ._silhouette_fit_cy import normal_equations, outline_angles, part_planes, sample_rays
from .errors import FitError
from .least_squares import Descent
from .superquadric import Superquadric, _rotation, resting_on

__all__ = ["SilhouetteFit", "fit_to_silhouettes"]

# The outline is the convex hull of the surface on this grid, of the points where it turns away from
# the camera (signed powers put the points where the surface bends, so a box's edges are as well drawn
# as an ellipsoid's rim).
_ETA = -np.pi / 2 + np.pi * np.arange(1, 17) / 17
_OMEGA = -np.pi + 2 * np.pi * np.arange(40) / 40
_ANGLES = outline_angles(_ETA, _OMEGA)  # the grid's trigonometry, once
# Exponents above 1 pinch the shape (a diamond, a star): no object a robot picks, and a square
# section seen as a diamond turned 45 degrees is a false minimum on the way to the box.
_SHAPE_BOUNDS = (0.1, 1.0)
# The polygon outline's normals are off by up to half its angle between vertices (a few degrees):
# the residual tries the plane turned about the ray by this much either way (radians).
_TILT = 0.05
# Sizes stay within a factor e^4 (55) of the start's: a size collapsing to 0 is no object. Growing, they
# are also held within how far the object may reach, where it is given (fit_to_silhouettes).
_LOG_SIZE_RANGE = 4.0
# With several starts, each takes this many steps; the best two this many more; the best of them goes on.
_SEARCH_ITERATIONS = 2
_FINALISTS, _FINAL_ITERATIONS = 2, 6
# Edge samples lie this close (px, RMS) to the true outline: colour edges ~0.15, binary masks ~0.3.
_NOISE_PX = 0.5
# A model whose outlines run farther than this (px, RMS) from the samples leaves the silhouettes
# unexplained (the worst edges, binary masks, lie ~0.3 from the truth): the starts left behind go on.
_EXPLAINED_PX = 0.3


@dataclass(frozen=True, eq=False)
class SilhouetteFit:
    """Result of :func:`fit_to_silhouettes`.

    Attributes
    ----------
    parts : tuple of Superquadric
        The model: one superquadric, or the parts of a union.
    rms_px : float
        RMS distance (pixels) of the edge samples from the model's outlines
        (read from the robust cost: exact when they are all alike).
    iterations : int
        Levenberg-Marquardt steps tried from the start that won.
    evaluations : int
        Evaluations of the cost over every start, each part of a union counted: the fit's work, by
        which a later search can size its own (deterministic, unlike its time).
    others : tuple of tuple of Superquadric
        Where the descents from the other starts stopped, best (lowest edge cost) first: models
        that a judge other than the edges (how well all silhouettes agree) may prefer, each
        already some steps on from its start.
    """

    parts: tuple[Superquadric, ...]
    rms_px: float
    iterations: int
    evaluations: int = 0
    others: tuple[tuple[Superquadric, ...], ...] = ()

    @property
    def superquadric(self) -> Superquadric:
        """The first part (the only one of a one-part model)."""
        return self.parts[0]


@dataclass(frozen=True, eq=False)
class _Views:
    """The cameras and their edge samples, packed for the kernels."""

    projections: np.ndarray  # (V, 3, 4)
    centres: np.ndarray  # (V, 3)
    cameras: list  # (K, R camera-to-world, centre, 1 / object depth) per view
    samples: list  # (N_v, 2) per view
    rows: list  # slices of the planes array, per view
    count: int
    pixel_scale: float  # the views' mean f / depth: pixels per world unit at the object
    # The same stacked for the kernel that draws a part's tangent planes in every view in one call.
    all_samples: np.ndarray  # (N, 2)
    starts: np.ndarray  # (V + 1,) view v's samples are all_samples[starts[v]:starts[v + 1]]
    Ks: np.ndarray  # (V, 3, 3)
    Rs: np.ndarray  # (V, 3, 3) camera to world
    pixels_per_unit: np.ndarray  # (V,) 1 / the object's depth
    rays: np.ndarray  # (N, 3) each sample's ray, a unit direction in the world
    doubtful: np.ndarray | None  # (N,) uint8, 1 where the segmentation cannot confirm the edge; None: no such sample

    @classmethod
    def pack(cls, cameras, edges, reference: np.ndarray, doubtful=None) -> _Views:
        projections, centres, packed, samples, rows, scales, row = [], [], [], [], [], [], 0
        doubts = []
        doubtful = [None] * len(edges) if doubtful is None else list(doubtful)
        for camera, view_samples, view_doubts in zip(cameras, edges, doubtful):
            view_samples = np.ascontiguousarray(view_samples, dtype=np.float64).reshape(-1, 2)
            (_, depth) = camera.project(reference[None])
            if depth[0] <= 0:
                raise FitError("the object lies behind the camera", view=camera.view)
            scales.append(camera.focal_length / depth[0])
            if not len(view_samples):
                continue
            projections.append(camera.projection)
            centres.append(camera.center)
            packed.append((camera.K, np.ascontiguousarray(camera.T_world_cam[:3, :3]),
                           np.ascontiguousarray(camera.center), 1.0 / depth[0]))
            samples.append(view_samples)
            doubts.append(np.zeros(len(view_samples), np.uint8) if view_doubts is None
                          else np.asarray(view_doubts, dtype=bool).astype(np.uint8))
            rows.append(slice(row, row + len(view_samples)))
            row += len(view_samples)
        all_samples = np.ascontiguousarray(np.concatenate(samples) if samples else np.empty((0, 2)))
        starts = np.array([0] + [r.stop for r in rows], np.intp)
        Ks = np.ascontiguousarray([K for K, _, _, _ in packed], dtype=np.float64).reshape(-1, 3, 3)
        Rs = np.ascontiguousarray([R for _, R, _, _ in packed], dtype=np.float64).reshape(-1, 3, 3)
        return cls(np.ascontiguousarray(projections).reshape(-1, 3, 4), np.ascontiguousarray(centres).reshape(-1, 3),
                   packed, samples, rows, row, float(np.mean(scales)), all_samples, starts, Ks, Rs,
                   np.array([scale for _, _, _, scale in packed], dtype=np.float64),
                   sample_rays(all_samples, starts, Ks, Rs),
                   np.concatenate(doubts) if any(doubt.any() for doubt in doubts) else None)


class _Problem:
    """The silhouette fit of a union of parts about one start: parameters to tangent planes, cost
    and normal equations. Part p's 11 parameters are ``x[11 p: 11 p + 11]``."""

    def __init__(self, start, views: _Views, support_plane, plane_weight, loss_scale, tally: list[int] | None = None,
                 resting: bool = False, reach: float | None = None):
        parts = [start] if isinstance(start, Superquadric) else list(start)
        self.count = len(parts)
        self.tally = [0] if tally is None else tally  # part evaluations so far, shared by a fitter's problems
        self.R0 = np.ascontiguousarray([part.T_world_object[:3, :3] for part in parts])
        self.t0 = np.ascontiguousarray([part.T_world_object[:3, 3] for part in parts])
        self.scale = np.array([float(np.mean(part.size)) for part in parts])
        self.views, self.support_plane, self.plane_weight, self.loss_scale = (
            views, support_plane, plane_weight, loss_scale)
        grid = len(_ETA) * len(_OMEGA) + 2
        self.grid = np.empty((grid, 6))
        self.uv = np.empty((len(views.samples), grid, 2), np.float32)
        self.counts = np.empty(len(views.samples), np.intp)
        shape = (self.count, views.count, 9)
        self.planes, self.trial_planes = np.empty(shape), np.empty(shape)
        # Which part answered for each sample last time: the kernel tries it first (only its time depends on it).
        self.owner = np.zeros(views.count, np.intp)
        self.x0 = np.concatenate([np.concatenate([np.log(part.size), np.clip(part.shape, *_SHAPE_BOUNDS), np.zeros(6)])
                                  for part in parts])
        self.low, self.high = np.full(len(self.x0), -np.inf), np.full(len(self.x0), np.inf)
        for p in range(self.count):
            block = slice(11 * p, 11 * p + 11)
            low, high, x0 = self.low[block], self.high[block], self.x0[block]
            low[3:5], high[3:5] = _SHAPE_BOUNDS
            low[:3], high[:3] = x0[:3] - _LOG_SIZE_RANGE, x0[:3] + _LOG_SIZE_RANGE
            if reach is not None:  # a start already larger keeps its size as its bound
                high[:3] = np.maximum(x0[:3], np.minimum(high[:3], math.log(reach)))
        # Resting, each part's axis along the plane's normal stays so: it turns only about that axis
        # (R = R0 Rz Ry Rx, so with all three angles 0 the two about its other axes are what tilt it).
        self.held: list[int] = []
        if resting:
            for p in range(self.count):
                upright = int(np.argmax(np.abs(support_plane[:3] @ self.R0[p])))
                self.held += [11 * p + 8 + axis for axis in range(3) if axis != upright]

    def part(self, x: np.ndarray, p: int) -> Superquadric:
        y = x[11 * p: 11 * p + 11]
        T = np.eye(4)
        T[:3, :3] = _rotation(self.R0[p], y[8:11])
        T[:3, 3] = self.t0[p] + self.scale[p] * y[5:8]
        return Superquadric(np.exp(y[:3]), y[3:5], T)

    def parts(self, x: np.ndarray) -> tuple[Superquadric, ...]:
        return tuple(self.part(x, p) for p in range(self.count))

    def superquadric(self, x: np.ndarray) -> Superquadric:
        return self.part(x, 0)

    def evaluate(self, x: np.ndarray, JtJ: np.ndarray, Jtr: np.ndarray) -> float:
        views, planes = self.views, self.trial_planes
        self.tally[0] += self.count
        if not part_planes(x, self.R0, self.t0, self.scale, len(_ETA), _ANGLES, views.projections, views.centres,
                           views.all_samples, views.starts, views.Ks, views.Rs, views.pixels_per_unit, views.rays,
                           self.grid, self.uv, self.counts, planes):
            return np.inf  # a part reaches behind a camera, or its outline in a view is no polygon
        cost = normal_equations(x, self.R0, self.t0, self.scale, planes, self.loss_scale, self.support_plane,
                                self.plane_weight, _TILT, JtJ, Jtr, True, self.owner, views.doubtful)
        if self.held:  # no step along a held parameter: its row and column of the normal equations are set aside
            JtJ[self.held, :] = 0.0
            JtJ[:, self.held] = 0.0
            JtJ[self.held, self.held] = 1.0
            Jtr[self.held] = 0.0
        return cost

    def keep(self, accepted: bool) -> None:
        if accepted:
            self.planes, self.trial_planes = self.trial_planes, self.planes


def _other_axes_as_z(sq: Superquadric) -> list[Superquadric]:
    """The superquadric's frame turned so that its x, then its y axis becomes z (sizes and the two
    exponents following: the profile across the new z had the old profile's exponent)."""
    turned = []
    R, e1, e2 = sq.T_world_object[:3, :3], sq.shape[0], sq.shape[1]
    for order in ((1, 2, 0), (2, 0, 1)):
        T = sq.T_world_object.copy()
        T[:3, :3] = R[:, order]
        turned.append(Superquadric(sq.size[list(order)], np.array([e2, e1]), T))
    return turned


class _Fitter:
    """The views packed once, and the settings every start shares: descents from starts."""

    def __init__(self, cameras, edges, reference, support_plane, loss_scale: float, doubtful=None,
                 resting: bool = False, reach: float | None = None):
        if len(cameras) != len(edges):
            raise FitError(f"got {len(cameras)} cameras but {len(edges)} sets of edge samples")
        self.views = views = _Views.pack(cameras, edges, reference, doubtful)
        if views.count < 11:
            raise FitError(f"need at least 11 edge samples (one per parameter), got {views.count}")
        if support_plane is None:
            self.plane, self.plane_weight = np.zeros(4), 0.0
        else:
            # The support plane is as sure as a whole view's samples, each seen at the views' mean scale.
            self.plane = np.asarray(support_plane, dtype=np.float64)
            self.plane_weight = views.pixel_scale * math.sqrt(views.count / len(views.samples))
        self.loss_scale = float(loss_scale)
        self.resting = resting
        if reach is not None and not reach > 0:
            raise FitError(f"the object's reach must be positive, got {reach}")
        self.reach = reach
        # A step that moves the samples' residuals by 0.01 px (RMS) is no step.
        self.tolerance = 0.5 * 1e-4 * views.count
        self.tally = [0]
        self.descents: list[Descent] = []  # the last search's, one per start

    @property
    def evaluations(self) -> int:
        """Evaluations of the cost so far, over every descent, each part of a union counted."""
        return self.tally[0]

    def descent(self, start) -> Descent:
        """A descent from ``start`` (a Superquadric, or the parts of a union), not yet run."""
        problem = _Problem(start, self.views, self.plane, self.plane_weight, self.loss_scale, self.tally,
                           self.resting, self.reach)
        return Descent(problem, problem.x0, problem.low, problem.high, self.tolerance)

    def turned(self, parts: tuple[Superquadric, ...], k: int) -> Iterator[Descent]:
        """The union ``parts`` with part ``k`` turned so that another of its axes is z (:func:`_other_axes_as_z`),
        each turn a few steps on, one at a time: a part's z axis is the odd one out (its profile has its own
        exponent), and the same body with another axis as z can only be reached by that jump."""
        for turned in _other_axes_as_z(parts[k]):
            yield self.descent(parts[:k] + (turned,) + parts[k + 1:]).run(_SEARCH_ITERATIONS)

    def best_of(self, starts, max_iterations: int, finalists: int = _FINALISTS,
                explained_px: float | None = None, within: Callable[[], bool] | None = None) -> Descent:
        """The start whose descent fits best: every start a few steps, the ``finalists`` best of
        them a few more, and the best of those on to convergence. Two bodies (a lying cylinder and a
        bar) may explain the views alike after a step or two, and only a few steps on tell apart.

        With ``explained_px``: while the winner's outlines stay farther than that (RMS) from the
        samples, the silhouettes disagree with it (a bad local minimum): the starts left behind go
        on, in the order of their cost, each a few more steps, and one that then fits better than
        the winner goes on to convergence and wins if it ends lower (each start is tried once), while
        ``within`` (a budget) says so."""
        alive = [self.descent(start) for start in starts]
        self.descents = alive
        if len(alive) > 1:
            for descent in alive:
                descent.run(_SEARCH_ITERATIONS)
            alive = sorted(alive, key=lambda descent: descent.cost)
        chosen = alive[:max(1, finalists)]
        if len(alive) > 1 and len(chosen) > 1:
            for descent in chosen:
                descent.run(_FINAL_ITERATIONS)
        best = min(chosen, key=lambda descent: descent.cost)
        if not np.isfinite(best.cost):
            raise FitError("every start reaches behind a camera")
        best.run(max_iterations)
        if explained_px is None:
            return best
        for descent in alive:
            if self.rms(best.cost) <= explained_px or (within is not None and not within()):
                break
            if descent is best or not np.isfinite(descent.cost):
                continue
            if descent not in chosen:
                descent.run(_FINAL_ITERATIONS)
            if descent.cost < best.cost:
                descent.run(max_iterations)
                if descent.cost < best.cost:
                    best = descent
        return best

    def rms(self, cost: float) -> float:
        return _rms(cost, self.views.count, self.loss_scale)

    def result(self, descent: Descent, others: tuple[Descent, ...] = ()) -> SilhouetteFit:
        return SilhouetteFit(descent.problem.parts(descent.x), self.rms(descent.cost), descent.iterations,
                             self.evaluations, tuple(other.problem.parts(other.x) for other in others))


def _first_part(start) -> Superquadric:
    return start if isinstance(start, Superquadric) else list(start)[0]


def fit_to_silhouettes(starts, cameras, edges, *, support_plane=None, loss_scale: float = 1.0,
                       max_iterations: int = 40, doubtful=None, resting: bool = False,
                       reach: float | None = None) -> SilhouetteFit:
    """Refine a model until its outline in every view runs through that view's edge samples.

    The model is one superquadric, or a union of parts: the union's outline is the
    outermost of its parts', so each sample answers to the part that reaches farthest
    past it, and the parts are refined together.

    Parameters
    ----------
    starts : Superquadric or sequence
        Where to start (the point fit's candidates): each a Superquadric, or a tuple of
        Superquadric (the parts of a union); each must lie in front of every camera. With
        several, each takes a few steps and the one whose outlines then fit best goes on.
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
    doubtful : sequence of ((N_i,) array_like of bool or None), optional
        Per view, the samples whose edge the segmentation cannot confirm (``auto``'s, on its
        unsure pixels: :func:`core_cy.auto_segment.unsure_pixels`): their pull fades as they lie
        farther from the model's outline, so that a stretch of one view's outline that the
        others contradict (a shadow taken in, a dark face left out) cannot drag the model.
    resting : bool
        Each part is set resting on the support plane (its axis nearest the plane's normal
        along it: :func:`core_cy.superquadric.resting_on`) and kept so, turning only about that
        axis: the model of an object at rest on the plane. Needs ``support_plane``.
    reach : float, optional
        How far the object may reach from its centre, as the views see it
        (:func:`core_cy.sphere.farthest_reach`): no part's half-size grows past it. The edge samples
        pull each outline towards them, but nothing pulls back an outline that runs on past them all:
        a rod fitted along a hammer's handle may grow on along it far beyond what any camera saw.

    Returns
    -------
    SilhouetteFit

    Raises
    ------
    FitError
        If there are fewer than 11 samples in all, a start lies behind a camera, or
        ``reach`` is not positive.
    """
    starts = [starts] if isinstance(starts, Superquadric) else list(starts)
    if not starts:
        raise FitError("need at least one start")
    if resting:
        if support_plane is None:
            raise FitError("a model resting on the support plane needs the plane")
        normal = np.asarray(support_plane, dtype=np.float64)[:3]
        starts = [tuple(resting_on(part, normal)[0] for part in ([start] if isinstance(start, Superquadric) else start))
                  for start in starts]
    fitter = _Fitter(cameras, edges, _first_part(starts[0]).T_world_object[:3, 3], support_plane, loss_scale,
                     doubtful, resting, reach)
    best = fitter.best_of(starts, max_iterations, explained_px=_EXPLAINED_PX)
    descents = fitter.descents
    # The same body with another of its axes as z (_Fitter.turned): both turns are tried, each going on
    # only if a few steps bring it below the best so far. Not needed where the outlines already run
    # through the samples to within the edges' own noise: no other body can explain them better.
    if best.problem.count == 1 and fitter.rms(best.cost) > _NOISE_PX:
        for other in fitter.turned(best.problem.parts(best.x), 0):
            if other.cost < best.cost:
                best = other.run(max_iterations)
    others = sorted((descent for descent in descents if descent is not best and np.isfinite(descent.cost)),
                    key=lambda descent: descent.cost)
    return fitter.result(best, tuple(others))


def _rms(cost: float, count: int, loss_scale: float) -> float:
    """The RMS residual (px) a cost of the soft-L1 loss stands for (exactly, were all residuals equal)."""
    per_sample = cost / count / loss_scale**2
    return loss_scale * math.sqrt(per_sample * (per_sample + 2.0))
