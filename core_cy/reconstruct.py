"""The whole algorithm: views in, superquadric out (DESIGN.md §1).

decode -> segment -> edge samples -> enclosing sphere -> carve -> support plane
-> starts (the point fit's search) -> silhouette fit -> quality
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from .camera import Camera, undistort_mask
from .carve import carve, check_support_plane, clip_to_plane, lift_above_plane, occupancy
from .edges import about_samples, edge_samples, samples_near
from .errors import CoreError, FitError, GeometryError, ImageError, SilhouetteError
from .images import checked_size
from .model_check import MIN_VIEW_IOU
from .auto_segment import auto_silhouettes, unsure_pixels
from .parts import MAX_PARTS, explains_more, fit_parts, union_ious
from .quality import outline_distances, radial_residual
from .segment import AUTO, Segmentation, mask_with_outline, segment_with_outline
from .silhouette_fit import _NOISE_PX, fit_to_silhouettes
from .sphere import CHECK_THE_POSES, enclosing_sphere, farthest_reach, fibonacci_sphere
from .superquadric import Superquadric, fit_superquadric, resting_on, start_superquadrics, upright_box

__all__ = ["View", "Options", "Reconstruction", "decode_image", "reconstruct"]

_JPEG_START, _JPEG_END = b"\xff\xd8", b"\xff\xd9"
# A view whose silhouette IoU stays below this clearly disagrees with the one-superquadric fit:
# the other starts' descents are judged by their agreement, and the best goes on (at most this many steps).
_DISAGREE = 0.8
_RESTART_ITERATIONS = 20
# An edge sample of auto's farther than this (px) from the one superquadric's outline, six times the
# edges' own noise, is one that the views together contradict.
_CONTRADICTED_PX = 6 * _NOISE_PX
_RESTING_TILT = 30.0  # degrees


@dataclass(frozen=True, eq=False)
class View:
    """One photograph of the object.

    ``image`` is a BGR uint8 array or encoded bytes (JPEG, PNG); ``mask`` an
    8-bit array or encoded bytes, nonzero = object. With a mask the image is
    not needed (and not decoded). ``background``, a BGR array or encoded
    bytes of the image's size: the empty workspace from the same pose, which
    the ``auto`` segmentation uses when it is given.
    """

    camera: Camera
    image: np.ndarray | bytes | None = None
    mask: np.ndarray | bytes | None = None
    background: np.ndarray | bytes | None = None


@dataclass(frozen=True)
class Options:
    """Tuning of the algorithm; the defaults are what the benchmark measured best.

    Parameters
    ----------
    n_points : int
        Points on the starting sphere (one radius each).
    inside_weight : float
        Weight of residuals of points inside the superquadric; 1 is plain
        Jaklic. Hull points only err outward, so inside ones weigh more.
    outside_loss : {"cauchy", "squared"}
        Loss on the residuals of points outside; "squared" with
        ``inside_weight=1`` is plain Jaklic.
    cauchy_scale : float
        Scale of the robust loss on points outside, in units of the cloud's
        RMS radius.
    radius_margin : float
        Starting sphere radius over the largest silhouette extent.
    fit_points : int
        At most this many points go into the fit (evenly strided).
    silhouette_fit : bool
        Fit to the silhouettes' edges (DESIGN.md §1, step 7), starting from
        the point fit's candidate starts. Off, the inside-weighted point fit
        (``inside_weight``, ``outside_loss``, ``cauchy_scale``, which apply
        only then) is the result, as before the silhouette fit existed.
    edge_samples : int
        Edge samples per view for the silhouette fit.
    max_parts : int
        The model may be a union of up to this many superquadrics (DESIGN.md §1.11;
        with the silhouette fit only); 1 keeps it one superquadric.
    """

    n_points: int = 1000
    inside_weight: float = 10.0
    outside_loss: str = "cauchy"
    cauchy_scale: float = 0.1
    radius_margin: float = 1.25
    fit_points: int = 250
    silhouette_fit: bool = True
    edge_samples: int = 32
    max_parts: int = MAX_PARTS

    def __post_init__(self) -> None:
        if self.n_points < 50:
            raise ValueError(f"n_points must be >= 50, got {self.n_points}")
        if self.outside_loss not in ("cauchy", "squared"):
            raise ValueError(f"outside_loss must be 'cauchy' or 'squared', got {self.outside_loss!r}")
        if not self.inside_weight > 0 or not self.cauchy_scale > 0:
            raise ValueError("inside_weight and cauchy_scale must be positive")
        if not self.radius_margin >= 1:
            raise ValueError(f"radius_margin must be >= 1, got {self.radius_margin}")
        if self.edge_samples < 4:
            raise ValueError(f"edge_samples must be >= 4, got {self.edge_samples}")
        if not 1 <= self.max_parts <= MAX_PARTS:
            raise ValueError(f"max_parts must be 1 to {MAX_PARTS}, got {self.max_parts}")


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """What :func:`reconstruct` found.

    ``points`` (N, 3) is the carved cloud (unseen directions, and those with no edge, dropped);
    ``silhouettes`` the ideal-pinhole silhouettes the hull was carved from;
    ``silhouette_iou`` how well the model's projection (the union of its parts) covers each;
    ``residual`` the points' RMS radial distance from the superquadric's surface, in the bundle's units;
    ``timings_ms`` the wall time of each stage and the total;
    ``parts`` the model (DESIGN.md §1.11): the object is their union, one part for an object
    that is one superquadric. ``superquadric`` is the one superquadric closest to the whole.
    ``evaluations`` counts the silhouette fits' evaluations of their cost, each part of a union
    counted: ``"fit"`` the one superquadric's, ``"parts"`` the search's beyond it. Their work, which
    unlike their time does not depend on the machine (not part of :meth:`to_dict`).
    ``backgrounds_set_aside``: None, or why the views' pictures of the empty workspace were set aside
    (what the reconstruction with them raised; :func:`reconstruct`), the model then found from the images
    alone.
    """

    superquadric: Superquadric
    centre: np.ndarray
    radius: float
    points: np.ndarray
    silhouettes: list[np.ndarray]
    silhouette_iou: list[float]
    residual: float
    timings_ms: dict[str, float] = field(default_factory=dict)
    parts: tuple[Superquadric, ...] = ()
    evaluations: dict[str, int] = field(default_factory=dict)
    backgrounds_set_aside: str | None = None

    def __post_init__(self) -> None:
        if not self.parts:
            object.__setattr__(self, "parts", (self.superquadric,))

    def to_dict(self, *, points: bool = False) -> dict:
        """The JSON result of DESIGN.md §3 (without the ``scan`` key)."""
        result = {
            "superquadric": self.superquadric.to_dict(),
            "parts": [part.to_dict() for part in self.parts],
            "timings_ms": {stage: round(ms, 3) for stage, ms in self.timings_ms.items()},
            "silhouette_iou": [round(iou, 4) for iou in self.silhouette_iou],
            "residual": self.residual,
        }
        if self.backgrounds_set_aside is not None:
            result["backgrounds_set_aside"] = self.backgrounds_set_aside
        if points:
            result["points"] = self.points.tolist()
        return result


def decode_image(data: bytes, *, grayscale: bool = False, view: int | None = None) -> np.ndarray:
    """Decode an encoded PNG or JPEG with OpenCV, its size checked from its header first.

    The pixels are taken as the sensor gave them: an EXIF orientation is not
    applied, since K describes the sensor's rows and columns.

    Raises
    ------
    ImageError
        If the bytes are not a decodable PNG or JPEG, declare more than
        ``core_cy.images.MAX_IMAGE_PIXELS``, or a JPEG is truncated (OpenCV
        would silently return a half-grey image).
    """
    what = "the mask" if grayscale else "the image"
    if data.startswith(_JPEG_START) and not data.rstrip(b"\x00").endswith(_JPEG_END):
        raise ImageError("the JPEG is truncated (no end-of-image marker)", view=view)
    checked_size(data, what=what, view=view)
    flags = (cv2.IMREAD_GRAYSCALE if grayscale else cv2.IMREAD_COLOR) | cv2.IMREAD_IGNORE_ORIENTATION
    image = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if image is None:
        raise ImageError(f"{what} is not a decodable image ({len(data)} bytes)", view=view)
    return image


def _unsure(view: View, image: np.ndarray, silhouette: np.ndarray, samples: np.ndarray | None = None) -> np.ndarray:
    """The pixels of auto's ``silhouette`` of ``view`` that its colours cannot confirm
    (:func:`core_cy.auto_segment.unsure_pixels`), on the ideal pinhole camera's grid as the silhouettes
    the fit sees; with ``samples`` (edge samples on that grid), only those that judge them need be
    asked about (without lens distortion, where the grids are one)."""
    if view.camera.dist is None:
        return unsure_pixels(image, silhouette, None if samples is None else about_samples(samples, silhouette.shape))
    doubtful = unsure_pixels(image, silhouette)
    return undistort_mask(np.where(doubtful, 255, 0).astype(np.uint8), view.camera) > 0


def _decoded(index: int, view: View) -> tuple[np.ndarray, bool]:
    """The view's mask if it has one (True), else its image (False), as an array."""
    is_mask = view.mask is not None
    data = view.mask if is_mask else view.image
    if data is None:
        raise ImageError("the view has neither an image nor a mask", view=index)
    if isinstance(data, (bytes, bytearray, memoryview)):
        data = decode_image(bytes(data), grayscale=is_mask, view=index)
    return data, is_mask


