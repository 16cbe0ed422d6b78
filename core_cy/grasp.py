"""Parallel-jaw grasps from a superquadric, ranked by how likely they are to hold (DESIGN.md §1.9).

The gripper and the grasp frame are in :mod:`core_cy.gripper`. Planning, for a
superquadric (sizes, exponents, pose) on a support plane:

1. **Candidates.** Frames of the object: its own axes and, around an axis
   whose cross-section is round, that frame turned in 30-degree steps from the
   one whose approach comes straight from above. A fit within 25 degrees of
   upright is set upright first: an object at rest on a plane has a principal
   axis along its normal, so the fit's tilt is its error (a fit tilted more,
   as a single superquadric of an L may be, is tried both ways). In each frame the jaws
   close along one axis and approach along another, from either side (not
   from below the plane); in the object's own frame they also slide along the
   third axis, halfway and all the way to either end. Each is tried at four
   depths: the pads' centre just inside the object, the deepest the palm and
   the plane allow, halfway between, and on the model's widest section.
   Where the superquadric misses more than 15 % of the silhouettes (it
   describes the object poorly: an L), the same is planned on the hull's
   upright box too (its horizontal axes the hull's principal ones), and the two
   lists are merged by score: the box bounds all the views saw, and the hull
   checks below keep its grasps where the hull has the surface it claims.
2. **Nominal checks**, in closed form (the jaws are aligned with the model's
   axes, so the widest chord the fingers meet and the normal there follow from
   the inside-outside function): the object fits the open jaws, the palm stays
   clear, the pads' centre line meets the object, the contact normals lie
   within the friction cone (held 3 degrees inside it, for what a fit rounder
   than the object hides), and no finger or palm corner comes within a
   clearance of the support plane. With the carved hull's points: the palm
   also stays clear of the hull (which holds the whole object, also what the
   superquadric leaves out, like a mug's handle), the hull reaches past the
   pads' centre between the fingers, and no hull point the model leaves
   unexplained lies where an open finger goes.
3. **Robustness.** The best candidates are checked again on the model moved by
   its own error, drawn 24 times (fixed draws, so planning is repeatable):
   semi-axes (half an error shorter on average: a hull errs outward, and so
   mostly do fits of it) and centre by the length error, the orientation by the angle
   error (mostly about the vertical for an upright frame), the exponents
   rounder or boxier. The errors come from the fit's evidence, its residual
   and how well it covers the silhouettes (:func:`model_error`). Each draw is
   checked on a grid of surface points facing the fingers (kernel in Cython):
   open jaws, palm, reach, and the contacts (the patches within
   ``pad_length/20`` of each finger's first touch: the pads give a little)
   antipodal within the friction cone. ``score`` is the share of draws that
   hold (smoothed over a quarter of a standard error), times the chance that
   the hull bears the model out under the pads (its extent along the closing
   axis there is the model's, within two length errors and the hull's typical
   bulge; a handle under a pad moves the contact off the checked one): an
   estimate of the chance that the grasp holds, on the cautious side.

With the hull's points, the length error comes from their typical (median)
distance from the model where that is below the fit's RMS ``residual``: what
the model leaves out (a handle, a ball on a box) is the hull checks' concern,
not an error of the model, and counting it would leave no grasp on the part
the model does describe.

Grasps scoring below ``min_score`` (0.05) are left out; an object no
candidate fits nominally (too big, say) gives an empty list, never a guess.
Among grasps within 0.05 in score, one from above comes first, then one with
more room in the jaws.
"""

from __future__ import annotations

import functools
import math
import numbers

import numpy as np
from scipy.special import ndtr

from ._grasp_cy import hull_reach as _hull_reach
from ._grasp_cy import in_finger_path as _in_finger_path
from ._grasp_cy import in_open_fingers as _in_open_fingers
from ._grasp_cy import nominal_margins as _nominal_margins
from ._grasp_cy import pad_extent as _pad_extent
from ._grasp_cy import perturbed_margins as _perturbed_margins
from ._grasp_cy import surface_samples as _surface_samples
from .errors import CoreError
from .gripper import DEFAULT_GRIPPER, Grasp, Gripper, grasps_to_json
from .superquadric import Superquadric, inside_outside, surface_points, upright_box

__all__ = ["Gripper", "Grasp", "DEFAULT_GRIPPER", "plan_grasps", "grasps_to_json", "model_error"]

