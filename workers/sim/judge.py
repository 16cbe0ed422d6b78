"""Does a parallel-jaw grasp hold the true object (the DESIGN.md §3 "holds" test)? And how much of
the true object does a model fill (:func:`union_iou`, :func:`union_silhouette_iou`, for unions of parts)?

Written apart from the planner (core_cy.grasp) on purpose: it imports nothing
from core_cy, and computes the true object's geometry its own way, by
bisection along lines, not by closed forms. A benchmark that judged grasps
with the planner's own checks would only measure that the planner agrees
with itself.

The object is a union of superquadric parts (``truth.json``: one superquadric,
or ``{"parts": [...]}``), or, for a cup stack or a lumpy figure, the object itself
(:class:`Solid`: the simulator's own level function of it, :func:`solids_from_truth`). The gripper (DESIGN.md §3) in the grasp frame:
z approach, y closing, x = y × z; pads' centre at the origin; fingertips at
``z = pad_length/2``, palm at ``z_palm = pad_length/2 - finger_length``. Each
finger is a box ``|x| <= finger_width/2``, ``z_palm <= z <= tip``, from the
inner face ``|y| = gap/2`` to ``gap/2 + finger_thickness``. The palm, and the
gripper body behind it, is everything at ``z <= z_palm`` over the footprint
``|x| <= palm_width/2``, ``|y| <= max_opening/2 + finger_thickness``.

A grasp holds when, closing from ``max_opening``:

1. no finger corner (open) and no palm corner is below the support plane;
2. the open fingers do not cut the object (it lies between the open jaws);
3. the palm (and the body behind it) does not cut the object;
4. both fingers touch it: the object reaches between the fingers;
5. the contacts are antipodal within the friction cone (Nguyen): with
   ``c1, c2`` the contact points and ``n1, n2`` the object's outward normals
   there, ``angle(n1, c1 - c2)`` and ``angle(n2, c2 - c1)`` are both at most
   ``atan(mu)``.

The pads are a little soft: a finger's contact is the patch of the object
within ``compliance`` (default ``pad_length / 20``, 1 mm for the default
gripper) of the finger's first touch, inside the finger's reach; the contact
point is the patch's centroid and its normal the patch's mean normal. With
perfectly hard pads a face touched a hair off parallel would make a point
contact at its far corner, which no real pad does.

Geometry is sampled on a grid of lines: along y through the fingers' inner
face (the fingers' contacts and their first touch), along z through the palm's
footprint. On each line the extent of each part is found by bisection of its
inside-outside function.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["Part", "Solid", "JudgeGripper", "Verdict", "parts_from_truth", "solids_from_truth", "judge", "judge_many", "inside_union", "union_iou",
           "union_silhouette_iou"]

_GOLDEN = (math.sqrt(5) - 1) / 2
_ITERATIONS = 48  # golden section and bisection: interval / 2^48 ~ 1e-15 of its length
# Lines across the finger's inner face (x, z) and over the palm's footprint (x, y).
_FINGER_GRID = (9, 19)
_PALM_GRID = (9, 13)


@dataclass(frozen=True)
class Part:
    """One superquadric of the true object: semi-axes, exponents (e1, e2), object-to-world pose."""

    size: np.ndarray
    shape: np.ndarray
    T_world_part: np.ndarray

    @classmethod
    def from_dict(cls, d: dict) -> Part:
        return cls(np.asarray(d["size"], float).reshape(3), np.asarray(d["shape"], float).reshape(2),
                   np.asarray(d["T_world_object"], float).reshape(4, 4))


def parts_from_truth(truth: dict) -> list[Part]:
    """The parts of a ``truth.json``: a superquadric, or ``{"parts": [...]}`` (their union)."""
    if "parts" in truth:
        return [Part.from_dict(p) for p in truth["parts"]]
    return [Part.from_dict(truth)]


@dataclass(frozen=True)
class Solid:
    """A true object that is no union of superquadrics (a cup stack, a lumpy figure): its level
    function (world points (N, 3) to (N,), at most 1 exactly inside, continuous, growing outwards)
    and the world box it lies in. :func:`judge` finds its chords by sampling each line and bisecting
    the crossings, and its normals as the level's gradient."""

    level: Callable[[np.ndarray], np.ndarray]
    box_min: np.ndarray
    box_max: np.ndarray