def _background(index: int, view: View) -> np.ndarray | None:
    """The view's background picture as an array, or None."""
    data = view.background
    if isinstance(data, (bytes, bytearray, memoryview)):
        try:
            return decode_image(bytes(data), view=index)
        except ImageError as exc:
            raise ImageError(f"the background: {str(exc).removeprefix(f'view {index}: ')}", view=index) from None
    return data


def reconstruct(views, *, segmentation: Segmentation = AUTO, support_plane=None,
                options: Options = Options()) -> Reconstruction:
    """Reconstruct a superquadric from two or more calibrated views.

    Parameters
    ----------
    views : sequence of View
    segmentation : Segmentation
        How to find the object in views that come without a mask (default:
        ``auto``, all such views together).
    support_plane : (4,) array_like, optional
        ``[nx, ny, nz, d]``: the object stands where ``n . x + d >= 0``.
    options : Options

    Returns
    -------
    Reconstruction

    Raises
    ------
    CoreError
        A subclass naming the view and what is wrong with it; or, where the
        silhouettes ``auto`` found contradict each other (the model agrees
        with one of them under ``MIN_VIEW_IOU``), a SilhouetteError giving
        every view's agreement; where they put the object apart in one view,
        a SilhouetteError naming it.

    Notes
    -----
    With ``auto``, views that come with a picture of the empty workspace are
    segmented against it. Where the silhouettes so found fail the
    reconstruction (they contradict each other, put the object apart in one
    view, or nothing stands out in one), the pictures may no longer show the
    workspace as it is (the light changed, the table moved), or two views may
    agree on a change that is not a shadow: the views are segmented again from
    their images alone, and the result's ``backgrounds_set_aside`` gives the
    first error (its ``timings_ms`` the first attempt's as ``with_backgrounds``,
    counted in the total). If that fails too, the first error is raised.
    """
    views = list(views)
    if len(views) < 2:
        raise GeometryError(f"need at least 2 views, got {len(views)}")
    began = time.perf_counter()
    try:
        return _reconstructed(views, segmentation, support_plane, options, backgrounds=True)
    except (SilhouetteError, GeometryError, FitError) as error:
        if segmentation.method != "auto" or all(view.background is None or view.mask is not None for view in views):
            raise
        with_backgrounds = error
    attempt_ms = (time.perf_counter() - began) * 1e3
    try:
        result = _reconstructed(views, segmentation, support_plane, options, backgrounds=False)
    except CoreError:
        raise with_backgrounds from None
    # The attempt with the backgrounds counts in the total: the caller waited for it too.
    timings = {**result.timings_ms, "with_backgrounds": attempt_ms}
    timings["total"] = timings.get("total", 0.0) + attempt_ms
    return replace(result, backgrounds_set_aside=str(with_backgrounds), timings_ms=timings)


