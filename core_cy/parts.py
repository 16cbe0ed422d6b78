"""A model in parts: a union of superquadrics where one leaves the silhouettes unexplained (DESIGN.md §1.11).

The one-superquadric fit comes first. A part must pay for itself: it is kept only
when, without it, the union's silhouette IoU would drop by at least
``PART_GAIN`` in at least two views (in every view, with fewer); a part seen in one
view only has no depth. A union may also carve away what one view shows empty, with
no more volume: twice ``PART_GAIN`` there, by covering less of what it shows empty within
the silhouette's convex hull, the table seen through the object (a dumbbell's two weights
without the gap between them, hidden behind them in the other views); beyond that hull a
silhouette that stops short may as well have left a face out. Where the segmentation says
which pixels it cannot confirm (``auto``: the table's shade about its silhouettes, where a
shadow may have been taken in or a dark face left out, and everything beyond a silhouette's
convex hull, where a face may have been left out whatever its colour), a part must pay as much
with what changes there set aside: a union that explains a segmentation's error explains nothing a
camera saw. A part that no view sees rise off the
table pays on the silhouettes as they are, and leaves the model at the end: it is the shadow
they took in, which it kept off the other parts' outlines. A sheet, a part whose thickness no view
sees, is no body either (silhouettes that wrong, a face and a shadow, each drawn flat, explain
them better than the body the views see): at the end a sheet floating over the table becomes the
body beneath it, standing on the table, and any other leaves the model. So where the silhouettes and
the one superquadric disagree by less than that, no part can pay and the object stays
one superquadric: decided before anything else is done, from the pixels where they
disagree farther from the other's outline than the edges' noise (a band along the
outline is no part's; a superquadric's views disagree by a few percent of IoU there
and nowhere else). The same decides whether another round is worth proposing.

Otherwise parts are proposed, each round from the union so far:

- **split** a part by the plane through its centre across one of its axes
  (Vezzani et al.'s superquadric-lib): the hull points that part explains best,
  on either side, each give a part (their box in the part's frame, upright on a
  table); in the first round the hull's upright box is split the same way, in
  case the one superquadric sits in a bad minimum;
- **add** a part where the silhouettes are unexplained: the hull points that
  project outside the union's outline in two views or more, grouped into
  neighbourhoods (as Liu et al.'s hierarchical EMS takes the points a part
  cannot explain), each group giving one.

Every proposal is refined against the silhouettes of the union (all parts
together, the support plane kept: :func:`core_cy.silhouette_fit.fit_to_silhouettes`)
a few steps; the best goes on to convergence (and, while it leaves the silhouettes
unexplained, the proposals left behind go on in turn); the parts that do not pay are
dropped (the least useful first, the rest refined again). Where that leaves a union no
better than the model before it, the few steps were a wrong guess (a start already at its
minimum beats those still on their way down): the proposals left behind go on to their
end, and of those that pay, the one that ends lowest is taken. The union is kept
if it gains ``PART_GAIN`` of IoU over the model before it in two views (or carves),
with more parts and losing less than that in every view (what one view pays for at another's
cost moves an error between views), or with no more and a lower edge cost (a better minimum); a union whose
parts all pay but that gains so in one view only, a dumbbell's two weights
without the bar, goes one round on before it is given up; at most ``MAX_PARTS``
parts. Last, a part that floats (what holds it up hidden behind it in every
view) is taken down to the table where that explains the silhouettes as well,
and each part is tried with another of its axes as z, as the one superquadric is
(a barrel fitted as a square bar across it becomes the cylinder along it);
whether the model rests on the table, its parts on a face or a side, is decided
after, for one part and many alike (:func:`explains_more`, in
:func:`core_cy.reconstruct.reconstruct`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .edges import edge_samples, silhouette_outline
from .quality import hull_covers, projected_outline
from .silhouette_fit import _EXPLAINED_PX, _NOISE_PX, _Fitter
from .superquadric import Superquadric, inside_outside, resting_on, surface_points, upright_box

__all__ = ["MAX_PARTS", "PART_GAIN", "PartsFit", "explains_more", "fit_parts", "union_ious"]

MAX_PARTS = 6
# What a part must explain to pay for its eleven parameters: this share of a view's
# silhouette IoU, in two views (every view, with fewer).
PART_GAIN = 0.02
_VIEWS_TO_PAY = 2
# What a union must explain more in the one view that sees it, to carve away what that view shows empty.
_CARVED_GAIN = _VIEWS_TO_PAY * PART_GAIN
# Edge samples per view for the union: a part that owns a tenth of the outline has ten.
_PART_SAMPLES = 96
# Levenberg-Marquardt steps of the union after the choice among proposals, and after a part is dropped.
_ITERATIONS = 30
# A hull point projecting this far (px) outside the union's outline is unexplained in that view.
_UNEXPLAINED_PX = 2.0
# Silhouette and model disagreeing within this (px) of the other's outline is the edges' noise (twice their RMS).
_EDGE_BAND_PX = 2 * _NOISE_PX
_MIN_GROUP = 11  # points of an unexplained group to place a part on
# Slabs along a part's axis, and directions across it, to find where it narrows; a waist is at most
# this share of the widest slab's width.
_SLABS, _WIDTH_DIRECTIONS, _WAIST = 12, 8, 0.5
_GROUPS = 2  # the largest groups each make a proposal
_START_SHAPE = np.array([0.5, 0.5])
_FLOOR = 0.05  # a start's semi-axis is at least this share of its parent's
# A part tilted less than this (degrees) from resting on a face stands on it: it may be taken down to the table.
_MIN_TILT = 1.0
# A part taken down to the table is kept where the silhouettes' cost grows by no more than this factor
# (the noise of a few steps).
_GROUNDED_COST = 1.1
_GROUNDED_STEPS = 2
# The proposals a round left behind go on while the search has taken fewer than this many times the
# evaluations of the one superquadric: at four, a bottle's neck and dtu65's second part (three views)
# were cut off just short of paying.
_BUDGET = 6.0


@dataclass(frozen=True, eq=False)
class PartsFit:
    """Result of :func:`fit_parts`.

    Attributes
    ----------
    parts : tuple of Superquadric
        The model: the object is their union; one part for an object that is one superquadric.
    silhouette_iou : list of float
        The union's silhouette IoU in each view.
    evaluations : int
        Evaluations of the union's silhouette cost the search took, each part counted.
    """

    parts: tuple[Superquadric, ...]
    silhouette_iou: list[float]
    evaluations: int = 0


def union_ious(parts, cameras, silhouettes, boxes) -> tuple[list[float], np.ndarray]:
    """Each view's silhouette IoU of the union, and (P, V) of the union without each part."""
    return _Rasters(cameras, silhouettes, boxes).ious(parts)