def solids_from_truth(truth: dict) -> list[Part | Solid]:
    """What :func:`judge` holds a grasp against, of a ``truth.json``: its superquadric parts
    (:func:`parts_from_truth`), or for a ``cup-stack`` or a ``lumpy`` figure the object itself (a
    :class:`Solid`, from the simulator's own description of it)."""
    kind = truth.get("kind")
    if kind not in ("cup-stack", "lumpy"):
        return list(parts_from_truth(truth))
    from .objects import CupStack, LumpyFigure

    obj = CupStack.from_truth(truth) if kind == "cup-stack" else LumpyFigure.from_truth(truth)
    return [Solid(obj.level, np.asarray(truth["bbox_min"], float), np.asarray(truth["bbox_max"], float))]


@dataclass(frozen=True)
class JudgeGripper:
    """The gripper of DESIGN.md §3, read here independently of core_cy.grasp."""

    max_opening: float = 0.085
    finger_length: float = 0.045
    finger_width: float = 0.02
    finger_thickness: float = 0.008
    pad_length: float = 0.02
    palm_width: float = 0.06

    @classmethod
    def from_dict(cls, d: dict) -> JudgeGripper:
        return cls(**{name: float(d[name]) for name in cls.__dataclass_fields__})

    @property
    def tip(self) -> float:
        return self.pad_length / 2

    @property
    def palm(self) -> float:
        return self.pad_length / 2 - self.finger_length

    def corners(self) -> np.ndarray:
        """(20, 3) grasp-frame corners: both fingers, open, and the palm."""
        g, t, w = self.max_opening / 2, self.finger_thickness, self.finger_width / 2
        fingers = [(x, s * y, z) for x in (-w, w) for s in (-1, 1) for y in (g, g + t)
                   for z in (self.palm, self.tip)]
        p = self.palm_width / 2
        palm = [(x, y, self.palm) for x in (-p, p) for y in (-(g + t), g + t)]
        return np.array(fingers + palm)


@dataclass(frozen=True)
class Verdict:
    """``holds``; else ``reason`` names the first test failed. ``width``: gap at closure, or NaN."""

    holds: bool
    reason: str
    width: float


def _gauge(q: np.ndarray, shape: np.ndarray) -> np.ndarray:
    """F^(e1/2) of points q (..., 3) already divided by the sizes: convex, degree 1."""
    e1, e2 = shape
    a = np.abs(q)
    xy = a[..., 0] ** (2 / e2) + a[..., 1] ** (2 / e2)
    return (xy ** (e2 / e1) + a[..., 2] ** (2 / e1)) ** (e1 / 2)