def _reconstructed(views: list[View], segmentation: Segmentation, support_plane, options: Options, *,
                   backgrounds: bool) -> Reconstruction:
    """:func:`reconstruct`, the views' pictures of the empty workspace used by ``auto`` or not (``backgrounds``)."""
    clock = time.perf_counter
    timings: dict[str, float] = {}
    start = last = clock()

    def lap(stage: str) -> None:
        nonlocal last
        now = clock()
        timings[stage] = timings.get(stage, 0.0) + (now - last) * 1e3
        last = now

    silhouettes, boxes, edges = [], [], []
    evaluations: dict[str, int] = {}
    decoded = [_decoded(index, view) for index, view in enumerate(views)]
    found: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    if segmentation.method == "auto":
        # auto sees all the views at once: the plane's parallax and the hull need every view.
        pictured = [index for index, (_, is_mask) in enumerate(decoded) if not is_mask]
        empty = [_background(index, views[index]) if backgrounds else None for index in pictured]
        lap("decode")
        if pictured:
            found = dict(zip(pictured, auto_silhouettes(
                [decoded[index][0] for index in pictured], [views[index].camera for index in pictured],
                support_plane=support_plane, backgrounds=empty,
                aim_cameras=[view.camera for view in views])))
            lap("segment")
    for index, view in enumerate(views):
        data, is_mask = decoded[index]
        lap("decode")
        if is_mask:
            silhouette, outline = mask_with_outline(data, view=index)
        elif index in found:
            silhouette, outline = found[index]
        else:
            silhouette, outline = segment_with_outline(data, segmentation, view=index)
        if view.camera.dist is None:
            silhouettes.append(silhouette)
            boxes.append(cv2.boundingRect(outline))
        else:
            silhouettes.append(undistort_mask(silhouette, view.camera))
            boxes.append(cv2.boundingRect(silhouettes[-1]))
        lap("segment")
        if options.silhouette_fit:
            edges.append(edge_samples(outline, silhouette, None if is_mask else data, count=options.edge_samples,
                                      camera=view.camera, on_edge=index in found))
            lap("edges")
    cameras = [view.camera for view in views]
    try:
        centre, radius = enclosing_sphere(silhouettes, cameras, margin=options.radius_margin, known_boxes=boxes)
    except GeometryError as error:
        if error.view not in found:
            raise
        # The silhouettes auto found put the object apart in this view: far likelier a view that missed it
        # (of the table's own colour) than poses wrong by as much, which the plane's parallax would have shown.
        reason = str(error).removeprefix(f"view {error.view}: ").replace(f"; {CHECK_THE_POSES}", "")
        raise SilhouetteError(f"{reason}; the silhouette found in this view's image may have missed the object: "
                              "give the views pictures of the empty workspace, or masks (or check the poses' "
                              "direction and units)", view=error.view) from error
    plane = None if support_plane is None else check_support_plane(support_plane, centre, radius)
    if plane is not None:
        centre = lift_above_plane(centre, radius, plane)
    # No part of the model grows past how far the object may reach from the centre (the radius across each
    # view's line of sight, farther along one that the other views see little across).
    reach = farthest_reach(centre, radius, cameras)
    lap("centroid")

    directions = fibonacci_sphere(options.n_points)
    radii, observed = carve(directions, centre, radius, cameras,
                            [occupancy(s, box) for s, box in zip(silhouettes, boxes)])
    if plane is not None:
        radii = clip_to_plane(directions, radii, centre, plane)
    # Points that no view saw, and directions in which no view saw the object, carry no evidence.
    seen = observed & (radii > 0)
    points = centre + radii[seen, None] * directions[seen]
    lap("carve")

    if len(points) < 11:
        raise FitError(f"only {len(points)} points survived carving: the silhouettes do not overlap")
    stride = max(1, len(points) // options.fit_points)
    if options.silhouette_fit:
        starts = start_superquadrics(points[::stride], support_plane=plane)
        if plane is not None:
            # An object on a table rests on a face or a side (DESIGN.md §1.12): a strong start, not a rule.
            # A start tilted less than that is set resting; one tilted more is kept and also tried resting.
            rested = [resting_on(start, plane[:3]) for start in starts]
            starts = ([upright if tilt < _RESTING_TILT else start for start, (upright, tilt) in zip(starts, rested)]
                      + [upright for upright, tilt in rested if tilt >= _RESTING_TILT]
                      + [upright_box(points, plane[:3])])
        lap("start")
        # The pixels of auto's silhouettes that their colours cannot confirm (a mask's are all sure), and the
        # edge samples on them: a stretch of one view's outline there may be a shadow taken in or a dark
        # face left out, and the other views decide.
        doubtful = [samples_near(edges[index], _unsure(view, decoded[index][0], found[index][0], edges[index]))
                    if index in found else None for index, view in enumerate(views)]
        fit = fit_to_silhouettes(starts, cameras, edges, support_plane=plane, doubtful=doubtful, reach=reach)
        superquadric = fit.superquadric
        evaluations["fit"] = fit.evaluations
        lap("fit")
        ious, _ = union_ious((superquadric,), cameras, silhouettes, boxes)
        if min(ious) < _DISAGREE:
            # A view clearly disagrees with the model: a bad local minimum (a slab seen edge-on, a
            # tilted start) or an object that is no superquadric. The descents from the other starts,
            # each some steps on already (the fit went on with them, the silhouettes unexplained), are
            # judged by how well they agree with all the silhouettes; the one that agrees best goes on
            # to its end, and is kept if it then agrees better than the fit (DESIGN.md §1.12).
            agreement = [(float(np.mean(union_ious(other, cameras, silhouettes, boxes)[0])), other[0])
                         for other in fit.others]
            if agreement:
                _, agreeing = max(agreement, key=lambda pair: pair[0])
                restart = fit_to_silhouettes(agreeing, cameras, edges, support_plane=plane,
                                             max_iterations=_RESTART_ITERATIONS, doubtful=doubtful,
                                             reach=reach)
                evaluations["fit"] += restart.evaluations
                other_ious, _ = union_ious((restart.superquadric,), cameras, silhouettes, boxes)
                if np.mean(other_ious) > np.mean(ious):
                    superquadric, ious = restart.superquadric, other_ious
            if min(ious) < _DISAGREE and any(doubt is not None and np.any(doubt) for doubt in doubtful):
                # Still in clear disagreement: the doubt may be its cause. A fit that lets the samples on
                # unsure pixels go is held only by the rest, and where most are unsure (a box of its
                # table's colour) the rest may run along a shadow or a strip of table, which a slab
                # floating over the table follows from every start. So the starts are fitted again with
                # every sample sure, and that model is kept if it agrees better with the silhouettes
                # themselves; the steps after it still doubt what auto could not confirm.
                sure = fit_to_silhouettes(starts, cameras, edges, support_plane=plane, reach=reach)
                evaluations["fit"] += sure.evaluations
                sure_ious, _ = union_ious((sure.superquadric,), cameras, silhouettes, boxes)
                if np.mean(sure_ious) > np.mean(ious):
                    superquadric, ious = sure.superquadric, sure_ious
            lap("fit")
    else:
        superquadric = fit_superquadric(points[::stride], inside_weight=options.inside_weight,
                                        outside_loss=options.outside_loss, cauchy_scale=options.cauchy_scale,
                                        support_plane=plane).superquadric
        lap("fit")
    if not options.silhouette_fit:
        ious, _ = union_ious((superquadric,), cameras, silhouettes, boxes)
    lap("quality")
    parts: tuple[Superquadric, ...] = (superquadric,)
    if options.silhouette_fit and options.max_parts > 1:
        model = fit_parts(superquadric, points, cameras, silhouettes, boxes, ious=ious,
                          support_plane=plane, max_parts=options.max_parts, reach=reach,
                          single_evaluations=evaluations["fit"],
                          # The pixels of auto's silhouettes that their colours cannot confirm, found only if
                          # a part could pay: it must pay on the rest too.
                          unsure=lambda: [_unsure(view, decoded[index][0], found[index][0]) if index in found
                                          else None for index, view in enumerate(views)])
        parts, ious, evaluations["parts"] = model.parts, model.silhouette_iou, model.evaluations
        lap("fit")  # the parts are the fit's too

    def refitted_where_contradicted(model: Superquadric, resting: bool) -> Superquadric | None:
        """``model`` (one superquadric) fitted again with auto's edge samples that run far from its own
        outline doubtful, and those of them that were doubtful already set aside; None if there are none such."""
        far = [None if before is None else np.abs(outline_distances(model, camera, samples)) > _CONTRADICTED_PX
               for before, camera, samples in zip(doubtful, cameras, edges)]
        if not any(view_far is not None and np.any(view_far) for view_far in far):
            return None
        # A sample whose colours could not confirm it and that the views contradict has nothing left to speak for
        # it: under the fading loss a thin strip of shadow a few pixels wide would still pull, and more so where
        # two views took in the same strip. It is set aside; the rest of the fit is as it was.
        kept_edges: list[np.ndarray] = []
        kept_doubts: list[np.ndarray | None] = []
        for samples, before, view_far in zip(edges, doubtful, far):
            if before is None or view_far is None:
                kept_edges.append(samples)
                kept_doubts.append(None)
            else:
                keep = ~(before & view_far)
                kept_edges.append(samples[keep])
                kept_doubts.append((before | view_far)[keep])
        refined = fit_to_silhouettes(model, cameras, kept_edges, support_plane=plane, doubtful=kept_doubts,
                                     resting=resting, reach=reach)
        evaluations["fit"] += refined.evaluations
        return refined.superquadric

    if options.silhouette_fit and found and len(parts) == 1:
        # The model stays one superquadric: a stretch of one view's outline that runs far from it, where the
        # other views hold it, is one they contradict (a shadow or a strip of table taken in, a face left
        # out), whatever its colours say. Such samples are doubtful as those on unsure pixels are, their
        # pull fading as they lie farther, and those on unsure pixels too are set aside; the fit goes on from
        # where it is: they can no longer drag it.
        refined = refitted_where_contradicted(parts[0], resting=False)
        if refined is not None:
            superquadric, parts = refined, (refined,)
            ious, _ = union_ious(parts, cameras, silhouettes, boxes)
            lap("fit")
    if options.silhouette_fit and plane is not None:
        # An object on the support plane rests on it in equilibrium, and one superquadric, its mass about its
        # centre, rests only on a face or a side, an axis along the plane's normal: tilted, a box balanced on
        # an edge, it would topple. So the model, one part or a union, is also fitted held at rest (each part
        # turning only about the normal), and a tilt is kept only where it pays as a part must (DESIGN.md
        # §1.11): two more parameters to a part that explain little more may only follow one view's wrong
        # silhouette (a shadow taken in, a face left out). This is the one place a model is set at rest.
        # Which of auto's samples the views contradict is judged by the resting model's own outline, not by
        # the tilted one's: each model is held to the samples that it, not another, leaves far off.
        resting = fit_to_silhouettes([parts], cameras, edges, support_plane=plane, doubtful=doubtful, resting=True,
                                     reach=reach)
        evaluations["fit"] += resting.evaluations
        at_rest = resting.parts
        if found and len(at_rest) == 1:
            refined = refitted_where_contradicted(at_rest[0], resting=True)
            at_rest = at_rest if refined is None else (refined,)
        resting_ious, _ = union_ious(at_rest, cameras, silhouettes, boxes)
        if not explains_more(np.subtract(ious, resting_ious)):
            parts, ious = at_rest, resting_ious
            if len(parts) == 1:
                superquadric = parts[0]
        lap("fit")
    if found and min(ious) < MIN_VIEW_IOU:
        # The silhouettes auto found contradict each other (two views that took in a stretch of table agree on a
        # slab over it, against the third): no model agrees with them all, and the fit is of none of them.
        # An error, not a model of the table; which view is wrong the agreements alone do not say.
        raise SilhouetteError("the views' silhouettes contradict each other: the model agrees with them only "
                              + ", ".join(f"{iou:.2f}" for iou in ious) + f" (at least {MIN_VIEW_IOU} each is "
                              "needed; a stretch of table or shadow taken for the object?): give the views "
                              "pictures of the empty workspace, or masks")
    residual = radial_residual(superquadric, points)
    timings["total"] = (clock() - start) * 1e3
    return Reconstruction(superquadric, centre, radius, points, silhouettes, ious, residual, timings, parts,
                          evaluations)
