"""Superquadrics: the model, its inside-outside function, surface and mesh, and the fit.

A superquadric has sizes ``a1, a2, a3`` (semi-axes), shape exponents ``e1``
(along the object's z axis) and ``e2`` (in its xy plane), and a pose
``T_world_object``. In the object frame its inside-outside function is::

    F = ((|x|/a1)^(2/e2) + (|y|/a2)^(2/e2))^(e2/e1) + (|z|/a3)^(2/e1)

F < 1 inside, F = 1 on the surface, F > 1 outside. ``e = 0.1`` gives box-like
edges, ``e = 1`` round ones; ``e1 = 0.1, e2 = 1`` is a cylinder along z.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from ._superquadric_cy import inside_outside as _inside_outside_kernel
from ._superquadric_cy import jaklic_normal_equations
from ._superquadric_cy import objective as _objective_kernel
from ._superquadric_cy import support as _support_kernel
from .errors import CoreError, FitError
from .least_squares import Descent
from .rigid import rigid_error

__all__ = [
    "Superquadric",
    "SuperquadricFit",
    "fit_superquadric",
    "inside_outside",
    "start_superquadrics",
    "resting_on",
    "upright_box",
    "mesh",
    "surface_points",
]

# Bounds in normalised units (points centred, RMS distance from the centroid 1).
_SIZE_BOUNDS = (0.01, 3.0)
_TRANSLATION_BOUND = 2.0
# Start search: a few iterations of each start on at most this many points.
_SEARCH_POINTS = 60
_SEARCH_ITERATIONS = 6
_START_SHAPE = (1.0, 1.0)  # an ellipsoid: from there e1 and e2 move either way
# A start turned 45 degrees about z is added when the two principal spreads
# across the z axis are closer than this ratio (their axes are then arbitrary).
_ROUND_RATIO = 1.3
# The optimiser sees the parameters divided by this: its first step (of unit
# length) then moves the superquadric by a tenth of its size, not across the bounds.
_STEP_SCALE = 0.1
# Stop when an iteration lowers the mean cost (about 1e-4 at a good fit) by less.
_FTOL = 1e-7
_MAXCOR = 20  # L-BFGS memory: 20 pairs took ~10 % fewer iterations than the default 10
# Weight of the squared depth below the support plane (normalised units). The
# data term's slope is small at a fit, so this already keeps the depth near
# 1e-3; a stiffer penalty (1e3) tripled the iterations on simulated hulls.
_PLANE_WEIGHT = 10.0


def _beta(a: float, b: float) -> float:
    """The Beta function, by log-gamma (scipy.special alone takes a fifth of a second to import)."""
    return math.exp(math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b))


def _vector(value, length: int, name: str, error=CoreError) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise error(f"{name} must be {length} finite numbers, got {value!r}") from exc
    if array.shape != (length,) or not np.all(np.isfinite(array)):
        raise error(f"{name} must be {length} finite numbers, got shape {array.shape}")
    return array


@dataclass(frozen=True, eq=False)
class Superquadric:
    """A superquadric posed in the world.

    Parameters
    ----------
    size : (3,) array_like
        Semi-axes ``a1, a2, a3`` along the object's x, y, z; positive, in the
        points' units.
    shape : (2,) array_like
        Shape exponents ``e1`` (z, "latitude") and ``e2`` (xy, "longitude"); positive.
    T_world_object : (4, 4) array_like
        Object-to-world rigid transform (rotation with determinant +1).

    Raises
    ------
    CoreError
        If a parameter has the wrong shape, is not finite or not positive, or
        the pose is not rigid.

    Examples
    --------
    >>> sq = Superquadric([1.0, 2.0, 3.0], [1.0, 1.0], np.eye(4))
    >>> round(sq.volume / (4 / 3 * np.pi * 6), 12)
    1.0
    >>> round(sq.support([0.0, 0.0, 1.0]), 12)
    3.0
    """

    size: np.ndarray
    shape: np.ndarray
    T_world_object: np.ndarray

    def __post_init__(self) -> None:
        size = _vector(self.size, 3, "size")
        shape = _vector(self.shape, 2, "shape")
        T = np.asarray(self.T_world_object, dtype=np.float64)
        if np.any(size <= 0) or np.any(shape <= 0):
            raise CoreError(f"size and shape must be positive, got size {size} and shape {shape}")
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise CoreError(f"T_world_object must be a finite 4x4 matrix, got shape {T.shape}")
        problem = rigid_error(T)
        if problem is not None:
            raise CoreError(f"T_world_object {problem}")
        for name, array in (("size", size), ("shape", shape), ("T_world_object", T)):
            array = np.array(array, order="C")
            array.flags.writeable = False
            object.__setattr__(self, name, array)

    def to_dict(self) -> dict:
        """Plain-JSON form: ``{"size": [3], "shape": [2], "T_world_object": 4x4 lists}``."""
        return {"size": [float(v) for v in self.size], "shape": [float(v) for v in self.shape],
                "T_world_object": [[float(v) for v in row] for row in self.T_world_object]}

    @classmethod
    def from_dict(cls, d) -> Superquadric:
        """Inverse of :meth:`to_dict`; raises CoreError if a key is missing."""
        try:
            return cls(d["size"], d["shape"], d["T_world_object"])
        except (KeyError, TypeError) as exc:
            raise CoreError("a superquadric needs the keys 'size', 'shape' and "
                            f"'T_world_object', got {d!r}") from exc

    @property
    def volume(self) -> float:
        """Enclosed volume, ``2 a1 a2 a3 e1 e2 B(e1/2 + 1, e1) B(e2/2, e2/2)``."""
        (a1, a2, a3), (e1, e2) = self.size, self.shape
        return float(2 * a1 * a2 * a3 * e1 * e2 * _beta(e1 / 2 + 1, e1) * _beta(e2 / 2, e2 / 2))

    def support(self, normal) -> float:
        """Support function: the maximum of ``normal . x`` over the surface (world).

        Uses the closed form of the nested dual norm, valid for a convex
        superquadric (both exponents below 2).

        Parameters
        ----------
        normal : (3,) array_like
            A world direction; need not be a unit vector (the result scales with it).

        Raises
        ------
        CoreError
            If ``normal`` is not 3 finite numbers, or an exponent is 2 or more.
        """
        normal = _vector(normal, 3, "normal")
        if np.any(self.shape >= 2):
            raise CoreError(f"support() needs shape exponents below 2 (convex), got {self.shape}")
        R, t = self.T_world_object[:3, :3], self.T_world_object[:3, 3]
        return float(normal @ t + _support_kernel(self.size, self.shape, R.T @ normal))


def _points(points, name: str = "points", error=CoreError) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64, order="C")
    if points.ndim != 2 or points.shape[1] != 3:
        raise error(f"{name} must be an (N, 3) array of 3D points, got shape {points.shape}")
    return points


def inside_outside(points, sq: Superquadric) -> np.ndarray:
    """Inside-outside function F of world points: < 1 inside, 1 on the surface, > 1 outside.

    Parameters
    ----------
    points : (N, 3) array_like of float64
        World points.
    sq : Superquadric

    Returns
    -------
    F : (N,) ndarray of float64

    Raises
    ------
    CoreError
        If ``points`` is not an (N, 3) array.

    Examples
    --------
    >>> sq = Superquadric([1.0, 2.0, 3.0], [1.0, 1.0], np.eye(4))
    >>> inside_outside([[1.0, 0, 0], [0, 0, 6.0], [0, 0, 0]], sq).round(12)
    array([1., 4., 0.])
    """
    points = _points(points)
    out = np.empty(len(points))
    T = sq.T_world_object
    _inside_outside_kernel(points, np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]),
                           sq.size, sq.shape, out)
    return out


def _signed_power(x: np.ndarray, p: float) -> np.ndarray:
    return np.sign(x) * np.abs(x) ** p


def mesh(sq: Superquadric, n_eta: int = 24, n_omega: int = 48) -> tuple[np.ndarray, np.ndarray]:
    """A closed, outward-facing triangle mesh of the surface (signed-power parametrisation).

    Vertices: the south pole, ``n_eta`` rings of ``n_omega`` points (latitude
    ``eta`` strictly between the poles, longitude ``omega`` over a full turn),
    the north pole: ``M = n_eta * n_omega + 2``.

    Parameters
    ----------
    sq : Superquadric
    n_eta : int
        Number of rings of latitude, >= 1.
    n_omega : int
        Points per ring, >= 3.

    Returns
    -------
    vertices : (M, 3) ndarray of float64
        World points on the surface.
    triangles : (2 * n_eta * n_omega, 3) ndarray of int32
        Vertex indices, counter-clockwise seen from outside.

    Raises
    ------
    CoreError
        If ``n_eta < 1`` or ``n_omega < 3``.

    Examples
    --------
    >>> vertices, triangles = mesh(Superquadric([1, 1, 1], [1, 1], np.eye(4)), 2, 4)
    >>> vertices.shape, triangles.shape
    ((10, 3), (16, 3))
    """
    vertices = surface_points(sq, n_eta, n_omega)
    n_eta, n_omega = int(n_eta), int(n_omega)
    ring = 1 + np.arange(n_eta)[:, None] * n_omega + np.arange(n_omega)  # (n_eta, n_omega)
    after = np.roll(ring, -1, axis=1)
    north = len(vertices) - 1
    south_fan = np.stack([np.zeros(n_omega, int), after[0], ring[0]], axis=1)
    north_fan = np.stack([np.full(n_omega, north), ring[-1], after[-1]], axis=1)
    a, b, c, d = ring[:-1], after[:-1], after[1:], ring[1:]
    quads = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
    triangles = np.concatenate([south_fan, quads, north_fan]).astype(np.int32)
    return vertices, triangles


def surface_points(sq: Superquadric, n_eta: int = 24, n_omega: int = 48) -> np.ndarray:
    """World points on the surface: the vertices of :func:`mesh`, ``(n_eta * n_omega + 2, 3)``.

    Raises
    ------
    CoreError
        If ``n_eta < 1`` or ``n_omega < 3``.

    Examples
    --------
    >>> surface_points(Superquadric([1, 1, 2], [1, 1], np.eye(4)), 3, 8).shape
    (26, 3)
    """
    if not (isinstance(n_eta, numbers.Integral) and isinstance(n_omega, numbers.Integral)
            and n_eta >= 1 and n_omega >= 3):
        raise CoreError(f"need integers n_eta >= 1 and n_omega >= 3, got {n_eta!r} and {n_omega!r}")
    n_eta, n_omega = int(n_eta), int(n_omega)
    (a1, a2, a3), (e1, e2) = sq.size, sq.shape
    eta = -np.pi / 2 + np.pi * np.arange(1, n_eta + 1) / (n_eta + 1)
    omega = -np.pi + 2 * np.pi * np.arange(n_omega) / n_omega
    ce, se = _signed_power(np.cos(eta), e1)[:, None], _signed_power(np.sin(eta), e1)[:, None]
    co, so = _signed_power(np.cos(omega), e2), _signed_power(np.sin(omega), e2)
    rings = np.stack([a1 * ce * co, a2 * ce * so, a3 * se * np.ones_like(co)], axis=-1)
    local = np.concatenate([[[0, 0, -a3]], rings.reshape(-1, 3), [[0, 0, a3]]])
    T = sq.T_world_object
    return local @ T[:3, :3].T + T[:3, 3]


@dataclass(frozen=True, eq=False)
class SuperquadricFit:
    """Result of :func:`fit_superquadric`.

    Attributes
    ----------
    superquadric : Superquadric
        The fitted superquadric, in the points' frame and units.
    residual : float
        RMS over all the points of ``sqrt(a1 a2 a3) (F^e1 - 1)``, unweighted,
        with the fitted world sizes (so it scales as the points' unit^(3/2)).
    cost : float
        Final value of the minimised objective (normalised units, mean over points).
    iterations : int
        L-BFGS-B iterations spent on the winning start (search and refinement).
    axis_order : int
        Which principal axis (0 largest spread, 2 smallest) became the object's z axis.
    """

    superquadric: Superquadric
    residual: float
    cost: float
    iterations: int
    axis_order: int


def _rotation(R0: np.ndarray, angles) -> np.ndarray:
    """R = R0 Rz(gamma) Ry(beta) Rx(alpha), angles = (alpha, beta, gamma); as in the kernel."""
    ca, sa, cb, sb, cg, sg = (f(x) for x in angles for f in (math.cos, math.sin))
    Rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    Ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    Rz = np.array([[cg, -sg, 0], [sg, cg, 0], [0, 0, 1]])
    return R0 @ Rz @ Ry @ Rx


class _Objective:
    """Cost and gradient of the 11 parameters divided by ``step_scale`` (as the optimiser
    sees them), in normalised units. ``plane``: (nx, ny, nz, d) with a unit normal, or None."""

    def __init__(self, points, R0, inside_weight, cauchy, cauchy_scale, plane, step_scale=1.0):
        self.points, self.R0, self.step_scale = points, R0, step_scale
        self.args = (float(inside_weight), bool(cauchy), float(cauchy_scale),
                     np.zeros(4) if plane is None else np.asarray(plane, dtype=np.float64),
                     0.0 if plane is None else _PLANE_WEIGHT)

    def __call__(self, y: np.ndarray) -> tuple[float, np.ndarray]:
        grad = np.empty(11)
        cost = _objective_kernel(y * self.step_scale, self.R0, self.points, *self.args, grad)
        grad *= self.step_scale
        return cost, grad


def _starts(points: np.ndarray, search: np.ndarray) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """Starts (axis order, R0, x0): each principal axis of ``points`` as the object's z axis.

    Sizes come from the spread of ``search`` along the axes (sqrt(3) std, exact
    for an ellipsoid's surface); a second start turned 45 degrees about z is
    added when the two other axes are ill-defined (nearly equal spreads), where
    a square section would otherwise fit as a diamond.
    """
    spreads, vectors = np.linalg.eigh(points.T @ points / len(points))
    spreads, vectors = spreads[::-1], vectors[:, ::-1]  # largest spread first
    turn = np.array([[1, -1, 0], [1, 1, 0], [0, 0, math.sqrt(2)]]) / math.sqrt(2)  # Rz(45 deg)
    starts = []
    for k in range(3):
        across = [i for i in range(3) if i != k]
        R0 = vectors[:, across + [k]].copy()
        if np.linalg.det(R0) < 0:
            R0[:, 0] *= -1
        frames = [R0, R0 @ turn] if spreads[across[0]] < _ROUND_RATIO * spreads[across[1]] else [R0]
        for frame in frames:
            size = np.sqrt(3 * np.mean((search @ frame) ** 2, axis=0))
            starts.append((k, frame, np.concatenate([size, _START_SHAPE, np.zeros(6)])))
    return starts


def _check_options(inside_weight, outside_loss, cauchy_scale, max_iterations, subsample) -> None:
    for name, value in (("inside_weight", inside_weight), ("cauchy_scale", cauchy_scale)):
        if not (isinstance(value, numbers.Real) and math.isfinite(value) and float(value) > 0):
            raise FitError(f"{name} must be a positive number, got {value!r}")
    if outside_loss not in ("cauchy", "squared"):
        raise FitError(f"outside_loss must be 'cauchy' or 'squared', got {outside_loss!r}")
    if not (isinstance(max_iterations, numbers.Integral) and int(max_iterations) >= 1):
        raise FitError(f"max_iterations must be a positive integer, got {max_iterations!r}")
    if subsample is not None and not (isinstance(subsample, numbers.Integral) and int(subsample) >= 11):
        raise FitError(f"subsample must be None or an integer >= 11, got {subsample!r}")


def _strided(points: np.ndarray, count: int) -> np.ndarray:
    if count >= len(points):
        return points
    return np.ascontiguousarray(points[np.linspace(0, len(points) - 1, count).round().astype(int)])


class _JaklicProblem:
    """The plain Jaklic cost of points about a start frame R0, for :class:`Descent`."""

    def __init__(self, points, R0, plane):
        self.points, self.R0 = points, R0
        self.plane = np.zeros(4) if plane is None else plane
        self.plane_weight = 0.0 if plane is None else _PLANE_WEIGHT

    def evaluate(self, x, JtJ, Jtr) -> float:
        return jaklic_normal_equations(x, self.R0, self.points, self.plane, self.plane_weight, JtJ, Jtr)

    def keep(self, accepted: bool) -> None:
        pass


class _Search:
    """The start search shared by :func:`fit_superquadric` and :func:`start_superquadrics`.

    Normalises the points (centroid at 0, RMS distance 1), and runs each start
    of :func:`_starts` for a few Levenberg-Marquardt steps of the plain Jaklic
    cost on a few points; ``tried`` holds (descent, axis order, R0), lowest
    cost first.
    """

    def __init__(self, points, support_plane, shape_bounds, subsample):
        points = _points(points, error=FitError)
        if len(points) < 11:
            raise FitError(f"need at least 11 points (one per parameter) to fit, got {len(points)}")
        if not np.all(np.isfinite(points)):
            raise FitError("points contain NaN or infinity")
        low, high = _vector(shape_bounds, 2, "shape_bounds", FitError)
        if not 0 < low <= high < 2:
            raise FitError(f"shape_bounds must satisfy 0 < low <= high < 2, got {shape_bounds!r}")
        self.points = points
        self.centroid = points.mean(axis=0)
        self.scale = math.sqrt(np.mean(np.sum((points - self.centroid) ** 2, axis=1)))
        if not self.scale > 0:
            raise FitError("all points coincide: nothing to fit")
        normalised = (points - self.centroid) / self.scale
        self.plane = None
        if support_plane is not None:
            plane = _vector(support_plane, 4, "support_plane", FitError)
            length = np.linalg.norm(plane[:3])
            if length == 0:
                raise FitError("support_plane's normal (nx, ny, nz) must not be zero")
            self.plane = np.append(plane[:3], (plane[:3] @ self.centroid + plane[3]) / self.scale) / length
        self.refine = _strided(normalised, subsample or len(points))
        search = _strided(self.refine, _SEARCH_POINTS)
        limits = np.array([_SIZE_BOUNDS] * 3 + [(low, high)] * 2
                          + [(-_TRANSLATION_BOUND, _TRANSLATION_BOUND)] * 3
                          + [(-np.pi, np.pi)] * 3)
        self.low, self.high = limits[:, 0] / _STEP_SCALE, limits[:, 1] / _STEP_SCALE
        self.tried = sorted(((Descent(_JaklicProblem(search, R0, self.plane), x0, limits[:, 0], limits[:, 1])
                              .run(_SEARCH_ITERATIONS), k, R0) for k, R0, x0 in _starts(normalised, search)),
                            key=lambda item: item[0].cost)

    def run(self, cloud, R0, y0, weights, iterations):
        objective = _Objective(cloud, R0, *weights, self.plane, _STEP_SCALE)
        # Imported here: scipy.optimize takes most of a second to import on a slow machine, and
        # only the point fit's refinement (not the default pipeline) needs it.
        from scipy.optimize import Bounds, minimize

        y0 = np.clip(y0, self.low, self.high)  # L-BFGS-B would clip silently
        return minimize(objective, y0, jac=True, method="L-BFGS-B", bounds=Bounds(self.low, self.high),
                        options={"maxiter": iterations, "ftol": _FTOL, "maxcor": _MAXCOR})

    def superquadric(self, R0, x) -> Superquadric:
        """The world superquadric of normalised parameters x about the frame R0."""
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = _rotation(R0, x[8:11]), self.centroid + self.scale * x[5:8]
        return Superquadric(x[0:3] * self.scale, x[3:5], T)


def start_superquadrics(points, *, support_plane=None, shape_bounds=(0.1, 1.9)) -> list[Superquadric]:
    """The starts that :func:`fit_superquadric` searches, each after its few search iterations.

    One per start (each principal axis of the points as the object's z axis,
    and the 45-degree turns), lowest plain Jaklic cost first: the candidates a
    fit to other evidence (the silhouettes) can choose from.

    Parameters
    ----------
    points : (N, 3) array_like of float64
        N >= 11, in any units.
    support_plane : (4,) array_like, optional
        As for :func:`fit_superquadric`.
    shape_bounds : (2,) array_like
        Bounds of both exponents.

    Returns
    -------
    list of Superquadric

    Raises
    ------
    FitError
        As :func:`fit_superquadric`.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> d = rng.normal(size=(500, 3))
    >>> starts = start_superquadrics(d / np.linalg.norm(d, axis=1, keepdims=True) * [3.0, 2.0, 1.0])
    >>> len(starts), np.sort(starts[0].size).round(1)
    (3, array([1., 2., 3.]))
    """
    search = _Search(points, support_plane, shape_bounds, None)
    return [search.superquadric(R0, descent.x) for descent, _, R0 in search.tried]


def fit_superquadric(points, *, inside_weight: float = 10.0, outside_loss: str = "cauchy",
                     cauchy_scale: float = 0.1, support_plane=None,
                     shape_bounds=(0.1, 1.9), max_iterations: int = 200,
                     subsample: int | None = None) -> SuperquadricFit:
    """Fit a superquadric to the points of a visual hull (Jaklic, Leonardis, Solina 2000).

    The residual of point i is ``r_i = sqrt(a1 a2 a3) (F_i^e1 - 1)``. Points
    inside (F < 1) cost ``inside_weight * r^2``; points outside cost ``r^2``
    (``"squared"``) or ``c^2 log(1 + r^2 / c^2)`` (``"cauchy"``, c =
    ``cauchy_scale``): a hull only bloats outward, so its inner envelope is the
    object. The objective is the mean cost over the points, computed on a copy
    of the points centred on their centroid and scaled to unit RMS distance
    from it (so ``cauchy_scale`` is in those units and the points' units do
    not matter), plus 10 times the squared depth (normalised) of the
    superquadric below ``support_plane``.

    L-BFGS-B minimises it with an analytic gradient over sizes, exponents,
    translation and orientation ``R = R0 Rz(gamma) Ry(beta) Rx(alpha)`` (R0
    the start's frame, angles from 0). Starts: each principal axis of the
    points as the object's z axis (plus a 45-degree turn about it when the
    other two spreads are nearly equal), shape (1, 1), sizes from the spreads.
    Each start takes 6 Levenberg-Marquardt steps of the plain Jaklic cost (its
    basin is wider) on at most 60 evenly strided points; the start with the lowest
    cost then converges under the requested cost on all the points (or
    ``subsample`` of them).

    Parameters
    ----------
    points : (N, 3) array_like of float64
        The points, N >= 11, in any units.
    inside_weight : float
        Weight of the squared residual of points inside the superquadric.
    outside_loss : {"cauchy", "squared"}
        Loss on the residuals of points outside.
    cauchy_scale : float
        Scale c of the Cauchy loss, in normalised units.
    support_plane : (4,) array_like, optional
        ``(nx, ny, nz, d)``: the object stands where ``n . x + d >= 0``; the
        superquadric's depth below the plane is penalised.
    shape_bounds : (2,) array_like
        Bounds of both exponents, ``0 < low <= high < 2`` (convex shapes).
    max_iterations : int
        Iteration limit of the convergence (the start search adds 6 per start).
    subsample : int, optional
        If smaller than N, refine on this many evenly strided points.

    Returns
    -------
    SuperquadricFit

    Raises
    ------
    FitError
        If ``points`` is not (N, 3), N < 11, a point is not finite, all points
        coincide, or an option is out of its range.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> d = rng.normal(size=(500, 3))
    >>> points = d / np.linalg.norm(d, axis=1, keepdims=True) * [3.0, 2.0, 1.0]
    >>> fit = fit_superquadric(points)
    >>> np.sort(fit.superquadric.size).round(2), fit.superquadric.shape.round(1)
    (array([1., 2., 3.]), array([1., 1.]))
    """
    _check_options(inside_weight, outside_loss, cauchy_scale, max_iterations, subsample)
    search = _Search(points, support_plane, shape_bounds, subsample)
    searched, axis_order, R0 = search.tried[0]
    loss = (inside_weight, outside_loss == "cauchy", cauchy_scale)
    result = search.run(search.refine, R0, searched.x / _STEP_SCALE, loss, max_iterations)
    iterations = searched.iterations + result.nit
    sq = search.superquadric(R0, result.x * _STEP_SCALE)
    F = inside_outside(search.points, sq)
    residual = math.sqrt(np.prod(sq.size)) * np.sqrt(np.mean((F ** sq.shape[0] - 1) ** 2))
    return SuperquadricFit(sq, float(residual), float(result.fun), int(iterations), axis_order)


def upright_box(points, normal) -> Superquadric:
    """The box around ``points`` standing on a plane of unit ``normal``: its z axis the normal,
    its horizontal axes the points' principal axes in the plane.

    Examples
    --------
    >>> box = upright_box([[0, 0, 0], [4, 0, 0], [4, 2, 0], [0, 2, 1]], [0.0, 0.0, 1.0])
    >>> np.sort(box.size).round(3).tolist(), box.T_world_object[:3, 2].round(3).tolist()
    ([0.5, 1.0, 2.0], [0.0, 0.0, 1.0])
    """
    points = _points(points)
    normal = _vector(normal, 3, "normal")
    side = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    basis = np.stack([side, np.cross(normal, side)], axis=1)  # (3, 2)
    flat = points @ basis
    _, vectors = np.linalg.eigh(np.cov((flat - flat.mean(axis=0)).T))
    first = basis @ vectors[:, 1]
    R = np.stack([first, np.cross(normal, first), normal], axis=1)
    local = points @ R
    low, high = local.min(axis=0), local.max(axis=0)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, R @ ((low + high) / 2)
    return Superquadric(np.maximum((high - low) / 2, 1e-9), np.array([0.1, 0.1]), T)


def resting_on(sq: Superquadric, normal) -> tuple[Superquadric, float]:
    """The superquadric turned about its centre so that its axis nearest the unit ``normal``
    lies along it (it rests on a face or a side), and the angle (degrees) it was turned by.

    Examples
    --------
    >>> T = np.eye(4); c, s = np.cos(0.2), np.sin(0.2); T[:3, :3] = [[1, 0, 0], [0, c, -s], [0, s, c]]
    >>> rested, tilt = resting_on(Superquadric([1, 2, 3], [0.5, 1.0], T), [0.0, 0.0, 1.0])
    >>> round(tilt, 2), rested.T_world_object[:3, 2].round(6).tolist(), rested.size.tolist()
    (11.46, [0.0, 0.0, 1.0], [1.0, 2.0, 3.0])
    """
    normal = _vector(normal, 3, "normal")
    R = sq.T_world_object[:3, :3]
    k = int(np.argmax(np.abs(normal @ R)))
    tilt = math.degrees(math.acos(min(1.0, abs(float(normal @ R[:, k])))))
    up = R[:, k] * np.sign(normal @ R[:, k])
    # The rotation taking up to the normal (Rodrigues), applied to the whole frame.
    axis, cosine = np.cross(up, normal), float(up @ normal)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    turn = np.eye(3) + K + K @ K / (1.0 + cosine)
    T = sq.T_world_object.copy()
    T[:3, :3] = turn @ R
    return Superquadric(sq.size, sq.shape, T), tilt