def _normal(q: np.ndarray, part: Part | Solid) -> np.ndarray:
    """World unit outward normals at points q (N, 3) given in the part's scaled frame (a
    :class:`Solid`'s: in the world, as its chords give them)."""
    if isinstance(part, Solid):
        return _solid_normal(q, part)
    e1, e2 = part.shape
    a = np.abs(q)
    xy = a[:, 0] ** (2 / e2) + a[:, 1] ** (2 / e2)
    with np.errstate(divide="ignore", invalid="ignore"):
        common = np.where(xy > 0, xy ** (e2 / e1 - 1), 0.0)
        g = np.stack([common * a[:, 0] ** (2 / e2 - 1), common * a[:, 1] ** (2 / e2 - 1),
                      a[:, 2] ** (2 / e1 - 1)], axis=1)
    g = np.nan_to_num(g) * np.sign(q) / part.size
    n = g @ part.T_world_part[:3, :3].T
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _chords(origins: np.ndarray, direction: np.ndarray, part: Part | Solid):
    """Where lines ``origins + t * direction`` (N lines, one direction each) enter and leave a part.

    Returns t_in, t_out (N,) with NaN where a line misses, and q0, v: the line's point at t is
    ``q0 + t v``, in the part's scaled frame (a :class:`Solid`'s: the world). The gauge is convex
    along a line: its minimum by golden section, then each crossing of 1 by bisection.
    """
    if isinstance(part, Solid):
        return _solid_chords(origins, direction, part)
    R, t = part.T_world_part[:3, :3], part.T_world_part[:3, 3]
    q0 = (origins - t) @ R / part.size
    v = (direction @ R) / part.size
    vv = np.einsum("ij,ij->i", v, v)
    centre_t = -np.einsum("ij,ij->i", q0, v) / vv
    # The part lies inside |q| <= sqrt(3) (the unit cube's corners): search only there.
    closest = q0 + centre_t[:, None] * v
    reach2 = (3.0 - np.einsum("ij,ij->i", closest, closest)) / vv
    n = len(origins)
    t_in, t_out = np.full(n, np.nan), np.full(n, np.nan)
    hit = reach2 > 0
    if not hit.any():
        return t_in, t_out, q0, v
    q0h, vh, ch = q0[hit], v[hit], centre_t[hit]
    reach = np.sqrt(reach2[hit])
    lo, hi = ch - reach, ch + reach

    def gauge(tt):
        return _gauge(q0h + tt[:, None] * vh, part.shape)

    a, b = lo.copy(), hi.copy()
    for _ in range(_ITERATIONS):
        c1, c2 = b - _GOLDEN * (b - a), a + _GOLDEN * (b - a)
        left = gauge(c1) < gauge(c2)
        b = np.where(left, c2, b)
        a = np.where(left, a, c1)
    t_min = (a + b) / 2
    inside = gauge(t_min) < 1.0

    def crossing(outer, inner):
        o, i = outer.copy(), inner.copy()
        for _ in range(_ITERATIONS):
            m = (o + i) / 2
            is_inside = gauge(m) < 1.0
            i = np.where(is_inside, m, i)
            o = np.where(is_inside, o, m)
        return (o + i) / 2

    enter, leave = crossing(lo, t_min), crossing(hi, t_min)
    index = np.flatnonzero(hit)[inside]
    t_in[index], t_out[index] = enter[inside], leave[inside]
    return t_in, t_out, q0, v


#: Samples along a line through a :class:`Solid`'s box: a piece of it thinner than the box's
#: diagonal over this many is missed.
_SOLID_SAMPLES = 257
#: The step (metres) of a :class:`Solid`'s level's central differences.
_NORMAL_STEP = 1e-5


def _solid_chords(origins: np.ndarray, direction: np.ndarray, solid: Solid):
    """A :class:`Solid`'s chords: from the first point of each line inside it to the last one (what
    lies between the two, for an object that is not convex, counts as the object)."""
    o, d = np.asarray(origins, float), np.asarray(direction, float)
    n = len(o)
    t_in, t_out = np.full(n, np.nan), np.full(n, np.nan)
    # The stretch of each line inside the box (slabs), the box grown by a hair for what touches it.
    lo_box, hi_box = solid.box_min - 1e-6, solid.box_max + 1e-6
    within = (o >= lo_box) & (o <= hi_box)
    with np.errstate(divide="ignore", invalid="ignore"):
        safe = np.where(d == 0, 1.0, d)
        t1, t2 = (lo_box - o) / safe, (hi_box - o) / safe
    near = np.where(d == 0, np.where(within, -np.inf, np.inf), np.minimum(t1, t2)).max(axis=1)
    far = np.where(d == 0, np.where(within, np.inf, -np.inf), np.maximum(t1, t2)).min(axis=1)
    crossing = np.flatnonzero(near < far)
    if not len(crossing):
        return t_in, t_out, o, d
    ts = near[crossing, None] + (far - near)[crossing, None] * np.linspace(0.0, 1.0, _SOLID_SAMPLES)
    oc, dc = o[crossing], d[crossing]

    def inside(rows: np.ndarray, t: np.ndarray) -> np.ndarray:
        return solid.level(oc[rows] + t[:, None] * dc[rows]) <= 1.0

    rows = np.repeat(np.arange(len(crossing)), _SOLID_SAMPLES)
    found = inside(rows, ts.ravel()).reshape(ts.shape)
    hit = np.flatnonzero(found.any(axis=1))
    if not len(hit):
        return t_in, t_out, o, d
    first = found[hit].argmax(axis=1)
    last = _SOLID_SAMPLES - 1 - found[hit][:, ::-1].argmax(axis=1)

    def crossing_at(inner_index: np.ndarray, step: int) -> np.ndarray:
        inner = ts[hit, inner_index]
        outer = ts[hit, np.clip(inner_index + step, 0, _SOLID_SAMPLES - 1)]
        for _ in range(_ITERATIONS):
            middle = (inner + outer) / 2
            is_inside = inside(hit, middle)
            inner, outer = np.where(is_inside, middle, inner), np.where(is_inside, outer, middle)
        return (inner + outer) / 2

    t_in[crossing[hit]], t_out[crossing[hit]] = crossing_at(first, -1), crossing_at(last, 1)
    return t_in, t_out, o, d