def unexplained_shares(parts, cameras, silhouettes, boxes, band: float = _EDGE_BAND_PX) -> list[float]:
    """Each view's share of the silhouette and the union's projection together that one explains and
    the other not, farther than ``band`` (px) from the other's outline: what a part could
    explain (a band along the edges is the edges' own noise, no part's)."""
    return _Rasters(cameras, silhouettes, boxes).unexplained(parts, band)


class _Rasters:
    """The views' silhouettes, and each view's pixels of the silhouette and of each part's projection
    (:func:`core_cy.quality.hull_covers`) for the union last drawn: a round's IoUs, the share it
    leaves unexplained and the next round's additions all look at the union it kept, drawn once,
    and counted once (its tallies: its IoUs and what each part pays are read off the same counts)."""

    def __init__(self, cameras, silhouettes, boxes, unsure=None) -> None:
        self.cameras, self.silhouettes, self.boxes = list(cameras), list(silhouettes), list(boxes)
        self._unsure = unsure
        self._parts: tuple[Superquadric, ...] = ()
        self._drawn: list = []
        self._tallied: dict[bool, np.ndarray] = {}  # the union last drawn's tallies, by ``each``

    @cached_property
    def unsure(self) -> list:
        """Per view, the pixels whose side the segmentation cannot confirm (None: every pixel is sure),
        found once a part is to pay, if ``unsure`` came as the function that finds them; and with them
        every pixel beyond the silhouette's convex hull (:attr:`enclosed`): there a silhouette that stops
        short may as well have left a face out (a lit top of the table's colour), so a union that explains
        it the better by covering less there explains the segmentation's error, not the object (as a union
        may not carve there either)."""
        unsure = self._unsure() if callable(self._unsure) else self._unsure
        if unsure is None:
            return [None] * len(self.cameras)
        return [None if view is None else view | ~hull for view, hull in zip(unsure, self.enclosed)]

    def drawn(self, parts) -> list:
        """Per view, ``hull_covers`` of the parts' projections."""
        parts = tuple(parts)
        if len(parts) != len(self._parts) or any(a is not b for a, b in zip(parts, self._parts)):
            surfaces = [surface_points(part) for part in parts]  # the same points, seen from every view
            self._drawn = [hull_covers([projected_outline(part, camera, surface) for part, surface in zip(parts, surfaces)],
                                       silhouette, box)
                           for camera, silhouette, box in zip(self.cameras, self.silhouettes, self.boxes)]
            self._parts = parts
            self._tallied = {}
        return self._drawn

    def ious(self, parts) -> tuple[list[float], np.ndarray]:
        """As :func:`union_ious`."""
        tallies = self._tallies(parts, each=True)
        without = _tally_iou(tallies[:, 1:]).T if len(parts) > 1 else np.zeros((len(parts), len(self.cameras)))
        return _tally_iou(tallies[:, 0]).tolist(), without

    @property
    def any_unsure(self) -> bool:
        return any(unsure is not None for unsure in self.unsure)

    def gains(self, parts, before=None) -> np.ndarray:
        """(P, V) how much each view's IoU drops without each part, or (V,) how much more ``parts``
        explain than ``before``: the less of two readings of the silhouettes, as they are and with
        what changes on their unsure pixels set aside (a change there is no evidence), so that what
        pays pays on the pixels the segmentation is sure of as well as on all of them."""
        tallies = self._tallies(parts, each=before is None)
        if before is None:
            union, without = tallies[:, :1], tallies[:, 1:]
            plain = _tally_iou(union) - _tally_iou(without)
            sure = _tally_iou(union) - _tally_iou(_as_on_unsure(without, union))
        else:
            earlier = self._tallies(before, each=False)
            plain = _tally_iou(tallies) - _tally_iou(earlier)
            sure = _tally_iou(_as_on_unsure(tallies, earlier)) - _tally_iou(earlier)
        gains = np.minimum(plain, sure)  # (V, P) or (V, 1)
        return gains[:, 0] if before is not None else gains.T

    def _tallies(self, parts, each: bool) -> np.ndarray:
        """(V, 1 + P, 5) per view, for the union and (``each``) for it without each part, else (V, 1, 5):
        the silhouette's pixels, those covered, the empty ones covered, and those two on unsure pixels
        (read-only: kept with the drawing)."""
        parts = tuple(parts)
        drawing = self.drawn(parts)
        if each in self._tallied:
            return self._tallied[each]
        if True in self._tallied:  # the union's own row is the first of every part's
            return self._tallied[True][:, :1]
        tallies = np.zeros((len(self.cameras), 1 + len(parts) if each else 1, 5))
        for v, ((object_pixels, covers, (x0, y0)), unsure) in enumerate(zip(drawing, self.unsure)):
            if object_pixels is None:
                continue
            aside = (None if unsure is None
                     else unsure[y0:y0 + object_pixels.shape[0], x0:x0 + object_pixels.shape[1]])
            area = int(np.count_nonzero(object_pixels))
            unions = [covers] + [covers[:p] + covers[p + 1:] for p in range(len(parts)) if each and len(parts) > 1]
            for u, union in enumerate(unions):
                covered = np.any(np.stack(union), axis=0) if union else np.zeros_like(object_pixels)
                explained, extra = object_pixels & covered, covered & ~object_pixels
                tallies[v, u] = (area, np.count_nonzero(explained), np.count_nonzero(extra),
                                 0 if aside is None else np.count_nonzero(explained & aside),
                                 0 if aside is None else np.count_nonzero(extra & aside))
        tallies.flags.writeable = False
        self._tallied[each] = tallies
        return tallies

    @cached_property
    def enclosed(self) -> list:
        """Per view, the silhouette's convex hull (the image's size): the table a view shows there, with
        the object on either side of it, is seen through the object (a dumbbell's gap between its
        weights); outside it a silhouette that stops short may as well have left a face out."""
        hulls = []
        for silhouette in self.silhouettes:
            hull = np.zeros(silhouette.shape, np.uint8)
            pixels = cv2.findNonZero(silhouette)
            if pixels is not None:
                cv2.fillConvexPoly(hull, cv2.convexHull(pixels), 1)
            hulls.append(hull.view(bool))
        return hulls

    def carved_ious(self, before, after) -> np.ndarray:
        """(V,) each view's IoU of ``before`` with what ``after`` covers of what the view shows empty
        within the silhouette's convex hull (:attr:`enclosed`) instead of its own, and outside it the
        more of the two: how much ``after`` explains the more by covering less of the table seen through
        the object (what it leaves out beyond the silhouette's hull a face left out explains as well)."""
        carved = np.zeros(len(self.cameras))
        explained = self._tallies(before, each=False)[:, 0, 1]
        extras = []
        for parts in (before, after):
            counts = []
            for (object_pixels, covers, (x0, y0)), enclosed in zip(self.drawn(parts), self.enclosed):
                if object_pixels is None:
                    counts.append((0, 0))
                    continue
                within = enclosed[y0:y0 + object_pixels.shape[0], x0:x0 + object_pixels.shape[1]]
                extra = np.any(np.stack(covers), axis=0) & ~object_pixels
                counts.append((int(np.count_nonzero(extra & within)), int(np.count_nonzero(extra & ~within))))
            extras.append(np.array(counts, float))
        (_, before_beyond), (after_within, after_beyond) = (extra.T for extra in extras)
        union = self._tallies(after, each=False)[:, 0, 0] + after_within + np.maximum(before_beyond, after_beyond)
        np.divide(explained, union, out=carved, where=union > 0)
        return carved

    def unexplained(self, parts, band: float = _EDGE_BAND_PX) -> list[float]:
        """As :func:`unexplained_shares`."""
        shares = []
        for object_pixels, covers, _ in self.drawn(parts):
            if object_pixels is None:
                shares.append(1.0)
                continue
            covered = np.any(np.stack(covers), axis=0)
            union = int(np.count_nonzero(object_pixels | covered))
            missed = object_pixels & ~covered
            extra = covered & ~object_pixels
            far = 0
            for mask, other in ((missed, covered), (extra, object_pixels)):
                if mask.any():
                    distance = cv2.distanceTransform((~other).view(np.uint8), cv2.DIST_L2, 3)
                    far += int(np.count_nonzero(distance[mask] > band))
            shares.append(far / union if union else 1.0)
        return shares


