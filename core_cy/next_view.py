"""Where to look next: the view whose silhouette would most reduce the model's uncertainty.

The silhouettes seen so far leave the model unsure where other models explain
them nearly as well. The competing hypotheses are the silhouette fit from each
of the point fit's starts (each axis of the hull as the object's z axis, and
the 45-degree turns), and, for a model in parts, other part counts (the one
superquadric closest to the whole, the union without each of its parts): those whose projections agree with the silhouettes nearly as well
as the model's does are kept beside it. Where they disagree, a view tells
them apart; where they agree, it does not.

- The **disagreement** of the hypotheses in a view is the mean, over pairs, of
  1 - IoU of their projections (drawn at a reduced resolution).
- The model's **uncertainty** is the largest disagreement over views all
  around the object, at the views' distance and elevation, and the candidates:
  0 when every hypothesis looks the same from everywhere. Below
  ``sure_below`` the model is sure.
- A candidate's **expected gain** is its disagreement (at most the
  uncertainty): what its silhouette would settle.

The carved hull (the largest body the silhouettes allow) breaks ties: where the
hypotheses agree, a view in which the hull and the model differ most sees the
most of what no view has seen yet (a mug's handle turned away). It weighs a
tenth of the hypotheses' disagreement in the choice and is no part of the
expected gain.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import ConvexHull

from .camera import Camera
from .carve import check_support_plane
from .edges import edge_samples, silhouette_outline
from .errors import CoreError, FitError
from .plan import look_at
from .silhouette_fit import fit_to_silhouettes
from .sphere import farthest_reach
from .superquadric import Superquadric, start_superquadrics, surface_points

__all__ = ["NextView", "choose_next_view", "propose_views"]

# Projections are drawn with the object's enclosing sphere this many pixels across: enough to tell
# hypotheses apart by a per cent, cheap enough for a few dozen views.
_DRAW_PX = 200
# A hypothesis is kept when it misses the silhouettes (1 - IoU, the views' mean) by at most this
# many times what the model misses, plus the slack: nearly as good an explanation of what was seen.
_MISS_RATIO = 1.5
_MISS_SLACK = 0.005
# Edge samples per view and Levenberg-Marquardt steps of each competing fit: a hypothesis, not the result.
_EDGE_SAMPLES = 24
_FIT_ITERATIONS = 8
# At most this many of the point fit's starts are fitted.
_MAX_STARTS = 4
_HULL_POINTS = 400
# Weight of the hull's disagreement with the model in the choice (not in the gain).
_HULL_WEIGHT = 0.1
# Views all around the object on which the uncertainty is measured (azimuth steps), and proposals.
_AROUND = 12


@dataclass(frozen=True)
class NextView:
    """The view to take next (see :func:`choose_next_view`)."""

    candidate: int | None  # index into the candidates given, None when proposed
    T_world_cam: np.ndarray  # (4, 4) camera-to-world
    expected_gain: float  # expected reduction of the model's uncertainty, >= 0
    uncertainty: float  # the model's uncertainty now (same units)
    sure: bool  # True when the uncertainty is below `sure_below`


@dataclass(frozen=True, eq=False)
class _Body:
    """Something to draw: convex pieces (point sets whose hull is drawn), or triangles."""

    pieces: tuple[np.ndarray, ...] = ()
    triangles: np.ndarray | None = None  # (T, 3, 3) world


def _model_pieces(reconstruction) -> list[Superquadric]:
    parts = getattr(reconstruction, "parts", None)
    return list(parts) if parts else [reconstruction.superquadric]


def _superquadric_body(parts) -> _Body:
    return _Body(pieces=tuple(surface_points(p, 12, 24) for p in parts))


def _hull_body(points: np.ndarray, centre: np.ndarray) -> _Body | None:
    """The carved hull as triangles: its points are radii along directions from the centre, so the
    convex hull of the directions triangulates it (it is star-shaped about the centre)."""
    # A few hundred points draw the hull to a pixel at the reduced resolution.
    points = points[::max(1, len(points) // _HULL_POINTS)]
    offsets = points - centre
    lengths = np.linalg.norm(offsets, axis=1)
    keep = lengths > 0
    if keep.sum() < 4:
        return None
    directions = offsets[keep] / lengths[keep, None]
    try:
        simplices = ConvexHull(directions).simplices
    except Exception:  # degenerate directions (all in one plane): no hull to draw
        return None
    return _Body(triangles=points[keep][simplices])


class _Canvas:
    """One view drawn at a fixed scale about the object: the camera's K shifted and scaled so that the
    object's enclosing sphere fills a square of ``_DRAW_PX`` pixels (whatever the object's size in
    the image, the projections are compared at the same resolution); or, with ``image_size``, the
    view's whole image at full resolution."""

    def __init__(self, camera: Camera, sphere: tuple[np.ndarray, float] | None = None,
                 image_size: tuple[int, int] | None = None) -> None:
        K = camera.K.copy()
        if image_size is not None:
            self.size = image_size
        else:
            centre, radius = sphere  # type: ignore[misc]
            (uv,), (depth,) = camera.project(np.asarray(centre, dtype=np.float64)[None])
            # The sphere's outline seen off the optical axis is a little wider than f R / depth.
            reach = 1.3 * camera.focal_length * radius / max(depth, 1e-12)
            scale = _DRAW_PX / (2.0 * reach) if depth > 0 else 1.0
            K[:2] *= scale
            K[0, 2] += _DRAW_PX / 2 - scale * uv[0]
            K[1, 2] += _DRAW_PX / 2 - scale * uv[1]
            self.size = (_DRAW_PX, _DRAW_PX)
        self.camera = Camera(K=K, T_world_cam=camera.T_world_cam)

    def draw(self, body: _Body) -> np.ndarray | None:
        """The body's projection (H, W) bool, or None if it reaches behind the camera."""
        width, height = self.size
        mask = np.zeros((height, width), np.uint8)
        limit = 4.0 * max(width, height)
        for piece in body.pieces:
            uv, depth = self.camera.project(piece)
            if np.any(depth <= 0):
                return None
            hull = cv2.convexHull(np.clip(uv, -limit, limit).astype(np.float32)).reshape(-1, 2)
            cv2.fillConvexPoly(mask, np.round(hull * 16).astype(np.int32), 1, shift=4)
        if body.triangles is not None:
            flat = body.triangles.reshape(-1, 3)
            uv, depth = self.camera.project(flat)
            if np.any(depth <= 0):
                return None
            polygons = np.round(np.clip(uv, -limit, limit) * 16).astype(np.int32).reshape(-1, 3, 2)
            cv2.fillPoly(mask, list(polygons), 1, shift=4)
        return mask.view(bool)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    union = int(np.count_nonzero(a | b))
    return int(np.count_nonzero(a & b)) / union if union else 1.0