def _solid_normal(points: np.ndarray, solid: Solid) -> np.ndarray:
    """World unit outward normals of a :class:`Solid` at world points (N, 3): its level's gradient."""
    points = np.asarray(points, float).reshape(-1, 3)
    gradient = np.empty_like(points)
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = _NORMAL_STEP
        gradient[:, axis] = solid.level(points + step) - solid.level(points - step)
    length = np.linalg.norm(gradient, axis=1, keepdims=True)
    return gradient / np.where(length > 0, length, 1.0)


def _grid(lo: float, hi: float, n: int) -> np.ndarray:
    return np.linspace(lo, hi, n)


def judge(T_world_grasp, parts: list[Part] | list[Part | Solid], gripper: JudgeGripper, support_plane=None, *,
          mu: float = 0.5, compliance: float | None = None, contacts: str = "patch") -> Verdict:
    """Judge one grasp against the true object; see the module docstring for the test.

    Parameters
    ----------
    T_world_grasp : (4, 4) array_like, grasp-to-world.
    parts : list of Part, the true object (their union); or of Solid (``solids_from_truth``).
    gripper : JudgeGripper
    support_plane : (4,) array_like or None, ``n . x + d >= 0`` is free space.
    mu : float, friction coefficient.
    compliance : float or None, how far the pads give (default ``pad_length / 20``).
    contacts : "patch" (the module docstring's test) or "centre-line": the other common
        reading, where the contacts are where the line through the pads' centres (the
        grasp's y axis) meets the object, as in Dex-Net; tests 1-4 are the same.
    """
    T = np.asarray(T_world_grasp, float)
    R, o = T[:3, :3], T[:3, 3]
    g = gripper
    delta = g.pad_length / 20 if compliance is None else compliance
    half_open = g.max_opening / 2
    outer = half_open + g.finger_thickness

    # 1. The support plane, against the open fingers' and the palm's corners.
    if support_plane is not None:
        plane = np.asarray(support_plane, float)
        plane = plane / np.linalg.norm(plane[:3])
        corners = g.corners() @ R.T + o
        if np.min(corners @ plane[:3] + plane[3]) < 0:
            return Verdict(False, "a finger or palm corner is below the support plane", math.nan)

    # 2, 4, 5. Lines along y through the fingers' inner face.
    xs = _grid(-g.finger_width / 2, g.finger_width / 2, _FINGER_GRID[0])
    zs = _grid(g.palm, g.tip, _FINGER_GRID[1])
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    local = np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], axis=1)
    origins = local @ R.T + o
    y_axis = R[:, 1]
    n_lines = len(origins)
    top = np.full(n_lines, -np.inf)  # highest y of the object between the jaws, per line
    bottom = np.full(n_lines, np.inf)
    top_part = np.full(n_lines, -1)
    bottom_part = np.full(n_lines, -1)
    top_q, bottom_q = np.zeros((n_lines, 3)), np.zeros((n_lines, 3))
    for k, part in enumerate(parts):
        t_in, t_out, q0, v = _chords(origins, np.broadcast_to(y_axis, origins.shape), part)
        hit = ~np.isnan(t_in)
        # Any piece of the object inside the open fingers' slabs: the fingers cut it.
        cuts = hit & (((t_out >= half_open) & (t_in <= outer)) | ((t_in <= -half_open) & (t_out >= -outer)))
        if cuts.any():
            return Verdict(False, "an open finger cuts the object", math.nan)
        between = hit & (t_in > -half_open) & (t_out < half_open)
        higher = between & (t_out > top)
        top[higher], top_part[higher] = t_out[higher], k
        top_q[higher] = q0[higher] + t_out[higher, None] * v[higher]
        lower = between & (t_in < bottom)
        bottom[lower], bottom_part[lower] = t_in[lower], k
        bottom_q[lower] = q0[lower] + t_in[lower, None] * v[lower]

    # 3. Lines along z over the palm's footprint: nothing of the object at or behind the palm.
    px = _grid(-g.palm_width / 2, g.palm_width / 2, _PALM_GRID[0])
    py = _grid(-outer, outer, _PALM_GRID[1])
    PX, PY = np.meshgrid(px, py, indexing="ij")
    palm_local = np.stack([PX.ravel(), PY.ravel(), np.full(PX.size, g.palm)], axis=1)
    palm_origins = palm_local @ R.T + o
    for part in parts:
        t_in, _, _, _ = _chords(palm_origins, np.broadcast_to(R[:, 2], palm_origins.shape), part)
        if np.any(t_in <= 0):  # t is measured from the palm along +z: entering at or behind it
            return Verdict(False, "the palm cuts the object", math.nan)

    touched = np.isfinite(top)
    if not touched.any():
        return Verdict(False, "the fingers close on nothing", math.nan)
    y_top, y_bottom = top[touched].max(), bottom[touched].min()
    width = float(y_top - y_bottom)

    # 5. Contact patches, their centroids and mean normals; Nguyen's antipodal test.
    def contact(values, extreme, sign, part_of, q):
        patch = np.flatnonzero(touched & (sign * (values - extreme) >= -delta))
        normals = np.empty((len(patch), 3))
        for k, part in enumerate(parts):
            mine = part_of[patch] == k
            if mine.any():
                normals[mine] = _normal(q[patch[mine]], part)
        normal = normals.mean(axis=0)
        points = origins[patch] + values[patch, None] * y_axis
        return points.mean(axis=0), normal / np.linalg.norm(normal)

    if contacts == "centre-line":
        found = _centre_line_contacts(o, y_axis, parts, half_open)
        if found is None:
            return Verdict(False, "the pads' centre line misses the object", width)
        c1, n1, c2, n2 = found
    else:
        c1, n1 = contact(top, y_top, 1.0, top_part, top_q)
        c2, n2 = contact(bottom, y_bottom, -1.0, bottom_part, bottom_q)
    line = c1 - c2
    length = np.linalg.norm(line)
    if length == 0:
        return Verdict(False, "the fingers close on nothing", math.nan)
    line /= length
    cone = math.atan(mu)
    angle1 = math.acos(float(np.clip(n1 @ line, -1, 1)))
    angle2 = math.acos(float(np.clip(-n2 @ line, -1, 1)))
    if max(angle1, angle2) > cone:
        return Verdict(False, f"contacts not antipodal ({math.degrees(max(angle1, angle2)):.0f} degrees "
                              f"off, friction cone {math.degrees(cone):.0f})", width)
    return Verdict(True, "holds", width)