# Clearances, as fractions of the finger length: of every gripper corner from the
# support plane, and (nominally) of the palm from the object.
_TABLE_CLEARANCE = 0.05
_PALM_CLEARANCE = 0.05
_COMPLIANCE = 1 / 20  # of the pad length: how far the pads give
# A cross-section is round when its two sizes differ by less than this fraction
# and its exponent is within this of 1.
_ROUND_SIZE, _ROUND_SHAPE = 0.08, 0.3
_RING_STEP = math.radians(30)
_SNAP = math.radians(25)  # a frame this near upright is set upright
_TILT_ERROR = math.radians(1.0)  # of an upright frame about the horizontal
_ROBUST_KEEP = 16  # candidates (with their depth) checked under perturbation
_ERROR_DRAWS = 24  # draws of the model's error per candidate
_MIN_SCORE = 0.05
# A superquadric missing more than this share of the silhouettes describes the object poorly
# (an L, say): the hull's upright box is planned on too.
_POOR_COVER = 0.15
_SCORE_STEP = 0.05  # scores closer than this rank as equal
_HULL_POINTS = 400  # at most this many hull points are checked
# Surface points of each other part of a union that no finger or palm may meet: their spacing
# (a tenth of a turn) is below a finger's thickness on parts of a graspable size.
_OBSTACLE_GRID = (12, 32)
_SLIDES = (0.5, -0.5, 1.0, -1.0)  # of the way from the model's middle to its end
# The exponents' error: rounder, and boxier (fits of boxes come out rounder than they are).
_SHAPE_ERROR = (0.2, -0.3)
_SHAPE_LIMITS = (0.1, 1.9)
_CONE_MARGIN = math.radians(3.0)
_SIZE_BIAS = 0.5  # standard errors by which a fitted semi-axis is likely too long
# Sample grid of the surface facing each finger: across the finger, along the approach.
_SAMPLES = (5, 7)
_ACROSS, _ALONG = np.linspace(-1, 1, _SAMPLES[0]), np.linspace(0, 1, _SAMPLES[1])
_APPROACH_ORDER = ("top", "side", "tilted")
_EYE, _X, _Y = np.eye(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
# (closing axis, approach axis, approach sign) of a frame's candidates.
_COMBOS = np.array([(i, j, s) for i in range(3) for j in range(3) if j != i for s in (1, -1)])


def model_error(superquadric: Superquadric, residual: float = 0.0, silhouette_iou=None) -> tuple[float, float]:
    """Standard errors (length, radians) of a fitted superquadric, from its own evidence.

    The length error grows with the fit's ``residual`` (RMS distance of the
    hull's points from the surface) and with the share of the silhouettes it
    fails to cover (``1 - mean IoU``, times the mean semi-axis); it is at
    least 2 % of the mean semi-axis. The angle error grows with the uncovered
    share, from 2 degrees. The factors were set on simulated three-view scans
    so that 90 % of the actual errors of sizes, centre and axes lie within
    1.64 standard errors.

    Examples
    --------
    >>> sq = Superquadric([0.02, 0.03, 0.04], [1.0, 1.0], np.eye(4))
    >>> [round(v, 4) for v in model_error(sq, 0.002, [0.95, 0.95, 0.95])]
    [0.002, 0.0949]
    """
    mean_size = float(np.sum(superquadric.size) / 3)
    miss = _miss(silhouette_iou)
    miss = min(max(miss, 0.0), 1.0)
    length = max(0.65 * residual, 1.3 * miss * mean_size, 0.02 * mean_size)
    angle = math.radians(2.0) + 1.2 * miss
    return length, angle


def _miss(silhouette_iou) -> float:
    """The share of the silhouettes the model misses: 1 - their mean IoU (0 without any)."""
    if silhouette_iou is None or len(silhouette_iou) == 0:
        return 0.0
    iou = np.asarray(silhouette_iou, dtype=np.float64)
    return 1.0 - float(iou.sum() / iou.size)


def _cone(gripper: Gripper) -> float:
    """The friction cone's half angle the planner holds contacts to: ``_CONE_MARGIN`` inside
    the gripper's, for what the sampled model cannot show (a face flatter than fitted)."""
    return math.atan(gripper.friction) - _CONE_MARGIN


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products along the last axis (np.cross costs more than the product here)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _norm(v: np.ndarray) -> float:
    """Length of a vector (np.linalg.norm's value, without its overhead)."""
    return math.sqrt(v @ v)


def _level_axes(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit axes perpendicular to the unit ``normal``, and to each other (right-handed with it)."""
    side = _cross(normal, _X if abs(normal[0]) < 0.9 else _Y)
    side /= _norm(side)
    return side, _cross(normal, side)


def _rotation(axis: np.ndarray, angle):
    """Rodrigues: rotations (..., 3, 3) by ``angle`` (a number, or an array of them) about the unit ``axis``."""
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    sine, versine = np.sin(angle)[..., None, None], (1 - np.cos(angle))[..., None, None]
    return _EYE + sine * K + (versine * K) @ K


def _turned(frame: np.ndarray, current: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The frame turned by the smallest rotation taking unit vector ``current`` to ``target``."""
    turn_axis = _cross(current, target)
    sine = _norm(turn_axis)
    if sine < 1e-12:
        return frame
    return _rotation(turn_axis / sine, math.atan2(sine, current @ target)) @ frame


def _upright(frame: np.ndarray, down: np.ndarray, round_axis: int | None) -> tuple[np.ndarray, bool]:
    """The frame turned so that one of its axes is vertical, if the fit is within 25 degrees of it.

    An object at rest on a plane rests with a principal axis along the plane's
    normal (its stable poses), so the fit's tilt is its error. Around a round
    axis any direction is principal: that axis, if nearly level, is made level.
    """
    cosines = frame.T @ down
    axis = int(np.argmax(np.abs(cosines)))
    if abs(cosines[axis]) >= math.cos(_SNAP):
        return _turned(frame, frame[:, axis] * np.sign(cosines[axis]), down), True
    if round_axis is not None and abs(cosines[round_axis]) <= math.sin(_SNAP):
        level = frame[:, round_axis] - cosines[round_axis] * down
        return _turned(frame, frame[:, round_axis], level / _norm(level)), True
    return frame, False


def _frames(sq: Superquadric, down: np.ndarray | None):
    """Object frames to grasp in: F (n, 3, 3) world axes as columns, sizes (n, 3), shape (n, 2),
    upright (n,) bool, and own (n,) bool: along the object's own axes (not turned about one).

    Frame axis 2 is the superquadric's z (the e1 axis). Around a round axis, the
    frame turns in steps from the one whose approach axis points most nearly down.
    With a support plane, the object's frame is first set upright (:func:`_upright`).
    """
    R, a, e = sq.T_world_object[:3, :3], sq.size, sq.shape

    def close(u, v):
        return abs(u - v) <= _ROUND_SIZE * max(u, v)

    ellipsoid = abs(e[0] - 1) <= _ROUND_SHAPE and abs(e[1] - 1) <= _ROUND_SHAPE
    rings = []
    if close(a[0], a[1]) and abs(e[1] - 1) <= _ROUND_SHAPE:
        rings.append((2, 0, 1))
    if ellipsoid and close(a[1], a[2]):
        rings.append((0, 1, 2))
    if ellipsoid and close(a[0], a[2]):
        rings.append((1, 2, 0))
    if len(rings) > 1 and down is not None:  # a ball: turning about the vertical axis suffices
        rings = [max(rings, key=lambda ring: abs(R[:, ring[0]] @ down))]
    upright = False
    if down is not None:
        R, upright = _upright(R, down, rings[0][0] if len(rings) == 1 else None)
    frames, sizes, shapes = [R], [a], [e]
    for axis, u, v in rings:
        mean = (a[u] + a[v]) / 2
        ring_size = a.copy()
        ring_size[u] = ring_size[v] = mean
        ring_shape = np.array([e[0], 1.0]) if axis == 2 else np.array([1.0, 1.0])
        start = 0.0
        if down is not None:
            along = down - (down @ R[:, axis]) * R[:, axis]
            if _norm(along) > 0.1:
                start = math.atan2(along @ R[:, v], along @ R[:, u])
        steps = round(math.pi / _RING_STEP)
        frames.extend(_rotation(R[:, axis], start + np.arange(steps) * _RING_STEP) @ R)
        sizes.extend([ring_size] * steps)
        shapes.extend([ring_shape] * steps)
    own = [0]  # frames along the object's own axes, where the jaws also slide
    if down is not None and not upright:
        # Fitted more than 25 degrees off upright: an object at rest rarely is, but a single
        # superquadric of a non-convex one (an L) often is. Try the frame set upright too.
        axis = int(np.argmax(np.abs(R.T @ down)))
        own.append(len(frames))
        frames.append(_turned(R, R[:, axis] * np.sign(R[:, axis] @ down), down))
        sizes.append(a)
        shapes.append(e)
    slides = np.zeros(len(frames), bool)
    slides[own] = True
    return np.array(frames), np.array(sizes), np.array(shapes), np.full(len(frames), upright), slides


@functools.lru_cache(maxsize=8)
def _corners(gripper: Gripper) -> np.ndarray:
    """The gripper's corners as columns (3, 20) (:meth:`Gripper.corners`), made once per gripper."""
    corners = np.ascontiguousarray(gripper.corners().T)
    corners.setflags(write=False)
    return corners


def _check_plane(support_plane) -> np.ndarray | None:
    if support_plane is None:
        return None
    try:
        plane = np.asarray(support_plane, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CoreError(f"support_plane must be 4 finite numbers, got {support_plane!r}") from exc
    if plane.shape != (4,) or not np.all(np.isfinite(plane)):
        raise CoreError(f"support_plane must be 4 finite numbers [nx, ny, nz, d], got shape {plane.shape}")
    length = np.linalg.norm(plane[:3])
    if length == 0:
        raise CoreError("support_plane's normal (nx, ny, nz) must not be zero")
    return plane / length


def _take(c: dict[str, np.ndarray], index) -> dict[str, np.ndarray]:
    return {key: value[index] for key, value in c.items()}


def _candidates(sq: Superquadric, plane: np.ndarray | None, gripper: Gripper) -> dict[str, np.ndarray]:
    """Every (frame, closing axis i, approach axis j, approach sign, slide ``dx``) not
    approaching from below."""
    F, sizes, shapes, upright, own = _frames(sq, None if plane is None else -plane[:3])
    f = np.repeat(np.arange(len(F)), len(_COMBOS))
    i, j, s = np.tile(_COMBOS, (len(F), 1)).T
    y = F[f, :, i]
    z = s[:, None] * F[f, :, j]
    if plane is not None:
        keep = np.flatnonzero(z @ plane[:3] <= 0.1)
        f, i, j, s, y, z = f[keep], i[keep], j[keep], s[keep], y[keep], z[keep]
    k = 3 - i - j
    # In the object's own frame, also slide along the grasp's x axis (to take one end of a long
    # object, say, clear of what the model leaves out): halfway and all the way to either end.
    reach = np.maximum(0.0, sizes[f, k] - gripper.finger_width / 2)
    sliding = np.flatnonzero(own[f] & (reach > 0.1 * sizes[f].max(axis=1)))
    pose = np.concatenate([np.arange(len(f))] + [sliding] * len(_SLIDES))
    dx = np.concatenate([np.zeros(len(f))] + [fraction * reach[sliding] for fraction in _SLIDES])
    R_grasp = np.stack([_cross(y, z), y, z], axis=2)
    f = f[pose]
    return {"F": F[f], "sizes": sizes[f], "shape": shapes[f], "i": i[pose], "j": j[pose], "k": k[pose],
            "s": s[pose], "R": R_grasp[pose], "upright": upright[f], "dx": dx, "pose": pose}


def _radial(points: np.ndarray, sq: Superquadric) -> np.ndarray:
    """Signed radial distance (N,) of points (N, 3) from the model's surface, outside positive."""
    F = inside_outside(points, sq)
    return np.linalg.norm(points - sq.T_world_object[:3, 3], axis=1) * (1 - np.minimum(F, 1e300) ** (-sq.shape[0] / 2))


def _hull(c, points: np.ndarray | None, radial: np.ndarray | None, sq: Superquadric, gripper: Gripper,
          length: float):
    """The hull's evidence for each candidate.

    Returns, along the approach from the model's centre, the nearest hull point towards
    the palm within the palm's footprint, and within the column between the fingers (n,)
    each (``+inf`` with no points, ``-inf`` for the column without points); and the hull
    points the model leaves unexplained (``radial``, their distances outside it, above two
    length errors), less the model's centre, shape (U, 3).
    """
    n = len(c["i"])
    if points is None or radial is None or len(points) == 0:
        return np.full(n, np.inf), np.full(n, -np.inf), np.zeros((0, 3))
    offsets = points - sq.T_world_object[:3, 3]
    nearest, column = np.empty(n), np.empty(n)
    # Slides of one pose share its axes: the kernel turns the points once for them.
    _hull_reach(offsets, c["R"], c["dx"], np.argsort(c["pose"], kind="stable"), gripper.palm_width / 2,
                gripper.max_opening / 2 + gripper.finger_thickness, gripper.finger_width / 2, gripper.max_opening / 2,
                np.empty_like(offsets), nearest, column)
    return nearest, column, offsets[radial > 2 * length]


def _palm_reach(c, obstacles: np.ndarray, sq: Superquadric, gripper: Gripper) -> np.ndarray:
    """The nearest point of the other parts within the palm's footprint along each candidate's
    approach (n,), as :func:`_hull`'s nearest (+inf with none)."""
    n = len(c["i"])
    offsets = np.ascontiguousarray(obstacles - sq.T_world_object[:3, 3])
    nearest, column = np.empty(n), np.empty(n)
    _hull_reach(offsets, c["R"], c["dx"], np.argsort(c["pose"], kind="stable"), gripper.palm_width / 2,
                gripper.max_opening / 2 + gripper.finger_thickness, gripper.finger_width / 2, gripper.max_opening / 2,
                np.empty_like(offsets), nearest, column)
    return nearest


def _agreement(pairs, points: np.ndarray | None, centre: np.ndarray, gripper: Gripper, length: float,
               bloat: float) -> np.ndarray:
    """How well the hull bears out the model where the pads meet it: the chance (M,) that the
    hull's extent along the closing axis under each pad is the model's ``half``, within two
    length errors and the hull's typical distance from the model (its bloat).

    A contact the hull puts elsewhere (on a handle, on a part the model leaves out) is
    not where the planner checked the friction cone; with no hull points under the pads
    the hull says nothing.
    """
    m = len(pairs["half"])
    if points is None or len(points) == 0:
        return np.ones(m)
    origin = np.stack([pairs["dx"], np.zeros(m), pairs["dz"]], axis=1)
    extent = np.empty((m, 3))
    _pad_extent(points - centre, pairs["R"], origin, gripper.finger_width / 2, gripper.pad_length / 2,
                gripper.max_opening / 2 + gripper.finger_thickness, extent)
    half = pairs["half"]
    apart = np.maximum(np.abs(extent[:, 0] - half), np.abs(extent[:, 1] - half))
    return np.where(extent[:, 2] > 0, ndtr((2 * length + bloat - apart) / length), 1.0)


def _nominal(c, centre, plane, gripper: Gripper, error: tuple[float, float], hull, obstacles=None,
             other_parts=()):
    """Closed-form checks of every candidate at its depths (kernel in Cython).

    Returns the passing (candidate, depth) pairs with their reach ``e`` past the
    model's near side, the offset ``dz`` of the grasp origin from the centre along
    the approach, the half-width ``half`` between the pads, and ``first``, a score
    from the nominal margins to pick the pairs worth checking under perturbation.
    """
    g = gripper
    length, angle = error
    hull_near, column, unexplained = hull
    n = len(c["i"])
    plane_height = np.zeros((n, 3))
    if plane is not None:
        normal_grasp = np.einsum("nab,a->nb", c["R"], plane[:3])  # the plane's normal in each grasp frame
        plane_height[:, 0] = centre @ plane[:3] + plane[3] + c["dx"] * normal_grasp[:, 0]
        plane_height[:, 1] = normal_grasp[:, 2]
        plane_height[:, 2] = (normal_grasp @ _corners(g)).min(axis=1)
    # Per (candidate, depth) pair, the kernel writing them as (n, 4) views.
    depth, dz, half = np.empty(4 * n), np.empty(4 * n), np.empty(4 * n)
    margins, passed = np.empty((4 * n, 4)), np.empty(4 * n, np.uint8)
    _nominal_margins(c["sizes"], c["shape"], np.stack([c["i"], c["j"], c["k"]], 1), c["dx"], hull_near, column,
                     plane_height, plane is not None, g.finger_length, g.pad_length, g.max_opening / 2,
                     g.finger_width / 2, _PALM_CLEARANCE * g.finger_length, _TABLE_CLEARANCE * g.finger_length,
                     _cone(g), length, angle, depth.reshape(n, 4), dz.reshape(n, 4), half.reshape(n, 4),
                     margins.reshape(n, 4, 4), passed.reshape(n, 4))
    pair = np.repeat(np.arange(n), 4)
    ok = passed > 0
    if unexplained.shape[0]:
        # What the hull has and the model lacks (a handle) must not be where an open finger is.
        # Checked last, on the pairs still standing: it weighs every such point against every pair.
        alive = np.flatnonzero(ok)
        hit = np.empty(len(alive), np.uint8)
        origin = np.stack([c["dx"][pair[alive]], np.zeros(len(alive)), dz[alive]], 1)
        _in_open_fingers(unexplained, c["R"][pair[alive]], origin,
                         g.finger_width / 2, g.palm, g.tip, g.max_opening / 2, g.finger_thickness, hit)
        ok[alive] &= hit == 0
    if obstacles is not None and len(obstacles):
        # The other parts of a union: no finger may cut one, open or closing onto this part.
        alive = np.flatnonzero(ok)
        hit = np.empty(len(alive), np.uint8)
        origin = np.stack([c["dx"][pair[alive]], np.zeros(len(alive)), dz[alive]], 1)
        _in_finger_path(np.ascontiguousarray(obstacles - centre), c["R"][pair[alive]], origin, half[alive],
                        g.finger_width / 2, g.palm, g.tip, g.max_opening / 2, g.finger_thickness,
                        _COMPLIANCE * g.pad_length, hit)
        ok[alive] &= hit == 0
    if other_parts:
        # A finger wholly inside another part has none of its surface points to meet: its volume
        # (at full opening, and on its way to the pads) must lie outside every other part.
        alive = np.flatnonzero(ok)
        if len(alive):
            ok[alive] &= ~_fingers_inside(c, pair[alive], dz[alive], half[alive], centre, g, other_parts)
    keep = np.flatnonzero(ok)
    out = _take(c, pair[keep])
    out.update(e=depth[keep], dz=dz[keep], half=half[keep], hull=hull_near[pair[keep]],
               first=np.prod(ndtr(margins[keep]), axis=1))
    return out


def _fingers_inside(c, pose, dz, half, centre, g: Gripper, other_parts) -> np.ndarray:
    """(M,) True where a sample of a finger's volume (open, or halfway to the pads) lies inside
    one of ``other_parts``."""
    m = len(pose)
    open_y = g.max_opening / 2 + g.finger_thickness / 2
    across = np.array([-1.0, 1.0]) * g.finger_width / 2
    along = g.palm + np.linspace(0.0, 1.0, 4) * (g.tip - g.palm)
    levels = np.stack([np.full(m, open_y), (half + open_y) / 2], axis=1)  # (M, 2)
    local = np.empty((m, 2, 2, 2, 4, 3))  # across, side, level, along
    local[..., 0] = c["dx"][pose][:, None, None, None, None] + across[None, :, None, None, None]
    local[..., 1] = (np.array([-1.0, 1.0])[None, None, :, None, None] * levels[:, None, None, :, None])
    local[..., 2] = dz[:, None, None, None, None] + along[None, None, None, None, :]
    world = centre + np.einsum("mab,mnb->mna", c["R"][pose], local.reshape(m, -1, 3)).reshape(-1, 3)
    inside = np.zeros(len(world), bool)
    for part in other_parts:
        inside |= inside_outside(world, part) < 1.0
    return np.asarray(inside.reshape(m, -1).any(axis=1))


# Fixed draws of the model's error, in standard errors: semi-axes along the grasp
# x, y, z (3), centre (3), rotation vector (3), the exponents (1).
_DRAWS = np.random.default_rng(20171).standard_normal((_ERROR_DRAWS, 10))


# The exponents of each draw: 0 nominal, 1 rounder, 2 boxier (each about a third of the draws).
_VARIANT = np.where(_DRAWS[:, 9] > 0.43, 1, np.where(_DRAWS[:, 9] < -0.43, 2, 0)).astype(np.int_)


def _perturbations(error: tuple[float, float], sizes_grasp: np.ndarray, R_grasp: np.ndarray,
                   upright: np.ndarray, plane: np.ndarray | None):
    """The model's error drawn ``_ERROR_DRAWS`` times (fixed draws, so planning is repeatable).

    Sizes along the grasp axes (half an error smaller on average) and the centre move
    by the length error. The
    rotation is drawn in the world: about the plane's normal by the angle error,
    about the two horizontal axes by it too, or by ``_TILT_ERROR`` for a frame set
    upright; without a plane, about each grasp axis by the angle error.

    Returns scale (P, M, 3) of the semi-axes along the grasp axes; turns (K, P, 3) as
    rotation vectors, the set (M,) of the K each grasp takes, and the axes (M, 3, 3) of
    each grasp in the turns' frame (the world's, or its own without a plane); shift (P, 3).
    """
    length, angle = error
    draws = _DRAWS
    # A hull only errs outward, and fits of it mostly do too: the semi-axes are drawn
    # half a standard error smaller on average.
    scale = np.maximum(0.3, 1 + (draws[:, None, 0:3] - _SIZE_BIAS) * length / sizes_grasp[None, :, :])
    shift = draws[:, 3:6] * length
    if plane is None:
        own_axes = np.ascontiguousarray(np.broadcast_to(_EYE, R_grasp.shape))
        return scale, draws[None, :, 6:9] * angle, np.zeros(len(R_grasp), np.int_), own_axes, shift
    normal = plane[:3]
    basis = np.stack([normal, *_level_axes(normal)])  # rows: world axes of the draws
    # World turns of a free frame and of an upright one.
    world = np.stack([draws[:, 6:9] * [angle, angle, angle], draws[:, 6:9] * [angle, _TILT_ERROR, _TILT_ERROR]]) @ basis
    return scale, world, upright.astype(np.int_), np.ascontiguousarray(R_grasp), shift


def _robust(c, gripper: Gripper, error: tuple[float, float], plane: np.ndarray | None):
    """How often each (candidate, depth) pair holds on the model perturbed by its error.

    Returns the score (M,): the mean over the draws of a smoothed "holds" (the
    product over the checks of the normal CDF of four times the margin in
    standard errors).
    """
    g = gripper
    length, angle = error
    m = len(c["i"])
    n = _SAMPLES[0] * _SAMPLES[1]
    frame_axes = np.stack([c["i"], c["j"], c["k"]], 1)  # closing, approach, across
    s_i, s_j, s_k = np.take_along_axis(c["sizes"], frame_axes, 1).T
    # Sample the surface facing the fingers, a little beyond their reach (the draws move it).
    across = _ACROSS * (g.finger_width / 2 + min(2 * length, g.finger_width / 2))
    near = -s_j * (1 - 1e-6)
    far = np.minimum(s_j * (1 - 1e-6), c["e"] - s_j + 2 * length)
    along = near[:, None] + _ALONG[None, :] * (far - near)[:, None]
    # Frame coordinate k is +-x of the grasp: sample across the finger where it slid to.
    sign_k = np.einsum("ma,ma->m", c["R"][:, :, 0], c["F"][np.arange(m), :, c["k"]])
    across = sign_k[:, None] * (c["dx"][:, None] + across[None, :])
    variants = np.stack([c["shape"]] + [np.minimum(np.maximum(c["shape"] + change, _SHAPE_LIMITS[0]), _SHAPE_LIMITS[1])
                                        for change in _SHAPE_ERROR])
    points, normals = np.empty((len(variants), m, 2 * n, 3)), np.empty((len(variants), m, 2 * n, 3))
    valid = np.empty((len(variants), m, 2 * n), np.uint8)
    _surface_samples(c["sizes"], variants, frame_axes, across, c["s"][:, None] * along, points, normals, valid)
    # Frame-to-grasp rotation of each pair; the model's centre in its grasp frame.
    M = np.einsum("mab,mac->mbc", c["R"], c["F"])
    centre = np.stack([-c["dx"], np.zeros(m), -c["dz"]], axis=1)
    scale, turns, rotation_set, axes, shift = _perturbations(error, np.stack([s_k, s_i, s_j], axis=1), c["R"],
                                                             c["upright"], plane)
    score = np.empty(m)
    # The hull does not move with the model's error.
    _perturbed_margins(points, normals, valid, variants, c["sizes"], M, _VARIANT, scale, turns, rotation_set,
                       axes, shift, centre, c["hull"] - c["dz"], g.finger_width / 2, g.palm, g.tip,
                       g.max_opening / 2, _COMPLIANCE * g.pad_length, _cone(g), length, angle,
                       np.empty((2 * n, 3)), np.empty((len(variants), 2 * n, 6)), np.empty(turns.shape + (3,)), score)
    return score


def _diverse(pairs, preference: np.ndarray) -> np.ndarray:
    """Indices of the ``_ROBUST_KEEP`` pairs to check under perturbation: by their first score
    (within 0.05, approaches from above first), the best of each orientation before the
    second best of any (slides and depths of one orientation are much alike)."""
    order = np.lexsort((preference, -np.round(pairs["first"] / _SCORE_STEP)))
    # Each pair's rank among those of its orientation, in that order.
    pose = pairs["pose"][order]
    grouped = np.argsort(pose, kind="stable")
    count = len(order)
    starts = np.concatenate([[True], pose[grouped][1:] != pose[grouped][:-1]])
    rank = np.empty(count, dtype=np.intp)
    rank[grouped] = np.arange(count) - np.maximum.accumulate(np.where(starts, np.arange(count), 0))
    return order[np.argsort(rank, kind="stable")][:_ROBUST_KEEP]


def _alike(R: np.ndarray, origin: np.ndarray, tolerance: float) -> np.ndarray:
    """(M, M) True where two grasps differ only in depth: the same approach, the same closing
    line (the gripper is symmetric under a half turn about z), origins apart along it alone."""
    cos = math.cos(math.radians(3))
    same = (R[:, :, 2] @ R[:, :, 2].T > cos) & (np.abs(R[:, :, 1] @ R[:, :, 1].T) > cos)
    apart = origin[:, None, :] - origin[None, :, :]
    along = np.einsum("nma,na->nm", apart, R[:, :, 2])
    across = np.linalg.norm(apart - along[:, :, None] * R[:, None, :, 2], axis=2)
    return same & (across < tolerance)


def plan_grasps(model, support_plane=None, gripper: Gripper = DEFAULT_GRIPPER, *,
                residual: float = 0.0, silhouette_iou=None, points=None, max_grasps: int = 10,
                min_score: float = _MIN_SCORE) -> list[Grasp]:
    """Parallel-jaw grasps of a superquadric or a union of them, best first (see the module docstring).

    On a union (DESIGN.md §1.11) each part is planned on as above, its contacts on that
    part, and a grasp is kept only where no other part comes between the palm and the
    object, lies where a finger goes (open, or closing onto the pads) or holds a finger
    inside it; the parts' lists are merged by score.

    Parameters
    ----------
    model : Superquadric or sequence of Superquadric
        The model, convex (exponents below 2), or the parts of a union.
    support_plane : (4,) array_like, optional
        ``[nx, ny, nz, d]``: the object stands where ``n . x + d >= 0``; no part
        of the gripper may come near the other side, and no approach comes from it.
    gripper : Gripper
    residual : float
        The fit's residual (bundle units): how far the hull's points lie from the model.
        With ``points``, their typical (median) distance from the model is used where smaller.
    silhouette_iou : sequence of float, optional
        How well the model covers each view's silhouette.
    points : (N, 3) array_like, optional
        The carved hull's points. The hull holds the whole object, also what
        the superquadric leaves out (a mug's handle): the palm keeps clear of
        them too.
    max_grasps : int
        At most this many grasps.
    min_score : float
        Grasps less likely to hold than this are left out.

    Returns
    -------
    list of Grasp
        Best first; empty when no grasp of this gripper is likely to hold.

    Raises
    ------
    CoreError
        If an argument is malformed, or the superquadric is not convex.

    Examples
    --------
    A 4 x 6 x 5 cm box on the table is taken across its 4 cm side, from above:

    >>> T = np.eye(4); T[2, 3] = 0.025
    >>> box = Superquadric([0.03, 0.02, 0.025], [0.1, 0.1], T)
    >>> best = plan_grasps(box, [0, 0, 1, 0])[0]
    >>> best.approach, round(best.width, 3), best.T_world_grasp[:3, 1].round(3).tolist()
    ('top', 0.04, [0.0, 1.0, 0.0])
    """
    parts = [model] if isinstance(model, Superquadric) else list(model) if isinstance(model, (list, tuple)) else None
    if not parts or not all(isinstance(part, Superquadric) for part in parts):
        raise CoreError(f"model must be a Superquadric or a non-empty sequence of them, got {type(model).__name__}")
    if not isinstance(gripper, Gripper):
        raise CoreError(f"gripper must be a Gripper, got {type(gripper).__name__}")
    for part in parts:
        if np.any(part.shape >= 2):
            raise CoreError(f"grasps need convex superquadrics (exponents below 2), got {part.shape}")
    if not (isinstance(max_grasps, numbers.Integral) and max_grasps >= 1):
        raise CoreError(f"max_grasps must be a positive integer, got {max_grasps!r}")
    if not (isinstance(min_score, numbers.Real) and 0 <= min_score <= 1):
        raise CoreError(f"min_score must be a number in [0, 1], got {min_score!r}")
    if not (isinstance(residual, numbers.Real) and math.isfinite(residual) and residual >= 0):
        raise CoreError(f"residual must be a finite number >= 0, got {residual!r}")
    if silhouette_iou is not None:
        silhouette_iou = np.asarray(silhouette_iou, dtype=np.float64).ravel()
        if not np.all((silhouette_iou >= 0) & (silhouette_iou <= 1)):
            raise CoreError(f"silhouette_iou must lie in [0, 1], got {silhouette_iou.tolist()}")
    if points is not None:
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
            raise CoreError(f"points must be an (N, 3) array of finite numbers, got shape {points.shape}")
        points = points[:: max(1, len(points) // _HULL_POINTS)]
    plane = _check_plane(support_plane)
    grasps: list[Grasp] = []
    for k, part in enumerate(parts):
        others = tuple(parts[:k] + parts[k + 1:])
        grasps = _merged(grasps, _plan(part, plane, gripper, residual, silhouette_iou, points, max_grasps, min_score,
                                       others), max_grasps)
    miss = _miss(silhouette_iou)
    if plane is not None and points is not None and len(points) >= 4 and miss > _POOR_COVER:
        # The superquadric describes the object poorly (an L): plan on the hull's upright box
        # too. The box bounds all the views saw; the hull checks keep its grasps where the
        # hull has the surface the box claims.
        box = upright_box(points, plane[:3])
        grasps = _merged(grasps, _plan(box, plane, gripper, math.inf, None, points, max_grasps, min_score), max_grasps)
    return grasps


def _merged(first: list[Grasp], second: list[Grasp], max_grasps: int) -> list[Grasp]:
    """Two ranked lists as one, by score within ``_SCORE_STEP`` (then from above first)."""
    both = first + second
    order = sorted(range(len(both)), key=lambda k: (-round(both[k].score / _SCORE_STEP),
                                                    _APPROACH_ORDER.index(both[k].approach), k))
    return [both[k] for k in order[:max_grasps]]


def _plan(superquadric: Superquadric, plane: np.ndarray | None, gripper: Gripper, residual: float, silhouette_iou,
          points: np.ndarray | None, max_grasps: int, min_score: float, others=()) -> list[Grasp]:
    """:func:`plan_grasps` on checked arguments: contacts on ``superquadric``, clear of the
    ``others`` (the rest of a union)."""
    radial, bloat = None, 0.0
    if points is not None and len(points):
        # What the hull has and the model lacks is measured from the whole union.
        radial = np.min([_radial(points, part) for part in (superquadric, *others)], axis=0)
        # The hull's typical distance from the model (the median's, scaled to a standard
        # deviation's): the model's own error, apart from what it leaves out (a handle),
        # which the hull checks cover; and how far the hull bulges past the object.
        bloat = 1.4826 * _median(np.abs(radial))
        residual = min(residual, bloat)
    error = model_error(superquadric, residual, silhouette_iou)
    centre = superquadric.T_world_object[:3, 3]

    candidates = _candidates(superquadric, plane, gripper)
    hull = _hull(candidates, points, radial, superquadric, gripper, error[0])
    obstacles = None
    if others:
        obstacles = np.concatenate([surface_points(part, *_OBSTACLE_GRID) for part in others])
        hull = (np.minimum(hull[0], _palm_reach(candidates, obstacles, superquadric, gripper)),) + hull[1:]
    pairs = _nominal(candidates, centre, plane, gripper, error, hull, obstacles, others)
    if len(pairs["i"]) == 0:
        return []
    preference = _approach_preference(pairs["R"][:, :, 2], plane)
    keep = _diverse(pairs, preference)
    pairs, preference = _take(pairs, keep), preference[keep]
    score = _robust(pairs, gripper, error, plane) * _agreement(pairs, points, centre, gripper, error[0], bloat)
    # Grasps about as likely to hold: from above first, then the one with more room in the jaws.
    order = np.lexsort((pairs["half"], preference, -np.round(score / _SCORE_STEP)))
    R = pairs["R"]
    origin = centre + np.einsum("mab,mb->ma", R, np.stack([pairs["dx"], np.zeros(len(R)), pairs["dz"]], 1))
    alike = _alike(R, origin, 0.05 * gripper.finger_length)
    T = np.zeros((len(R), 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, origin, 1.0
    scores, widths, alike = score.tolist(), (2 * pairs["half"]).tolist(), alike.tolist()
    grasps: list[Grasp] = []
    chosen: list[int] = []
    for index in order.tolist():
        if scores[index] < min_score or len(grasps) == max_grasps:
            break
        if any(alike[index][other] for other in chosen):  # the same grasp but for its depth, ranked higher
            continue
        chosen.append(index)
        grasps.append(Grasp(T[index].copy(), widths[index], scores[index], _APPROACH_ORDER[preference[index]]))
    return grasps


def _median(values: np.ndarray) -> float:
    """np.median of a 1-D array without NaNs, without its overhead."""
    half = len(values) // 2
    if len(values) % 2:
        return float(np.partition(values, half)[half])
    low, high = np.partition(values, [half - 1, half])[half - 1:half + 1]
    return float((low + high) / 2)


def _approach_preference(approach: np.ndarray, plane: np.ndarray | None) -> np.ndarray:
    """Index into ``_APPROACH_ORDER`` of each approach (N, 3): "top" within 30 degrees of
    straight down the plane's normal, "side" within 30 degrees of level, else "tilted"."""
    if plane is None:
        return np.full(len(approach), 2)
    down = -approach @ plane[:3]
    return np.where(down >= math.cos(math.radians(30)), 0, np.where(np.abs(down) <= 0.5, 1, 2))