def _tally_iou(tallies: np.ndarray) -> np.ndarray:
    """IoUs of tallies (as :meth:`_Rasters._tallies`, last axis)."""
    area, explained, extra = tallies[..., 0], tallies[..., 1], tallies[..., 2]
    union = area + extra
    return np.divide(explained, union, out=np.zeros_like(union), where=union > 0)


def _as_on_unsure(tallies: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``tallies`` with what they cover of the unsure pixels replaced by what ``reference`` covers there."""
    changed = tallies.copy()
    changed[..., 1] += reference[..., 3] - tallies[..., 3]
    changed[..., 2] += reference[..., 4] - tallies[..., 4]
    changed[..., 3:] = reference[..., 3:]
    return changed


def _views_to_pay(views: int) -> int:
    return min(_VIEWS_TO_PAY, views)


def explains_more(gains) -> bool:
    """Whether a model explains the silhouettes more than another as more parts must to pay for
    themselves, ``gains`` (V,) its IoU less the other's per view: :func:`_paid` and :func:`_loses_nowhere`."""
    return _paid(gains) and _loses_nowhere(gains)


def _paid(gains) -> bool:
    """Whether the gains (V,) reach ``PART_GAIN`` in two views (in every view, with fewer)."""
    return bool(_views_paid(gains) >= _views_to_pay(len(gains)))


def _loses_nowhere(gains) -> bool:
    """Whether in no view the gains (V,) are a loss of ``PART_GAIN``: what a model explains the more in some
    views at as much loss in another moves one view's error (a shadow taken in, a face left out) to another,
    and which view is wrong no part can say."""
    return bool(float(np.min(gains)) > -PART_GAIN)


def _views_paid(gains) -> np.ndarray:
    """(...,) in how many views the gains (last axis) reach ``PART_GAIN``."""
    return np.sum(np.asarray(gains) >= PART_GAIN, axis=-1)


def _could_pay(shares) -> bool:
    """Whether a new part could pay, or a union carve away what one view shows empty: either can
    explain a view's unexplained share at most."""
    shares = np.asarray(shares)
    return _paid(shares) or float(np.max(shares)) >= _CARVED_GAIN


def _pays(gains: np.ndarray) -> np.ndarray:
    """(P,) how many views each part pays in, plus its mean gain (a tie-break below 1); ``gains``
    (P, V) as :meth:`_Rasters.gains`."""
    return _views_paid(gains) + np.clip(gains.mean(axis=1), 0.0, 0.999)


def _volume(parts) -> float:
    return float(sum(part.volume for part in parts))


def fit_parts(single: Superquadric, points, cameras, silhouettes, boxes, *, ious=None,
              support_plane=None, max_parts: int = MAX_PARTS, single_evaluations: int | None = None,
              unsure: Sequence | Callable[[], Sequence] | None = None,
              reach: float | None = None) -> PartsFit:
    """The union of superquadrics that explains the silhouettes, from the one-superquadric fit.

    Parameters
    ----------
    single : Superquadric
        The one-superquadric silhouette fit.
    points : (N, 3) array_like
        The carved hull's points.
    cameras : sequence of Camera
        Ideal pinhole cameras of the views.
    silhouettes : sequence of (H, W) ndarray of uint8
        The ideal-pinhole silhouettes.
    boxes : sequence of (4,) tuple of int
        Their bounding boxes.
    ious : sequence of float, optional
        ``single``'s silhouette IoU per view, if already known.
    support_plane : (4,) array_like, optional
        ``[nx, ny, nz, d]`` with a unit normal: the object stands where ``n . x + d >= 0``.
    max_parts : int
        At most this many parts (1 to ``MAX_PARTS``).
    single_evaluations : int, optional
        The evaluations of the cost the one superquadric took: proposals left behind by a round go
        on only while the search has taken fewer than ``_BUDGET`` times as many (each part of a
        union counted); without it, while they leave the silhouettes unexplained.
    unsure : sequence of ((H, W) ndarray of bool or None), or a function returning one, optional
        Per view, the pixels whose side the segmentation cannot confirm
        (:func:`core_cy.auto_segment.unsure_pixels`); None for a view whose silhouette is sure (a
        mask given). A part must pay with them set aside as well as with them as they are. A
        function is called only if a part could pay (most objects are one part, decided before).
    reach : float, optional
        How far the object may reach from its centre: no part's half-size grows past it
        (:func:`core_cy.silhouette_fit.fit_to_silhouettes`).

    Returns
    -------
    PartsFit
        ``(single,)`` when no part could pay for itself.
    """
    rasters = _Rasters(cameras, silhouettes, boxes, unsure)
    if ious is None:
        ious, _ = rasters.ious((single,))
    ious = list(ious)
    # A view's unexplained share is at most its miss, 1 - IoU: where even that cannot pay, the
    # pixels need not be looked at.
    if (max_parts < 2 or not _could_pay(1.0 - np.asarray(ious))
            or not _could_pay(rasters.unexplained((single,)))):
        return PartsFit((single,), ious)
    points = np.asarray(points, dtype=np.float64)
    plane = None if support_plane is None else np.asarray(support_plane, dtype=np.float64)
    edges = [edge_samples(silhouette_outline(silhouette), silhouette, None, count=_PART_SAMPLES)
             for silhouette in silhouettes]
    fitter = _Fitter(cameras, edges, single.T_world_object[:3, 3], support_plane, 1.0, reach=reach)
    # Going on with a round's proposals left behind (while its winner leaves the silhouettes
    # unexplained) is the search's most open-ended work: it stops once the search has spent
    # _BUDGET times what the one superquadric cost. The next round, which may explain them with one
    # more part, is not bounded so.
    budget = np.inf if single_evaluations is None else _BUDGET * single_evaluations

    def within() -> bool:
        return fitter.evaluations < budget
    current: tuple[Superquadric, ...] = (single,)
    # A union of every part paying that explains more in one view but not yet in two (a dumbbell's
    # two weights without the bar between them) goes one round on before it is given up.
    trial: tuple[Superquadric, ...] | None = None
    bounded = 0
    while bounded < MAX_PARTS:
        bounded += 1
        base = current if trial is None else trial
        if len(base) >= min(max_parts, MAX_PARTS):
            break
        if bounded > 1 and not _could_pay(rasters.unexplained(base)):
            break
        # Which part explains each hull point best, for the splits and the waists alike.
        owner = _owners(base, points)
        proposals = _splits(base, points, plane, owner) + _additions(base, points, rasters, plane)
        box = None if len(base) > 1 or plane is None else (upright_box(points, plane[:3]),)
        if box is not None:
            # The one superquadric may sit in a bad minimum of its own (a T is no superquadric at all):
            # also split the box of the whole hull, standing on the table.
            box_owner = np.zeros(len(points), np.intp)  # one part owns every point
            proposals += _splits(box, points, plane, box_owner)
        if len(base) == 1:
            # Two ends and the thinner part between them (a dumbbell's bar) are no split in two.
            proposals += _waists(base, points, owner)
            if box is not None:
                proposals += _waists(box, points, box_owner)
        if not proposals:
            break
        winner = fitter.best_of(proposals, _ITERATIONS, finalists=1, explained_px=_EXPLAINED_PX, within=within)
        candidate, candidate_ious = _paying(fitter.result(winner).parts, fitter, rasters, plane)
        verdict = _verdict(candidate, candidate_ious, current, ious, base, trial is None, fitter, rasters)
        if verdict is None:
            # The screening ranks the proposals by their cost after a few steps, a guess at where they
            # end: the winner may be a start already at its minimum, its extra part paying for nothing,
            # while others still on their way down end lower, and pay. So, the winner given up, the
            # proposals left behind go on to their end in the order of their cost (while within the
            # budget), and of those whose parts pay, the one that ends lowest is kept (the first to
            # pay may only explain a view's wrong silhouette the better).
            chosen = None
            for descent in sorted((descent for descent in fitter.descents
                                   if descent is not winner and np.isfinite(descent.cost)),
                                  key=lambda descent: descent.cost):
                if not within():
                    break
                other, other_ious = _paying(fitter.result(descent.run(_ITERATIONS)).parts, fitter, rasters, plane)
                other_verdict = _verdict(other, other_ious, current, ious, base, trial is None, fitter, rasters)
                if other_verdict is None:
                    continue
                rank = (other_verdict != "kept", fitter.descent(other).cost)
                if chosen is None or rank < chosen[0]:
                    chosen = (rank, other, other_ious, other_verdict)
            if chosen is not None:
                _, candidate, candidate_ious, verdict = chosen
        if verdict == "kept":
            current, ious, trial = candidate, candidate_ious, None
        elif verdict == "trial":
            trial = candidate
        else:
            break
    if len(current) > 1 and plane is not None:
        current, ious = _taken_down(current, fitter, plane, ious, rasters)
    if current != (single,) and any(_sheet(part, rasters.cameras) for part in current):
        current, ious = _bodies(current, single, fitter, rasters, plane)
    if len(current) > 1 and plane is not None and rasters.any_unsure:
        # A part that no view sees rise off the table is the shadow the silhouettes took in: it kept
        # the shadow off the other parts' outlines, and is no part of the object.
        seen = tuple(part for part in current if not _flat_on_table(part, rasters.cameras, plane))
        if seen and len(seen) < len(current):
            current, ious = seen, rasters.ious(seen)[0]
    if len(current) > 1:
        current, ious = _turned_where_better(current, ious, fitter, rasters)
    return PartsFit(current, ious, fitter.evaluations)


def _turned_where_better(parts, ious, fitter: _Fitter,
                         rasters: _Rasters) -> tuple[tuple[Superquadric, ...], list[float]]:
    """The union with each part in turn tried with another of its axes as z (:meth:`_Fitter.turned`), as the
    one superquadric's fit tries it: a part's z axis is the odd one out, its profile with its own exponent, and
    a drill's barrel fitted along x as a square bar becomes the round cylinder along z that it is only by that
    jump. A turn goes a few steps on and, where the union then fits the samples better, to its end; it is kept
    where it explains the silhouettes more over the views and no worse in any (:func:`_loses_nowhere`), on
    either reading of them: with doubtful silhouettes (a banana's shadow taken in) a turned part may run nearer
    the samples by following the doubt. Not where the outlines already run through the samples to within the
    edges' noise."""
    best = fitter.descent(parts)
    for k in range(len(parts)):
        if fitter.rms(best.cost) <= _NOISE_PX:
            break
        for other in fitter.turned(parts, k):
            if not other.cost < best.cost:
                continue
            other.run(_ITERATIONS)
            candidate = fitter.result(other).parts
            candidate_ious = rasters.ious(candidate)[0]
            gains = (rasters.gains(candidate, parts) if rasters.any_unsure
                     else np.asarray(candidate_ious) - np.asarray(ious))
            if float(np.sum(gains)) > 0.0 and _loses_nowhere(gains):
                best, parts, ious = other, candidate, candidate_ious
                break
    return parts, ious


def _bodies(parts, single: Superquadric, fitter: _Fitter, rasters: _Rasters, plane):
    """The union with its sheets (:func:`_sheet`) made bodies or dropped. A sheet is the outline of a
    body seen from one side only: a rod as thick as it is wide (a dumbbell's bar, which the views see
    from above, drawn flat), kept if every part then pays; else a sheet floating over the table is the
    face of a body standing on it (resting on a face, taken down to the table), any other sheet no body
    at all; the parts that then do not pay dropped; ``single`` if nothing is left."""
    rods = tuple(_as_thick_as_wide(part) if _sheet(part, rasters.cameras) else part for part in parts)
    paying, ious = _paying(rods, fitter, rasters, plane)
    if len(paying) == len(rods):
        return paying, ious
    bodies = []
    for part in parts:
        if not _sheet(part, rasters.cameras):
            bodies.append(part)
        elif plane is not None:
            grounded = _grounded(resting_on(part, plane[:3])[0], plane)
            if grounded is not None:
                bodies.append(grounded)
    if not bodies:
        return (single,), rasters.ious((single,))[0]
    return _paying(tuple(bodies), fitter, rasters, plane)


def _as_thick_as_wide(part: Superquadric) -> Superquadric:
    """The part with its thinnest semi-axis made as long as its middle one."""
    size = part.size.copy()
    size[int(np.argmin(size))] = np.sort(size)[1]
    return Superquadric(size, part.shape, part.T_world_object)


def _sheet(part: Superquadric, cameras) -> bool:
    """Whether no view sees the part's thickness (its extent along its thinnest axis, through its
    centre) span more than the edges' noise: to the cameras it is a sheet, no body. Where the views
    see a body, a union of sheets explains a segmentation's errors (a face and a shadow, each drawn
    flat), not the object."""
    R, centre = part.T_world_object[:3, :3], part.T_world_object[:3, 3]
    k = int(np.argmin(part.size))
    ends = np.stack([centre - part.size[k] * R[:, k], centre + part.size[k] * R[:, k]])
    for camera in cameras:
        (near, far), _ = camera.project(ends)
        if np.hypot(*(far - near)) > _EDGE_BAND_PX:
            return False
    return True


def _flat_on_table(part: Superquadric, cameras, plane: np.ndarray) -> bool:
    """Whether no view sees the part's top rise off the plane by more than the edges' noise: to the
    cameras it is paint on the table, or a shadow."""
    R, centre = part.T_world_object[:3, :3], part.T_world_object[:3, 3]
    normal = plane[:3]
    height = float(normal @ centre + plane[3])
    foot = centre - height * normal
    top = foot + (height + float(np.abs(normal @ R) @ part.size)) * normal
    for camera in cameras:
        (foot_uv, top_uv), _ = camera.project(np.stack([foot, top]))
        if np.hypot(*(top_uv - foot_uv)) > _EDGE_BAND_PX:
            return False
    return True


def _verdict(candidate, candidate_ious, current, ious, base, may_trial: bool, fitter: _Fitter,
             rasters: _Rasters) -> str | None:
    """Whether a round's union, its parts all paying, is kept ("kept"), goes one round on ("trial")
    or is given up (None), against the model before it, ``current`` with its IoUs ``ious``."""
    # More parts must explain more: as much as one part must pay, in as many views. A union of no
    # more parts that explains as much more, its outlines nearer the edges too, is a better minimum found on the way
    # (not the one superquadric: that is the single fit's, from its own starts).
    gains = np.asarray(candidate_ious) - np.asarray(ious)
    if rasters.any_unsure:
        gains = rasters.gains(candidate, current)
    gained = int(_views_paid(gains))
    # A union that explains more in one view only, by covering less of what that view shows empty,
    # carves it away (a dumbbell's weights without the gap between them, which the other views see
    # hidden behind them); one that explains more there by covering more adds volume seen in one
    # view, its depth unseen, perhaps in the wrong place (a mug's handle behind its body; a thin slab
    # held edge-on to the other views, on a shadow that one view's silhouette took in): that pays in
    # two views. Less volume is not enough: a thin part lies in the views' blind spot. Nor is covering
    # less beyond the silhouette's convex hull (:attr:`_Rasters.enclosed`): slabs round a column that
    # leave out the face one view's silhouette left out explain a segmentation's error, not a gap.
    pays = _paid(gains)
    if not pays and float(np.max(gains)) >= _CARVED_GAIN and _volume(candidate) <= _volume(current):
        carved = rasters.carved_ious(current, candidate) - np.asarray(ious)
        pays = float(np.max(carved)) >= _CARVED_GAIN
    if pays and len(candidate) <= len(current):
        pays = len(candidate) > 1 and fitter.descent(candidate).cost < fitter.descent(current).cost
    # More parts must lose nowhere (:func:`_loses_nowhere`), on either reading of the silhouettes
    # (``gains``, the less of the two): as :func:`explains_more`, with carving in place of two views paid.
    if pays and (len(candidate) <= len(current) or _loses_nowhere(gains)):
        return "kept"
    if may_trial and len(candidate) > len(base) and gained >= 1:
        return "trial"  # it explains more in one view at least: not just a part cut in two
    return None


def _taken_down(parts, fitter: _Fitter, plane: np.ndarray, ious, rasters: _Rasters):
    """The union with each part that floats (what holds it up hidden behind it in every view), set
    resting on a face, taken down to the table (through the parts it stands on, whose volume it then
    shares), kept where that explains the silhouettes about as well."""
    best = fitter.descent(parts)
    for k, part in enumerate(parts):
        grounded = _grounded(resting_on(part, plane[:3])[0], plane)
        if grounded is not None:
            other = fitter.descent(parts[:k] + (grounded,) + parts[k + 1:]).run(_GROUNDED_STEPS)
            if other.cost <= _GROUNDED_COST * best.cost:
                best, parts = other, other.problem.parts(other.x)
    if best.iterations == 0:
        return parts, ious
    return parts, rasters.ious(parts)[0]


def _grounded(part: Superquadric, plane: np.ndarray) -> Superquadric | None:
    """The part, resting on a face or a side, stretched down to the plane with its top kept;
    None if no axis of it is upright or it already reaches the plane."""
    R, centre = part.T_world_object[:3, :3], part.T_world_object[:3, 3]
    normal = plane[:3]
    k = int(np.argmax(np.abs(normal @ R)))
    if abs(float(normal @ R[:, k])) < np.cos(np.radians(_MIN_TILT)):
        return None
    height = float(normal @ centre + plane[3])
    top, bottom = height + part.size[k], height - part.size[k]
    if bottom < _FLOOR * part.size[k]:
        return None
    T = part.T_world_object.copy()
    T[:3, 3] = centre - (height - top / 2) * normal
    size = part.size.copy()
    size[k] = top / 2
    return Superquadric(size, part.shape, T)


def _paying(parts, fitter: _Fitter, rasters: _Rasters, plane) -> tuple[tuple[Superquadric, ...], list[float]]:
    """The parts less those that do not pay (the least useful dropped first, the rest refined). A part
    flat on the table (``plane``; :func:`_flat_on_table`) pays on the silhouettes as they are: what it
    explains is the shadow they took in, which their unsure pixels set aside."""
    parts = tuple(parts)
    while True:
        ious, without = rasters.ious(parts)
        if len(parts) == 1:
            return parts, ious
        gains = np.asarray(ious)[None, :] - without
        if rasters.any_unsure:
            flat = [plane is not None and _flat_on_table(part, rasters.cameras, plane) for part in parts]
            gains = np.where(np.array(flat)[:, None], gains, rasters.gains(parts))
        pays = _pays(gains)
        weakest = int(np.argmin(pays))
        if pays[weakest] >= _views_to_pay(len(rasters.cameras)):
            return parts, ious
        rest = parts[:weakest] + parts[weakest + 1:]
        parts = fitter.result(fitter.descent(rest).run(_ITERATIONS)).parts


def _ratios(parts, points: np.ndarray) -> np.ndarray:
    """(P, N) how far out each point lies along its ray from each part's centre (1 on the surface)."""
    return np.stack([np.maximum(inside_outside(points, part), 1e-300) ** (part.shape[0] / 2) for part in parts])


def _box_start(points: np.ndarray, R: np.ndarray, floor: np.ndarray) -> Superquadric:
    """The superquadric filling the box of ``points`` in the frame R (columns: axes)."""
    local = points @ R
    low, high = local.min(axis=0), local.max(axis=0)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, R @ ((low + high) / 2)
    return Superquadric(np.maximum((high - low) / 2, floor), _START_SHAPE, T)


def _owners(parts, points: np.ndarray) -> np.ndarray:
    """(N,) which part explains each point best (the one it lies deepest in)."""
    if len(parts) == 1:
        return np.zeros(len(points), np.intp)
    return np.argmin(_ratios(parts, points), axis=0)


def _splits(parts, points: np.ndarray, plane, owner: np.ndarray) -> list[tuple[Superquadric, ...]]:
    """Each part split in two by the plane through its centre across each of its axes (on a
    table, each half's start upright: a part rests on a face); ``owner`` as :func:`_owners`."""
    if len(points) < 2 * _MIN_GROUP:
        return []
    proposals = []
    for k, part in enumerate(parts):
        mine = points[owner == k]
        R, centre = part.T_world_object[:3, :3], part.T_world_object[:3, 3]
        side = (mine - centre) @ R
        floor = _FLOOR * part.size
        frame = R if plane is None else _upright(R, plane[:3])
        for axis in range(3):
            halves = [mine[side[:, axis] >= 0], mine[side[:, axis] < 0]]
            if min(len(half) for half in halves) < _MIN_GROUP:
                continue
            proposals.append(parts[:k] + parts[k + 1:] + tuple(_box_start(half, frame, floor) for half in halves))
    return proposals


def _waists(parts, points: np.ndarray, owner: np.ndarray) -> list[tuple[Superquadric, ...]]:
    """Each part cut in three where it narrows along its longest axis (parts meet at a waist: a
    dumbbell's bar between its weights): the hull points it explains best, in slabs along the
    axis, each slab's width the least of its extents across the axis (the views carve the hull
    narrow across their rays); the waist is the run of slabs about the narrowest that are nearer
    its width than the widest's, at most ``_WAIST`` of it. The pieces before, within and after the
    waist each give a part whose z axis is that axis; a narrowing at an end is left to the splits.
    ``owner`` as :func:`_owners`."""
    if len(points) < 2 * _MIN_GROUP:
        return []
    angles = np.pi * np.arange(_WIDTH_DIRECTIONS) / _WIDTH_DIRECTIONS
    directions = np.stack([np.cos(angles), np.sin(angles)])
    proposals = []
    for k, part in enumerate(parts):
        mine = points[owner == k]
        axis = int(np.argmax(part.size))
        order = [(axis + 1) % 3, (axis + 2) % 3, axis]
        frame = part.T_world_object[:3, :3][:, order]
        local = mine @ frame
        along = local[:, 2]
        edges = np.linspace(along.min(), along.max(), _SLABS + 1)
        slab = np.clip(np.searchsorted(edges, along, side="right") - 1, 0, _SLABS - 1)
        width = np.full(_SLABS, np.nan)
        for i in range(_SLABS):
            across = local[slab == i, :2] @ directions
            if len(across) >= 3:
                width[i] = float(np.min(across.max(axis=0) - across.min(axis=0)))
        if np.count_nonzero(np.isfinite(width)) < 3:
            continue
        narrowest = int(np.nanargmin(width))
        low, high = float(np.nanmin(width)), float(np.nanmax(width))
        if low > _WAIST * high:
            continue
        inside = ~(width > (low + high) / 2)  # nan (an empty slab) counts as narrow
        first = last = narrowest
        while first > 0 and inside[first - 1]:
            first -= 1
        while last < _SLABS - 1 and inside[last + 1]:
            last += 1
        cuts = [edges[first], edges[last + 1]]
        pieces = [mine[along < cuts[0]], mine[(along >= cuts[0]) & (along < cuts[1])], mine[along >= cuts[1]]]
        if min(len(piece) for piece in pieces) < _MIN_GROUP:
            continue  # narrowing at an end: a split in two proposes that
        floor = _FLOOR * part.size[order]
        proposals.append(parts[:k] + parts[k + 1:] + tuple(_box_start(piece, frame, floor) for piece in pieces))
    return proposals


def _additions(parts, points: np.ndarray, rasters: _Rasters, plane) -> list[tuple[Superquadric, ...]]:
    """The union and one more part on each of the largest groups of unexplained hull points."""
    if len(points) < _MIN_GROUP:
        return []
    outside = np.zeros(len(points), np.intp)
    for camera, (object_pixels, covers, (x0, y0)) in zip(rasters.cameras, rasters.drawn(parts)):
        if object_pixels is None:
            continue
        covered = np.any(np.stack(covers), axis=0).astype(np.uint8)
        # Distance (px) of every pixel of the box from the union's outline, outside it.
        distance = cv2.distanceTransform(1 - covered, cv2.DIST_L2, 3)
        uv, depth = camera.project(points)
        column = np.round(uv[:, 0] - x0).astype(np.intp)
        row = np.round(uv[:, 1] - y0).astype(np.intp)
        inside = (depth > 0) & (column >= 0) & (row >= 0) & (column < covered.shape[1]) & (row < covered.shape[0])
        far = np.ones(len(points), bool)
        far[inside] = distance[row[inside], column[inside]] > _UNEXPLAINED_PX
        outside += far
    return _grouped(parts, points[outside >= _views_to_pay(len(rasters.cameras))], plane)


def _grouped(parts, unexplained: np.ndarray, plane) -> list[tuple[Superquadric, ...]]:
    """The union and one more part on each of the largest neighbourhoods of ``unexplained``."""
    if len(unexplained) < _MIN_GROUP:
        return []
    # Neighbourhoods: points within a few of their typical spacing of each other.
    tree = cKDTree(unexplained)
    nearest, _ = tree.query(unexplained, k=2)
    reach = 2.5 * float(np.median(nearest[:, 1]))
    pairs = tree.query_pairs(reach, output_type="ndarray")
    links = csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(unexplained),) * 2)
    count, label = connected_components(links, directed=False)
    sizes = np.bincount(label, minlength=count)
    floor = _FLOOR * np.mean([part.size for part in parts], axis=0).min() * np.ones(3)
    proposals = []
    for group in np.argsort(sizes)[::-1][:_GROUPS]:
        if sizes[group] < _MIN_GROUP:
            break
        members = unexplained[label == group]
        _, vectors = np.linalg.eigh(np.cov((members - members.mean(axis=0)).T))
        R = vectors if np.linalg.det(vectors) > 0 else vectors * [-1, 1, 1]
        if plane is None:
            proposals.append(tuple(parts) + (_box_start(members, R, floor),))
            continue
        # On a table a part rests on a face: its frame upright (a strong start, not a rule), and,
        # since what lies below it may hide behind the parts in front, also reaching down to the table.
        R = _upright(R, plane[:3])
        start = _box_start(members, R, floor)
        proposals.append(tuple(parts) + (start,))
        height = members @ plane[:3] + plane[3]
        down = _box_start(np.vstack([members, members - height[:, None] * plane[:3]]), R, floor)
        # A group that reaches the table already gives that same start again: its descent would be the
        # first one's, step for step.
        if not (np.array_equal(down.size, start.size) and np.array_equal(down.T_world_object, start.T_world_object)):
            proposals.append(tuple(parts) + (down,))
    return proposals


def _upright(R: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The frame R turned so that its axis nearest ``normal`` is ``normal`` (as its z axis)."""
    k = int(np.argmax(np.abs(normal @ R)))
    first = R[:, (k + 1) % 3] - (R[:, (k + 1) % 3] @ normal) * normal
    first /= np.linalg.norm(first)
    second = normal[[1, 2, 0]] * first[[2, 0, 1]] - normal[[2, 0, 1]] * first[[1, 2, 0]]  # normal x first
    return np.stack([first, second, normal], axis=1)