def _centre_line_contacts(origin, y_axis, parts, half_open: float):
    """Where the line through the pads' centres enters and leaves the object between the jaws:
    (c1, n1, c2, n2) on the +y and -y sides, or None if it misses."""
    top, bottom = None, None  # (t, scaled point, part) where the line leaves (+y) and enters (-y)
    for part in parts:
        t_in, t_out, q0, v = _chords(origin[None, :], y_axis[None, :], part)
        if np.isnan(t_in[0]) or t_in[0] <= -half_open or t_out[0] >= half_open:
            continue
        if top is None or t_out[0] > top[0]:
            top = (t_out[0], q0 + t_out[0] * v, part)
        if bottom is None or t_in[0] < bottom[0]:
            bottom = (t_in[0], q0 + t_in[0] * v, part)
    if top is None:
        return None
    return (origin + top[0] * y_axis, _normal(top[1], top[2])[0],
            origin + bottom[0] * y_axis, _normal(bottom[1], bottom[2])[0])


def judge_many(grasps, parts: list[Part], gripper: JudgeGripper, support_plane=None, **kwargs) -> list[Verdict]:
    """:func:`judge` for each (4, 4) pose of ``grasps``."""
    return [judge(T, parts, gripper, support_plane, **kwargs) for T in grasps]