def _disagreement(masks: list[np.ndarray]) -> float:
    if len(masks) < 2:
        return 0.0
    return float(np.mean([1.0 - _iou(a, b) for a, b in itertools.combinations(masks, 2)]))


def _hypotheses(reconstruction, cameras, plane) -> list[list[Superquadric]]:
    """The model, and the competing fits whose silhouettes agree with the views nearly as well."""
    model = _model_pieces(reconstruction)
    silhouettes = reconstruction.silhouettes
    # Agreement at full resolution: the hypotheses differ by a pixel or two where the views saw them.
    canvases = [_Canvas(camera, image_size=(s.shape[1], s.shape[0])) for camera, s in zip(cameras, silhouettes)]
    seen = [s != 0 for s in silhouettes]

    def miss(parts) -> float:
        drawn = [c.draw(_superquadric_body(parts)) for c in canvases]
        return float(np.mean([1.0 if d is None else 1.0 - _iou(d, s) for d, s in zip(drawn, seen)]))

    bar = _MISS_RATIO * miss(model) + _MISS_SLACK
    kept = [model]
    if len(model) > 1:
        # Other part counts: the union without each of its parts, and the one superquadric. That one is
        # the best of the silhouette fits from the point fit's starts: where it explains the views too
        # poorly, so do the others, which are not fitted.
        kept.extend(rival for rival in (model[:k] + model[k + 1:] for k in range(len(model))) if miss(rival) <= bar)
        if miss([reconstruction.superquadric]) > bar:
            return kept
        kept.append([reconstruction.superquadric])
    points = reconstruction.points
    edges = []
    for silhouette in silhouettes:
        try:
            edges.append(edge_samples(silhouette_outline(silhouette), silhouette, count=_EDGE_SAMPLES))
        except CoreError:
            edges.append(np.zeros((0, 2)))
    try:
        starts = start_superquadrics(points[::max(1, len(points) // 250)], support_plane=plane)[:_MAX_STARTS]
    except FitError:
        starts = []
    reach = farthest_reach(reconstruction.centre, reconstruction.radius, cameras)
    for start in starts:
        try:
            fit = fit_to_silhouettes(start, cameras, edges, support_plane=plane, max_iterations=_FIT_ITERATIONS,
                                     reach=reach)
        except FitError:
            continue
        if miss([fit.superquadric]) <= bar:
            kept.append([fit.superquadric])
    return kept


def propose_views(centre, cameras, count: int = _AROUND) -> list[Camera]:
    """``count`` cameras evenly around ``centre`` (about the support's up, world z), at the
    views' mean distance and elevation from it, aimed at it, with the first view's K.

    Examples
    --------
    >>> K = [[600, 0, 319.5], [0, 600, 239.5], [0, 0, 1]]
    >>> views = [Camera(K=K, T_world_cam=look_at([0.3, 0.0, 0.4], [0.0, 0.0, 0.0]))]
    >>> ring = propose_views([0.0, 0.0, 0.0], views, count=4)
    >>> [np.round(c.center, 3).tolist() for c in ring][:2]
    [[0.3, 0.0, 0.4], [0.0, 0.3, 0.4]]
    """
    centre = np.asarray(centre, dtype=np.float64).reshape(3)
    offsets = np.array([c.center - centre for c in cameras])
    distance = float(np.mean(np.linalg.norm(offsets, axis=1)))
    elevation = float(np.mean(np.arcsin(np.clip(offsets[:, 2] / np.linalg.norm(offsets, axis=1), -1, 1))))
    # A view straight from above or below has no azimuth: keep the ring off the pole.
    elevation = float(np.clip(elevation, -math.radians(80), math.radians(80)))
    start = math.atan2(offsets[0, 1], offsets[0, 0])
    proposals = []
    for k in range(count):
        azimuth = start + 2 * math.pi * k / count
        position = centre + distance * np.array([math.cos(elevation) * math.cos(azimuth),
                                                 math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])
        proposals.append(Camera(K=cameras[0].K, T_world_cam=look_at(position, centre)))
    return proposals


def _inside(position: np.ndarray, workspace) -> bool:
    if workspace is None:
        return True
    lo, hi = (np.asarray(v, dtype=np.float64).reshape(3) for v in workspace)
    return bool(np.all(position >= lo) and np.all(position <= hi))


def choose_next_view(reconstruction, cameras, candidates=None, *, support_plane=None, workspace=None,
                     sure_below: float = 0.02) -> NextView:
    """The view whose silhouette would most reduce the model's uncertainty (module docstring).

    Parameters
    ----------
    reconstruction : core_cy.reconstruct.Reconstruction
        The model from the views so far (its silhouettes, hull and model).
    cameras : sequence of Camera
        The cameras of those views, in order.
    candidates : sequence of Camera, optional
        Where the next view may be taken from. None: views proposed around the
        object at the views' distance and elevation (:func:`propose_views`).
    support_plane : (4,) array_like, optional
        ``[nx, ny, nz, d]``, as given to the reconstruction.
    workspace : ((3,), (3,)) array_like, optional
        ``(lo, hi)``, an axis-aligned box the camera's position must lie in:
        a candidate outside it is never chosen.
    sure_below : float
        The model is sure when its uncertainty is below this.

    Returns
    -------
    NextView

    Raises
    ------
    CoreError
        If no candidate lies inside the workspace, or the cameras do not match
        the reconstruction's views.
    """
    cameras = list(cameras)
    if len(cameras) != len(reconstruction.silhouettes):
        raise CoreError(f"got {len(cameras)} cameras for a reconstruction of {len(reconstruction.silhouettes)} views")
    if workspace is not None:
        try:
            lo, hi = (np.asarray(v, dtype=np.float64).reshape(3) for v in workspace)
        except (TypeError, ValueError):
            raise CoreError("workspace must be two corners (lo, hi), three numbers each") from None
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)):
            raise CoreError(f"workspace must have lo <= hi, finite, got {lo.tolist()} and {hi.tolist()}")
    centre = np.asarray(reconstruction.centre, dtype=np.float64)
    plane = None if support_plane is None else check_support_plane(support_plane, centre)
    proposed = candidates is None
    offered = propose_views(centre, cameras) if proposed else list(candidates)
    admissible = [j for j, c in enumerate(offered) if _inside(c.center, workspace)]
    if not admissible:
        raise CoreError(f"none of the {len(offered)} {'proposed' if proposed else 'candidate'} views lies inside "
                        f"the workspace")
    hypotheses = [_superquadric_body(parts) for parts in _hypotheses(reconstruction, cameras, plane)]
    hull = _hull_body(np.asarray(reconstruction.points), centre)
    sphere = (centre, float(reconstruction.radius))

    def rate(camera: Camera, with_hull: bool) -> tuple[float, float]:
        """(the hypotheses' disagreement, the hull's disagreement with the model) in the view."""
        canvas = _Canvas(camera, sphere)
        drawn = [canvas.draw(body) for body in hypotheses]
        if drawn[0] is None:
            return 0.0, 0.0  # the model reaches behind the camera: no silhouette to compare
        masks = [d for d in drawn if d is not None]
        hull_mask = canvas.draw(hull) if with_hull and hull is not None else None
        return _disagreement(masks), 0.0 if hull_mask is None else 1.0 - _iou(drawn[0], hull_mask)

    rated = {j: rate(offered[j], True) for j in admissible}
    around = [] if proposed or len(hypotheses) < 2 else [rate(c, False)[0] for c in propose_views(centre, cameras)]
    uncertainty = max([*around, *(r[0] for r in rated.values())])
    best = max(admissible, key=lambda j: rated[j][0] + _HULL_WEIGHT * rated[j][1])
    gain = min(rated[best][0], uncertainty)
    return NextView(candidate=None if proposed else best, T_world_cam=offered[best].T_world_cam.copy(),
                    expected_gain=float(max(0.0, gain)), uncertainty=float(uncertainty),
                    sure=bool(uncertainty < sure_below))