def _box_of(parts: list[Part]) -> tuple[np.ndarray, np.ndarray]:
    """World axis-aligned box around the parts: each lies in its own box |q_k| <= a_k."""
    corners = np.array([(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    points = np.vstack([(corners * p.size) @ p.T_world_part[:3, :3].T + p.T_world_part[:3, 3] for p in parts])
    return points.min(axis=0), points.max(axis=0)


def inside_union(points: np.ndarray, parts: list[Part]) -> np.ndarray:
    """(N,) bool: which world points (N, 3) lie in at least one part."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    out = np.zeros(len(points), dtype=bool)
    for part in parts:
        R, t = part.T_world_part[:3, :3], part.T_world_part[:3, 3]
        with np.errstate(over="ignore"):
            out |= _gauge((points - t) @ R / part.size, part.shape) <= 1.0
    return out


def union_iou(model: list[Part], truth: list[Part], n: int = 200_000, seed: int = 0) -> float:
    """Volumetric IoU of two unions of superquadrics (a model and the true object), Monte Carlo.

    Samples are uniform in the box around both; each side's inside test is its parts' own
    gauge (nothing of the fit's code). The standard error is about ``sqrt(IoU (1 - IoU) / n')``,
    ``n'`` the samples that fall in the union of both.

    Examples
    --------
    >>> cube = Part(np.ones(3), np.array([0.1, 0.1]), np.eye(4))
    >>> half = Part(np.array([0.5, 1.0, 1.0]), np.array([0.1, 0.1]), np.eye(4))
    >>> round(union_iou([half], [cube], n=20000), 1)
    0.5
    """
    lo_a, hi_a = _box_of(model)
    lo_b, hi_b = _box_of(truth)
    lo, hi = np.minimum(lo_a, lo_b), np.maximum(hi_a, hi_b)
    samples = np.random.default_rng(seed).uniform(lo, hi, size=(int(n), 3))
    in_model, in_truth = inside_union(samples, model), inside_union(samples, truth)
    union = int(np.count_nonzero(in_model | in_truth))
    return int(np.count_nonzero(in_model & in_truth)) / union if union else 0.0


def surface_points(part: Part, n_eta: int = 24, n_omega: int = 48) -> np.ndarray:
    """World points on the part's surface, spread by its own signed-power parametrisation."""
    e1, e2 = part.shape
    eta = np.linspace(-np.pi / 2, np.pi / 2, n_eta)[:, None]
    omega = np.linspace(-np.pi, np.pi, n_omega, endpoint=False)[None, :]

    def power(x, p):
        return np.sign(x) * np.abs(x) ** p

    ce, se = power(np.cos(eta), e1), power(np.sin(eta), e1)
    q = np.stack([np.broadcast_to(ce * power(np.cos(omega), e2), (n_eta, n_omega)),
                  np.broadcast_to(ce * power(np.sin(omega), e2), (n_eta, n_omega)),
                  np.broadcast_to(se, (n_eta, n_omega))], axis=-1).reshape(-1, 3) * part.size
    return q @ part.T_world_part[:3, :3].T + part.T_world_part[:3, 3]


def union_silhouette_iou(parts: list[Part], K: np.ndarray, T_world_cam: np.ndarray, silhouette: np.ndarray) -> float:
    """IoU of a silhouette (H, W; nonzero = object) and the union of the parts' projections.

    Each part is convex, so its projection is the convex hull of its projected surface points;
    an ideal pinhole camera (K, camera-to-world pose, OpenCV axes) projects them. A part reaching
    behind the camera covers nothing.
    """
    import cv2

    height, width = silhouette.shape
    covered = np.zeros((height, width), np.uint8)
    R, c = np.asarray(T_world_cam, float)[:3, :3], np.asarray(T_world_cam, float)[:3, 3]
    for part in parts:
        cam = (surface_points(part) - c) @ R
        if np.any(cam[:, 2] <= 0):
            continue
        uv = (cam @ np.asarray(K, float).T)[:, :2] / cam[:, 2:3]
        limit = 4.0 * max(height, width)
        hull = cv2.convexHull(np.clip(uv, -limit, limit).astype(np.float32)).reshape(-1, 2)
        cv2.fillConvexPoly(covered, np.round(hull * 16).astype(np.int32), 1, shift=4)
    seen = silhouette != 0
    union = int(np.count_nonzero(seen | (covered != 0)))
    return int(np.count_nonzero(seen & (covered != 0))) / union if union else 0.0
