"""``auto`` segmentation: find what stands on the support plane where the views converge (DESIGN.md §1.10).

Nothing is known of the object's colour; what is known is geometry. The
views were aimed at the object, so it lies near the point closest to all
optical axes (the *aim*). The table is a plane, so the plane's homography
maps one view's table onto another's exactly, shadow included, while what
stands above the plane does not map (plane parallax): a pixel whose colour
no other view confirms through the plane is above it. A picture of the empty
workspace (``background``), where there is one, says the same directly: the
image's ratio to it is 1 on the table (its texture divides out), a smooth
darkening on a shadow, and the plane maps that ratio from one view to another
alike on the table and on a shadow but not on what stands above the plane.

Per view, at a coarse scale (about 200 pixels a side, where every cue is
cheap): the cues give an evidence map; the region that stands out nearest
the aim gives the seeds (sure object, sure table, and the uncertain rest) of
a graph cut (OpenCV's GrabCut, initialised with that mask on a small region
around the object), which draws the silhouette along the image's own edges
with colour models of object and table learned from the seeds. The views
then check each other: the hull carved from all other views, projected into
a view, must contain that view's silhouette; what lies outside it (a
shadow, a stretch of table) is table, and that view is cut again with it
marked so. Last, the silhouette's edge is placed at full resolution: along
each normal of the coarse outline, on the sharpest colour step that leaves
only the table's colour (or its shadow) beyond it, to a fraction of a pixel.

Without a support plane the aim alone seeds the cut (the region around it
is taken for the object, the image's border for the background), and the
views' consistency does the rest; this serves a bright object on a dark
ground, or a photograph whose background is not a plane.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import NamedTuple

import cv2
import numpy as np
from scipy.special import erfinv

from ._auto_segment_cy import (add_relit_grain, any_within, channel_sum, columns_meet_mask, median,
                               median_and_spread, plane_homography_maps, project_into_mask, ratio_disagreement,
                               shadow_like_pixels, shadow_look, windowed_correlation)
from ._edges_cy import smoothest_path
from .camera import Camera
from .carve import check_support_plane
from .errors import GeometryError, ImageError, SilhouetteError
from .segment import mask_with_outline

__all__ = ["auto_silhouettes", "aim_point", "unsure_pixels"]

#: The coarse images' longer side, px: the cues and the graph cut work there.
COARSE_SIDE = 200
#: A view in which nothing stands out over this share of the evidence's noise is empty.
_NOTHING = "nothing stands on the table near the views' aim"
_SPECK_LEFT = ("only a speck of what stands near the views' aim was told from the table (an object of the table's "
               "own colour and light?): give the views pictures of the empty workspace, or masks")
_GC_ITERATIONS = 2
#: The evidence's noise is taken to be at least this (a relative colour difference): JPEG and a
#: pixel's worth of misregistration leave that much on a flat table.
_NOISE_FLOOR = 0.03
#: Against a picture of the empty workspace from the same pose nothing is misregistered: JPEG and the
#: sensor's noise are all.
_BACKGROUND_NOISE_FLOOR = 0.015
#: The score of a pixel whose table point no other view sees: above the threshold of standing out,
#: below that of a sure seed.
_HIDDEN = 3.0
_HULL_GRID = 40
#: A region of fewer coarse pixels than this is a speck of noise, not an object.
_SPECK = 12


def _matched_exposure(view: _View) -> None:
    """Bring the view's background to its image's exposure and white balance.

    The empty workspace is taken before the object is put there, and a camera may set its exposure and white
    balance anew for each picture (the object, dark or bright, changes what it meters): the whole table then
    differs by one gain per channel, which the comparison with the background would take for a change
    everywhere. Most of the picture is table, so the median of each channel's log ratio of image to background
    is that gain. Within :data:`_EXPOSURE_MATCHED` of 1 the pictures are left as they are: the same camera's
    pictures of the same table give 0 (the grey levels' rounding), and so every scene of the benchmarks."""
    assert view.background is not None and view.full_background is not None
    ratio = np.log((view.coarse + _RATIO_OFFSET) / (view.background + _RATIO_OFFSET)).reshape(-1, 3)
    gain = np.array([median(np.ascontiguousarray(ratio[:, k])) for k in range(3)], np.float32)
    if np.abs(gain).max() > _EXPOSURE_MATCHED:
        # Both pictures of the empty workspace, the coarse one and the one the finer scales are read from.
        scale = np.exp(gain).astype(np.float32)
        view.background = view.background * scale
        view.full_background = view.full_background * scale


#: A background within this of the image's exposure, in the log of each channel's gain, is left as it is.
_EXPOSURE_MATCHED = 0.03


def aim_point(cameras: Sequence[Camera]) -> np.ndarray:
    """(3,) the point closest, in least squares, to all the cameras' optical axes.

    Raises
    ------
    GeometryError
        If the axes are (nearly) parallel: they do not converge anywhere.

    Examples
    --------
    >>> from core_cy.camera import Camera
    >>> def looking_at_origin(position):
    ...     z = -np.asarray(position, float) / np.linalg.norm(position)
    ...     x = np.cross([0.0, 0.0, 1.0], z); x /= np.linalg.norm(x)
    ...     T = np.eye(4); T[:3, :3] = np.column_stack([x, np.cross(z, x), z]); T[:3, 3] = position
    ...     return Camera(K=[[500, 0, 320], [0, 500, 240], [0, 0, 1]], T_world_cam=T)
    >>> aim_point([looking_at_origin([1, 0, 1]), looking_at_origin([0, 1, 1])]).round(6).tolist()
    [0.0, 0.0, 0.0]
    """
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for camera in cameras:
        axis = camera.T_world_cam[:3, 2]
        P = np.eye(3) - np.outer(axis, axis)
        A += P
        b += P @ camera.center
    eigenvalues = np.linalg.eigvalsh(A)
    if eigenvalues[0] < 1e-6 * eigenvalues[-1]:
        raise GeometryError("the views' optical axes are parallel: they converge nowhere, so the "
                            "object cannot be found without a segmentation naming its colour or masks")
    return np.linalg.solve(A, b)


class _View:
    """One view at the coarse scale: its image, camera matrices scaled, and what was found."""

    def __init__(self, index: int, image: np.ndarray, camera: Camera, background: np.ndarray | None) -> None:
        height, width = image.shape[:2]
        self.index = index
        self.image = image
        self.camera = camera
        self.scale = max(1.0, max(width, height) / COARSE_SIDE)
        self.coarse_size = (max(8, round(width / self.scale)), max(8, round(height / self.scale)))
        cw, ch = self.coarse_size
        self.sx, self.sy = width / cw, height / ch
        self.coarse = cv2.resize(image, self.coarse_size, interpolation=cv2.INTER_AREA).astype(np.float32)
        self.background = None if background is None else cv2.resize(
            background, self.coarse_size, interpolation=cv2.INTER_AREA).astype(np.float32)
        self.full_background = background
        # The smooth light field the coarse pictures were divided by (_even_the_light), if they were.
        self.light_field: np.ndarray | None = None
        self.fine_scale = max(1.0, max(width, height) / FINE_SIDE)
        self.fine: dict[str, np.ndarray] = {}  # grey images at the fine scale
        # With the empty workspace: per coarse pixel, the sums its grain is told by over a region
        # (:func:`_texture_change`).
        self.grain_sums: np.ndarray | None = None
        self.shadow_look: np.ndarray | None = None  # and where it has a shadow's look (_shadow_of_table)
        # The open shadow's darkenings, all views' (_open_shadow), worked out when first asked; without an
        # empty workspace, the other views' (their shadow_seen), for a view that sees none of its own.
        self.open_shadow: Callable[[], np.ndarray] | None = None
        # Without an empty workspace: the brightness over the table's of the shadow that the view's first cut
        # saw in the open (_open_shadow_seen), None if it saw none.
        self.shadow_seen: np.ndarray | None = None
        # Without an empty workspace, with a plane: the coarse pixels whose table point no other view's picture
        # holds (_first_cut). Geometry alone, the same for every look.
        self.unconfirmable: np.ndarray | None = None
        # The last graph cut's box's shadow without an empty workspace (_shadow_in_box), and what it was of.
        self.box_shadow: tuple | None = None
        self.noise: float | None = None  # the sensor's noise in the fine grey image (_sensor_noise)
        # The texture's local correlation with another view mapped through a plane, and where it is known.
        self.correlations: dict[tuple[int, bytes], tuple[np.ndarray, np.ndarray]] = {}
        self._mappings: dict[tuple[int, bytes], tuple[np.ndarray, np.ndarray]] = {}
        self._nearest_maps: dict[tuple[int, bytes], np.ndarray] = {}
        # Each other view's image mapped through a plane and compared with this one, per comparison.
        self.differences: dict[tuple[int, bytes, Callable], np.ndarray] = {}
        self._points: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}  # each plane's points, per coarse pixel
        self._warped: dict[tuple[int, bytes], np.ndarray] = {}
        # Each other view's fine grey image mapped through a plane onto a window of this one's (_fine_warped).
        self.fine_warped: dict[tuple[int, bytes, int, int, int, int], np.ndarray] = {}

    @functools.cached_property
    def unrounded(self) -> tuple[np.ndarray, np.ndarray]:
        """With the empty workspace: both coarse images before their rounding to whole grey levels (float32
        BGR, divided by the light field as the coarse ones are), whose change against each other the rounding
        does not hide in its steps (_log_ratio). Asked only once the light is evened."""
        assert self.full_background is not None
        image, empty = (cv2.resize(picture.astype(np.float32), self.coarse_size, interpolation=cv2.INTER_AREA)
                        for picture in (self.image, self.full_background))
        if self.light_field is None:
            return image, empty
        return image / self.light_field, empty / self.light_field

    def mapping(self, other: _View, plane: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where each coarse pixel's table point (through ``plane``) falls in ``other``'s coarse image, as
        (h, w, 2) float32 maps for cv2.remap, and (h * w,) which of them ``other`` sees (a fresh copy).
        Geometry alone: worked out once per pair of views."""
        key = _pair(other, plane)
        if key not in self._mappings:
            if self.camera.dist is None and other.camera.dist is None:
                self._mappings[key] = _plane_homography_maps(self, other, plane)
            else:
                plane_key = key[1]
                if plane_key not in self._points:
                    self._points[plane_key] = _plane_points(self, plane)
                points, valid = self._points[plane_key]
                self._mappings[key] = _plane_maps(other, points, valid, self.coarse_size)
        maps, inside = self._mappings[key]
        return maps, inside.copy()

    def warped(self, other: _View, plane: np.ndarray) -> np.ndarray:
        """``other``'s coarse image mapped through ``plane`` onto this view's (float32 BGR): each colour
        comparison of the two starts from it, so it is made once per pair of views."""
        key = _pair(other, plane)
        if key not in self._warped:
            maps, _ = self.mapping(other, plane)
            self._warped[key] = _remapped(other.coarse, maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return self._warped[key]

    def sees(self, other: _View, plane: np.ndarray,
             hidden: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`mapping`'s maps, and (h, w) where ``other`` sees each coarse pixel's table point and
        where it would but has it behind ``hidden`` (0/255 in ``other``'s coarse image: what stands
        there, in front of the table point, so that ``other`` says nothing of it)."""
        cw, ch = self.coarse_size
        maps, inside_flat = self.mapping(other, plane)
        inside = inside_flat.reshape(ch, cw)
        if hidden is None:
            return maps, inside, np.zeros_like(inside)
        key = _pair(other, plane)
        if key not in self._nearest_maps:
            # The maps rounded to whole pixels, as cv2.remap rounds float maps for INTER_NEAREST on every call:
            # once per pair of views, for the many looks at what hides the table.
            self._nearest_maps[key] = cv2.convertMaps(  # type: ignore[call-overload]  # stubs want map2
                maps, None, cv2.CV_16SC2, nninterpolation=True)[0]
        behind = inside & (_remapped(hidden, self._nearest_maps[key], cv2.INTER_NEAREST, borderValue=0) > 0)
        return maps, inside & ~behind, behind

    def to_coarse(self, uv: np.ndarray) -> np.ndarray:
        """Full-resolution pixel coordinates (N, 2) to coarse ones (pixel centres on integers)."""
        return np.column_stack([(uv[:, 0] + 0.5) / self.sx - 0.5, (uv[:, 1] + 0.5) / self.sy - 0.5])

    def from_coarse(self, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """Coarse pixel coordinates (columns ``xs``, rows ``ys``, (N,) each) to full-resolution ones (N, 2)."""
        return np.column_stack([(xs + 0.5) * self.sx - 0.5, (ys + 0.5) * self.sy - 0.5])

    def coarse_pixels(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World ``points`` (N, 3) at their nearest coarse pixels: (N, 2) int64 (column, row), (N,) bool whether
        the view sees them (in front of the camera, within the coarse image), and (N,) their depths."""
        uv, depth = self.project(points)
        coarse = np.rint(self.to_coarse(uv)).astype(np.int64)
        cw, ch = self.coarse_size
        seen = (depth > 0) & (coarse[:, 0] >= 0) & (coarse[:, 1] >= 0) & (coarse[:, 0] < cw) & (coarse[:, 1] < ch)
        return coarse, seen, depth

    def coarse_grid(self) -> np.ndarray:
        """Full-resolution coordinates (N, 2) of every coarse pixel's centre, row by row."""
        cw, ch = self.coarse_size
        u, v = np.meshgrid((np.arange(cw) + 0.5) * self.sx - 0.5, (np.arange(ch) + 0.5) * self.sy - 0.5)
        return np.column_stack([u.ravel(), v.ravel()])

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Full-resolution pixels (N, 2) of world points, through the lens (distortion applied), and depth."""
        uv, depth = self.camera.project(points)
        if self.camera.dist is not None:
            R = self.camera.T_world_cam[:3, :3]
            local = (points - self.camera.center) @ R
            lens, _ = cv2.projectPoints(local.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), self.camera.K,
                                        self.camera.dist)
            uv = lens.reshape(-1, 2)
        return uv, depth

    def rays(self, uv: np.ndarray) -> np.ndarray:
        """World directions (N, 3) of the rays through full-resolution pixels of the lens's image."""
        if self.camera.dist is not None:
            ideal = cv2.undistortPoints(uv.reshape(-1, 1, 2).astype(np.float64), self.camera.K, self.camera.dist,
                                        P=self.camera.K).reshape(-1, 2)
            uv = ideal
        return self.camera.pixel_rays(uv)


def _pair(other: _View, plane: np.ndarray) -> tuple[int, bytes]:
    """The key of what a view caches per other view and plane (its mapping, the warped image, comparisons)."""
    return other.index, np.asarray(plane, np.float64).tobytes()


def _remapped(image: np.ndarray, maps: np.ndarray, interpolation: int, **border) -> np.ndarray:
    """``image`` sampled at ``maps`` ((h, w, 2) float32, as :meth:`_View.mapping` gives, or int16 whole pixels), by
    cv2.remap. The two-channel map goes in whole: taken apart, each channel is a strided view that OpenCV
    copies first."""
    return cv2.remap(image, maps, None, interpolation, **border)  # type: ignore[call-overload]  # stubs want map2


def _relative_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-pixel colour difference of two float32 BGR images, relative to their brightness: a change of
    light over the image (vignetting, a gentle fall-off) changes it little, a change of colour much."""
    difference = cv2.transform(cv2.absdiff(a, b), _CHANNEL_SUM)
    return difference / (cv2.transform(a + b, _CHANNEL_MEAN) + 30.0)


_CHANNEL_SUM = np.ones((1, 3), np.float32)
_CHANNEL_MEAN = np.full((1, 3), 0.5, np.float32)


def _chroma_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-pixel difference of two float32 BGR images' tints, blind to brightness: ``b`` brought to
    ``a``'s brightness, the grey levels between them (summed over the channels). In grey levels, not
    as a ratio, because the sensor's noise is in grey levels: a dark pixel's tint is mostly noise."""
    a, b = a + _CHROMA_OFFSET, b + _CHROMA_OFFSET
    gain = cv2.transform(a, _CHANNEL_SUM) / cv2.transform(b, _CHANNEL_SUM)
    return cv2.transform(cv2.absdiff(a, np.asarray(b * gain[..., None], np.float32)), _CHANNEL_SUM)


def _parallax_evidence(view: _View, others: Sequence[_View], plane: np.ndarray,
                       standing: Sequence[np.ndarray | None] | None = None,
                       difference_of=_relative_difference) -> np.ndarray:
    """How little any other view, mapped through the support plane, agrees with each coarse pixel of
    ``view``: the smallest difference over the others (NaN where no other view sees that table point).

    ``standing``, per other view, what stands out in it (0/255, or None): where the plane point lies
    behind the object in another view, that view sees the object, not the table, and says nothing."""
    cw, ch = view.coarse_size
    evidence = np.full((ch, cw), np.inf, np.float32)
    seen = np.zeros((ch, cw), bool)
    occluded = np.zeros((ch, cw), bool)
    for number, other in enumerate(others):
        maps, inside, behind = view.sees(other, plane, None if standing is None else standing[number])
        occluded |= behind
        # The images do not change from one look to the next, only what is taken to stand in front.
        key = (*_pair(other, plane), difference_of)
        if key not in view.differences:
            view.differences[key] = difference_of(view.coarse, view.warped(other, plane))
        difference = view.differences[key]
        np.minimum(evidence, difference, out=evidence, where=inside)
        seen |= inside
    # Out of every other view's picture: nothing is known, taken for table; hidden behind the object
    # in the other views that would see it: NaN.
    evidence[~seen] = np.where(occluded[~seen], np.nan, 0.0)
    return evidence


def _colour_parallax(view: _View, others: Sequence[_View], plane: np.ndarray,
                     standing: Sequence[np.ndarray]) -> np.ndarray:
    """:func:`_parallax_evidence` of the colour in units of its noise (NaN where hidden): the evidence the
    view has without a background, for a view that has one."""
    evidence = _parallax_evidence(view, others, plane, standing)
    return evidence / max(_noise_level(evidence), _NOISE_FLOOR)


#: The fine images' longer side, px, at most: a table's grain (wood, a weave) is a few pixels wide and
#: the coarse images average it away; texture is compared here.
FINE_SIDE = 800
#: Window of the local correlation of textures, fine px.
_TEXTURE_PATCH = 7
#: A window's grey-level variance below this is flat whatever its brightness: its correlation with another
#: is the sensor's noise and JPEG's.
_TEXTURE_FLOOR = 3.0 ** 2
#: The texture's decorrelation on the table is taken to be at least this: JPEG and a fine pixel's worth of
#: misregistration leave that much.
_TEXTURE_NOISE_FLOOR = 0.15


def _fine_grey(view: _View, background: bool = False) -> np.ndarray:
    """The view's image (or its empty workspace's) in grey at the fine scale (float32), kept once made."""
    key = "background" if background else "image"
    if key not in view.fine:
        source = view.full_background if background else view.image
        assert source is not None, "the empty workspace's grain is asked only of a view that has one"
        grey = cv2.cvtColor(source, cv2.COLOR_BGR2GRAY)
        height, width = grey.shape
        if view.fine_scale > 1.0:
            grey = cv2.resize(grey, (round(width / view.fine_scale), round(height / view.fine_scale)),
                              interpolation=cv2.INTER_AREA)
        view.fine[key] = grey.astype(np.float32)
    return view.fine[key]


def _sensor_noise(view: _View) -> float:
    """The standard deviation (grey levels) of the sensor's noise in the view's fine grey image: Immerkaer's
    estimate (the image filtered by the difference of two Laplacians, which leaves little of any smooth
    shading or of an edge), from the median of its magnitude so that edges and grain weigh little."""
    if view.noise is None:
        residual = cv2.filter2D(_fine_grey(view), cv2.CV_32F, _NOISE_KERNEL)[1:-1, 1:-1]
        view.noise = float(median(np.ascontiguousarray(np.abs(residual).ravel())) / 0.6745 / 6.0)
    return view.noise


_NOISE_KERNEL = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
#: A window's texture stands clear of the sensor's noise where its variance is this many times the noise's: under
#: twice, it is half noise or more, and its correlation with another view's is at most a half on the table too.
_NOISE_CLEARANCE = 2.0


def _flat_below(view: _View) -> float:
    """The grey-level variance below which a window of the view's fine image is flat (its correlation with
    another is the sensor's noise): :data:`_TEXTURE_FLOOR`, or more in a noisy picture (a camera's high gain
    in dim light): in a flat window the noise alone would pass for a grain that no other view shares."""
    return max(_TEXTURE_FLOOR, _NOISE_CLEARANCE * _sensor_noise(view) ** 2)


def _window_statistics(image: np.ndarray,
                       flat: float = _TEXTURE_FLOOR) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A grey image, and its mean and variance over :data:`_TEXTURE_PATCH` windows at every pixel, and the
    variance below which its window is flat (:func:`_local_correlation`; ``flat``, or more where the
    window is bright: a grain counts by its contrast)."""
    window = (_TEXTURE_PATCH, _TEXTURE_PATCH)
    mean = cv2.blur(image, window)
    variance = np.maximum(cv2.blur(image * image, window) - mean * mean, 0.0)
    # A shadow darkens the grain with the light and keeps its contrast (the table's dark face-coloured shadow
    # beside a dark face keeps the table's grain, the face shows its own), so a grain counts by its contrast;
    # but it must stand clear of the sensor's noise and of what JPEG drops, a few grey levels whatever the light.
    floor = np.maximum((_TEXTURE_CONTRAST * mean) ** 2, flat)
    return image, mean, variance, floor


def _local_correlation(a: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                       b: np.ndarray, flat: float = _TEXTURE_FLOOR) -> tuple[np.ndarray, np.ndarray]:
    """Normalised cross-correlation of two grey images over a small window at every pixel (-1 to 1), and
    where both windows hold a texture that stands clear of the noise (elsewhere it says nothing). ``a``
    comes as its :func:`_window_statistics`, made once for every image it is compared with; ``b``'s window
    is flat under the variance ``flat``."""
    window = (_TEXTURE_PATCH, _TEXTURE_PATCH)
    a_image, mean_a, var_a, floor_a = a
    correlation = np.empty(b.shape, np.float32)
    textured = np.empty(b.shape, np.uint8)
    # The window sums by OpenCV's box filter; the dozen operations that combine them, in one pass.
    windowed_correlation(mean_a, var_a, floor_a, cv2.blur(b, window), cv2.blur(b * b, window),
                         cv2.blur(a_image * b, window), _TEXTURE_CONTRAST, flat, correlation, textured)
    return correlation, textured.view(bool)


def _aim_window(view: _View, centre: np.ndarray) -> tuple[tuple[slice, slice], tuple[slice, slice]]:
    """The window around the aim (coarse pixel ``centre``) where the grain is compared: the views were
    aimed at the object. As (rows, columns) slices of the coarse image and of the fine one."""
    cw, ch = view.coarse_size
    fh, fw = _fine_grey(view).shape
    reach = int(np.ceil(_TEXTURE_REACH * np.hypot(cw, ch)))
    x, y = int(round(centre[0])), int(round(centre[1]))
    x0, x1 = min(max(x - reach, 0), cw), min(max(x + reach + 1, 0), cw)
    y0, y1 = min(max(y - reach, 0), ch), min(max(y + reach + 1, 0), ch)
    fine = (slice(round(y0 * fh / ch), round(y1 * fh / ch)), slice(round(x0 * fw / cw), round(x1 * fw / cw)))
    return (slice(y0, y1), slice(x0, x1)), fine


#: The window the grain is compared in reaches this share of the coarse image's diagonal from the aim.
_TEXTURE_REACH = 0.2


def _in_window(view: _View, window: tuple[slice, slice], fine: np.ndarray) -> np.ndarray:
    """A fine map of the window (of one channel or a few), averaged into the coarse image's pixels (NaN outside
    the window)."""
    cw, ch = view.coarse_size
    coarse = np.full((ch, cw) + fine.shape[2:], np.nan, np.float32)
    rows, columns = window
    if rows.stop > rows.start and columns.stop > columns.start and fine.size:
        coarse[window] = cv2.resize(fine, (columns.stop - columns.start, rows.stop - rows.start),
                                    interpolation=cv2.INTER_AREA)
    return coarse


def _texture_parallax(view: _View, others: Sequence[_View], plane: np.ndarray,
                      standing: Sequence[np.ndarray | None], centre: np.ndarray) -> np.ndarray:
    """How little any other view, mapped through the support plane at the fine scale, shares each coarse
    pixel's texture (1 less the best correlation; 0 where no other view sees the table point, or where the
    textures are flat; NaN out of the window around the aim, coarse pixel ``centre``): the table's grain
    maps onto itself, a face above the plane shows another grain, even of the table's own colour."""
    window, fine_window = _aim_window(view, centre)
    grey = _fine_grey(view)
    fh, fw = grey.shape
    grey = grey[fine_window]
    best = np.full(grey.shape, -1.0, np.float32)
    seen = np.zeros(grey.shape, bool)
    own = None  # the window's own statistics, shared by every other view's comparison
    # The coarse pixel each fine pixel of the window lies in, as cv2.resize's nearest neighbour picks it.
    rows, columns = _nearest_indices(view.coarse_size, (fw, fh))
    window_rows, window_columns = rows[fine_window[0]], columns[fine_window[1]]
    for other, hidden in zip(others, standing):
        # The grain is compared at a finer scale than the object's outline is known: the table points just
        # behind its edge in the other view are taken for hidden too.
        maps, inside, _ = view.sees(other, plane, None if hidden is None else
                                    cv2.dilate(hidden, _SMALL, iterations=_OCCLUSION_MARGIN))
        key = _pair(other, plane)
        if key not in view.correlations:
            warped = _fine_warped(view, other, plane, maps, fine_window)
            if own is None:
                own = _window_statistics(grey, _flat_below(view))
            view.correlations[key] = _local_correlation(own, warped, _flat_below(other))
        correlation, textured = view.correlations[key]
        seeing = inside[window_rows][:, window_columns]
        known = textured & seeing
        np.maximum(best, correlation, out=best, where=known)
        seen |= known
    return _in_window(view, window, np.where(seen, 1.0 - best, 0.0).astype(np.float32))


def _plane_grain_sums(view: _View, others: Sequence[_View], plane: np.ndarray, standing: Sequence[np.ndarray],
                      centre: np.ndarray) -> np.ndarray:
    """(h, w, 3), per coarse pixel, the means over its fine pixels of what :func:`_pooled_grain` regresses,
    with the other views mapped through the plane in place of the empty workspace: the view's grain brought
    back to their light times theirs, theirs squared, the former squared; over the other views that see the
    table point (``standing``, what stands in each, hides it), NaN where none does or out of the window
    around the aim (coarse pixel ``centre``). The table's grain maps onto itself, in a shadow too (dimmed
    by the light, as the other view sees it dimmed); a face above the plane hides it, even of the table's
    colour and of the shadow's darkness behind it."""
    window, fine_window = _aim_window(view, centre)
    fh, fw = _fine_grey(view).shape
    grey = _fine_grey(view)[fine_window]
    own, own_light = _grain(grey), cv2.GaussianBlur(grey, (0, 0), _GRAIN_WINDOW)
    rows, columns = _nearest_indices(view.coarse_size, (fw, fh))
    window_rows, window_columns = rows[fine_window[0]], columns[fine_window[1]]
    sums = np.zeros(grey.shape + (3,), np.float32)
    seeing = np.zeros(grey.shape, np.float32)
    for other, hidden in zip(others, standing):
        maps, inside, _ = view.sees(other, plane, cv2.dilate(hidden, _SMALL, iterations=_OCCLUSION_MARGIN))
        warped = _fine_warped(view, other, plane, maps, fine_window)
        # Where the other view sees the table point: the view's grain brought back to its light, times its grain.
        add_relit_grain(own, own_light, _grain(warped), cv2.GaussianBlur(warped, (0, 0), _GRAIN_WINDOW),
                        inside.view(np.uint8), window_rows, window_columns, sums, seeing)
    coarse_seeing = _in_window(view, window, seeing)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(coarse_seeing[..., None] > 0.0, _in_window(view, window, sums) / coarse_seeing[..., None],
                        np.nan).astype(np.float32)


def _nearest_indices(size: tuple[int, int], to: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Which row and which column of an image of ``size`` (w, h) each row and column of it resized to ``to``
    (w, h) by cv2.resize's nearest neighbour is taken from: OpenCV's own choice, read off an image of
    indices resized alike, so that an image's resized window is its rows and columns picked by them
    (without resizing the whole image)."""
    (w, h), (tw, th) = size, to
    key = (w, h, tw, th)
    if key not in _NEAREST_INDICES:
        columns = cv2.resize(np.arange(w, dtype=np.float32)[None, :], (tw, 1), interpolation=cv2.INTER_NEAREST)
        rows = cv2.resize(np.arange(h, dtype=np.float32)[:, None], (1, th), interpolation=cv2.INTER_NEAREST)
        _NEAREST_INDICES[key] = (rows.ravel().astype(np.intp), columns.ravel().astype(np.intp))
    return _NEAREST_INDICES[key]


_NEAREST_INDICES: dict[tuple[int, int, int, int], tuple[np.ndarray, np.ndarray]] = {}


def _texture_change(view: _View, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """How much of the empty workspace's grain each coarse pixel has lost, at the fine scale (0: all kept,
    1: none; 0 where the grain does not stand clear of the noise; NaN out of the window around the aim,
    coarse pixel ``centre``): a shadow darkens the grain by the same factor as its brightness, and its
    soft edge, a slope unrelated to the grain, does not weaken it; a face that hides the grain, even one
    of the table's colour, loses it. And the share of each coarse pixel's fine pixels whose grain stands
    clear of the noise and is mostly kept (:data:`_GRAIN_KEPT`): there the table is seen, lit or not.
    And (h, w, 4), per coarse pixel, the means over its fine pixels of what :func:`_keeps_the_grain` sums
    over a piece of a shadow (NaN out of the window): the image's grain brought back to the empty
    workspace's light times the empty workspace's grain, the latter squared, the former squared, and what
    the sensor's noise alone leaves of the former less the latter."""
    window, fine_window = _aim_window(view, centre)
    image, empty = _fine_grey(view)[fine_window], _fine_grey(view, background=True)[fine_window]
    image_grain, empty_grain = _grain(image), _grain(empty)
    # How much of the empty workspace's grain the image still holds (the local regression's slope), over
    # how much the light there is dimmed. Each product and blur below is made once and used twice.
    empty_power = empty_grain * empty_grain
    strength = cv2.GaussianBlur(empty_power, (0, 0), _GRAIN_WINDOW)
    slope = cv2.GaussianBlur(image_grain * empty_grain, (0, 0), _GRAIN_WINDOW) / np.maximum(strength, 1e-6)
    empty_light = cv2.GaussianBlur(empty, (0, 0), _GRAIN_WINDOW)
    dimmed = (cv2.GaussianBlur(image, (0, 0), _GRAIN_WINDOW) + 1.0) / (empty_light + 1.0)
    lit = np.maximum(dimmed, 0.05)
    kept = slope / lit
    # The grain, dimmed as the image is, must stand clear of the noise (the two pictures' difference on
    # most of the table), and of what JPEG drops: it keeps no grain fainter than a few grey levels.
    noise = median(cv2.GaussianBlur((image_grain - empty_grain) ** 2, (0, 0), _GRAIN_WINDOW).ravel())
    faint = (_GRAIN_FLOOR * empty_light) ** 2
    expected = strength * np.minimum(dimmed, 1.0) ** 2
    grained = (expected > np.maximum(_GRAIN_CLEAR ** 2 * noise, _GRAIN_VISIBLE ** 2)) & (strength > faint)
    lost = _in_window(view, window, np.where(grained, np.clip(1.0 - kept, 0.0, 1.0), 0.0).astype(np.float32))
    # Brought back to the light (the dimming over the grain's window: a shadow's soft edge dims it smoothly,
    # by no one factor), the image's grain in a shadow is the empty workspace's. Each picture's own noise is
    # about half of the two pictures' difference on the table, the image's scaled up with it.
    relit = image_grain / lit
    planes = np.stack([relit * empty_grain, empty_power, relit * relit,
                       0.5 * noise * (1.0 / (lit * lit) + 1.0)], axis=-1).astype(np.float32)
    return lost, _in_window(view, window, (grained & (kept > _GRAIN_KEPT)).astype(np.float32)), \
        _in_window(view, window, planes)


def _keeps_the_grain(candidates: np.ndarray, sums: np.ndarray, fine_per_coarse: float) -> np.ndarray:
    """The pieces of ``candidates`` (h, w bool) in which the image is the empty workspace's grain dimmed by
    the light, and nothing else, told over each piece whole (``sums``, the third of :func:`_texture_change`;
    ``fine_per_coarse``, fine pixels in a coarse one).

    A shadow dims the table and keeps its grain exactly: brought back to the light, the image's grain is
    the empty workspace's (a regression's slope of 1, within :data:`_KEPT_TOLERANCE`, standing clear of its
    own uncertainty by :data:`_KEPT_CLEAR` standard errors) and what it leaves is the sensor's noise (within
    :data:`_KEPT_NOISE` of it). A face hides the grain: the slope is nought. A face printed with another
    stretch of the table's own pattern may correlate with the grain behind it where its stripes run alike,
    but its own pattern is left over. A grain too faint for a pixel's window (a fine weave, dimmed in a
    shadow) is told so over a piece of a shadow."""
    found = np.zeros(candidates.shape, bool)
    count, labels = cv2.connectedComponents(candidates.astype(np.uint8), connectivity=8)
    if count <= 1:
        return found
    # Told inside each piece: along its outline the grain's windows hold the piece's neighbours too (the
    # object beside its shadow, the lit table beyond its soft edge).
    inner = cv2.erode(candidates.astype(np.uint8), _SMALL) > 0
    known = np.isfinite(sums[..., 0]) & (labels > 0) & inner
    flat = labels[known].astype(np.intp)
    totals = np.stack([np.bincount(flat, weights=sums[..., k][known], minlength=count) for k in range(4)], axis=-1)
    pixels = np.bincount(flat, minlength=count).astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        shared, power, own, expected = (totals / np.maximum(pixels, 1.0)[:, None]).T
        slope = shared / power
        residual = np.maximum(own - slope * shared, 0.0)
        standard_error = np.sqrt(residual / (pixels * fine_per_coarse * power))
        kept = ((pixels > 0) & (power > 0) & (slope > _KEPT_CLEAR * standard_error)
                & (np.abs(slope - 1.0) < _KEPT_TOLERANCE) & (residual < _KEPT_NOISE * expected))
    kept[0] = False
    return kept[labels]


#: A shadow's grain, brought back to the light, is the empty workspace's within this share, its slope clear
#: of this many standard errors, and what it leaves within this share of the sensor's noise.
_KEPT_TOLERANCE = 0.4
_KEPT_CLEAR = 3.0
_KEPT_NOISE = 1.5


def _fine_per_coarse(view: _View) -> float:
    """How many fine pixels a coarse pixel holds."""
    fh, fw = _fine_grey(view).shape
    cw, ch = view.coarse_size
    return fh * fw / float(cw * ch)


def _grain(image: np.ndarray) -> np.ndarray:
    """What varies over a few fine pixels only (the grain)."""
    return image - cv2.GaussianBlur(image, (0, 0), _GRAIN_SIGMA)


#: The grain's scale and the window its strength is measured over, fine px.
_GRAIN_SIGMA = 1.5
_GRAIN_WINDOW = 2.5
#: A grain weaker than this (its relative contrast), or than this many times the noise, is no grain.
_GRAIN_FLOOR = 0.02
_GRAIN_CLEAR = 2.0
#: Grey levels: the faintest grain that JPEG keeps.
_GRAIN_VISIBLE = 3.0
#: A grain is kept where the image holds more than this share of the empty workspace's, dimmed as the light.
_GRAIN_KEPT = 0.5
#: A pixel whose fine pixels keep the grain in more than this share is the table, in a shadow or not.
_GRAIN_SEEN = 0.6
#: The grain lost on the table is taken to be at least this: JPEG and the sensor's noise leave that much.
_GRAIN_NOISE_FLOOR = 0.2


def _background_evidence(view: _View) -> np.ndarray:
    """How much each coarse pixel differs from the empty workspace, a shadow (darker, same chromaticity)
    counting as no difference."""
    assert view.background is not None
    return _shadowless_difference(view.coarse, view.background)


def _darkening(view: _View) -> np.ndarray:
    """How much darker than the empty workspace each coarse pixel is (image over background brightness)."""
    assert view.background is not None
    return (_brightness(view.coarse) + 3 * _CHROMA_OFFSET) / (_brightness(view.background) + 3 * _CHROMA_OFFSET)


def _shadow_of_table(view: _View) -> np.ndarray:
    """Pixels darker than the empty workspace with about its chromaticity (a shadow's look; an object of the
    table's colour may look so too)."""
    assert view.background is not None
    # The chromaticities and the darkening (:func:`_darkening`), in one pass.
    found = np.empty(view.coarse.shape[:2], np.uint8)
    shadow_look(view.coarse, view.background, _CHROMA_OFFSET, 0.1, 0.97, _LAMP_HUE_SHIFT, found)
    return found.view(bool)


#: How far two views' darkening of one table point may differ for both to be the same shadow: a shadow's
#: edge is soft and the views' pixels are not the same size on the table.
_SHADOW_AGREEMENT = 0.08
#: Coarse pixels around what stands out in another view that are taken to be hidden by it there too.
_OCCLUSION_MARGIN = 1


def _darkening_contradicted(view: _View, others: Sequence[_View], plane: np.ndarray,
                            standing: Sequence[np.ndarray | None]) -> np.ndarray:
    """Where another view, seeing the same table point through the support plane, does not see it darkened
    alike: a shadow lies on the table, so what such a view denies stands above it."""
    cw, ch = view.coarse_size
    contradicted = np.zeros((ch, cw), bool)
    ratio = _darkening(view)
    for other in others:
        hidden = standing[other.index]
        # Where the other view sees the object in front of the table point, it says nothing of it.
        maps, inside, _ = view.sees(other, plane, None if hidden is None else
                                    cv2.dilate(hidden, _SMALL, iterations=_OCCLUSION_MARGIN))
        other_shadow = _shadow_of_table(other).astype(np.uint8)
        # A pixel's worth of misregistration: the other view's nearest agreeing value around the point.
        other_ratio = _darkening(other).astype(np.float32)
        high, low = cv2.dilate(other_ratio, _SMALL), cv2.erode(other_ratio, _SMALL)
        warped_high = _remapped(high, maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        warped_low = _remapped(low, maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        warped_shadow = _remapped(cv2.dilate(other_shadow, _SMALL), maps, cv2.INTER_NEAREST,
                                  borderValue=0) > 0
        agrees = warped_shadow & (ratio >= warped_low - _SHADOW_AGREEMENT) & (ratio <= warped_high + _SHADOW_AGREEMENT)
        contradicted |= inside & ~agrees
    return contradicted


def _texture_lost(view: _View) -> np.ndarray:
    """Where the empty workspace shows a texture (grain, a grid, a weave) that the image no longer shows
    with the same pattern: a shadow darkens the table's texture but keeps it; an object hides it."""
    assert view.background is not None
    image = cv2.cvtColor(np.clip(view.coarse, 0, 255).astype(np.uint8), cv2.COLOR_BGR2GRAY).astype(np.float32)
    empty = cv2.cvtColor(np.clip(view.background, 0, 255).astype(np.uint8), cv2.COLOR_BGR2GRAY).astype(np.float32)
    window = (_TEXTURE_WINDOW, _TEXTURE_WINDOW)
    mean_i, mean_e = cv2.blur(image, window), cv2.blur(empty, window)
    var_i = np.maximum(cv2.blur(image * image, window) - mean_i * mean_i, 0.0)
    var_e = np.maximum(cv2.blur(empty * empty, window) - mean_e * mean_e, 0.0)
    cov = cv2.blur(image * empty, window) - mean_i * mean_e
    correlation = cov / np.sqrt(var_i * var_e + 1e-6)
    # The texture must stand clear of the noise, relative to the table's brightness.
    textured = np.sqrt(var_e) > _TEXTURE_CONTRAST * mean_e + 1.5
    lost = np.where(textured & (correlation < _TEXTURE_KEPT), 255, 0).astype(np.uint8)
    # The grain is not everywhere: where it is lost here and there across a face, the face hides it all.
    closed = cv2.morphologyEx(lost, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, window))
    return cv2.morphologyEx(closed, cv2.MORPH_OPEN, _SMALL) > 0


_TEXTURE_WINDOW = 5
_TEXTURE_CONTRAST = 0.03
_TEXTURE_KEPT = 0.5


def _plane_points(view: _View, plane: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The support plane's points (N, 3) behind each coarse pixel of ``view``, and which rays meet it."""
    rays = view.rays(view.coarse_grid())
    normal, offset = plane[:3], plane[3]
    height = float(normal @ view.camera.center + offset)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -height / (rays @ normal)
    valid = np.isfinite(t) & (t > 0)
    return view.camera.center + np.where(valid, t, 0.0)[:, None] * rays, valid


def _plane_maps(other: _View, points: np.ndarray, valid: np.ndarray,
                size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Coarse pixel coordinates in ``other`` of plane ``points``, as (h, w, 2) float32 maps for
    cv2.remap, and which of them ``other`` sees."""
    cw, ch = size
    uv, depth = other.project(points)
    coarse_uv = other.to_coarse(uv).astype(np.float32)
    ow, oh = other.coarse_size
    inside = valid & (depth > 0) & (coarse_uv[:, 0] >= 0) & (coarse_uv[:, 1] >= 0) & \
        (coarse_uv[:, 0] <= ow - 1) & (coarse_uv[:, 1] <= oh - 1)
    return coarse_uv.reshape(ch, cw, 2), inside


def _plane_homography(view: _View, other: _View, plane: np.ndarray,
                      to_full: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """For two pinhole cameras without distortion, the plane's homography from pixels of ``view`` (on a grid
    that ``to_full``, 3x3, takes to full-resolution pixels) to ``other``'s full-resolution pixels.

    A pixel x of the grid has the ray d = R K^-1 to_full x from the centre c; the ray meets the plane at
    c + t d with t = -h / (n . d) (h the centre's height over the plane). Projected by the other camera
    (M, p) and multiplied through by n . d, its homogeneous pixel is H x = ((M c + p) n^T - h M) d; its
    third coordinate, over n . d, is the depth. Returns H, the row vector ``across`` with n . d =
    across . x, and h."""
    normal, offset = np.asarray(plane[:3], np.float64), float(plane[3])
    centre = view.camera.center
    height = float(normal @ centre + offset)
    to_ray = view.camera.T_world_cam[:3, :3] @ np.linalg.inv(view.camera.K) @ to_full
    projection = other.camera.projection
    M, p = projection[:, :3], projection[:, 3]
    across = normal @ to_ray
    return np.outer(M @ centre + p, across) - height * (M @ to_ray), across, height


def _homography_maps(H: np.ndarray, across: np.ndarray, height: float, columns: slice, rows: slice,
                     unit: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Where the grid's pixels (``columns`` x ``rows``) fall through :func:`_plane_homography`'s ``H``, in
    pixels of ``unit`` (u, v) full-resolution pixels: (h, w, 2) float32 maps for cv2.remap, and (h, w) where
    the ray meets the plane in front of both cameras."""
    maps = np.empty((rows.stop - rows.start, columns.stop - columns.start, 2), np.float32)
    valid = np.empty(maps.shape[:2], np.uint8)
    plane_homography_maps(np.ascontiguousarray(H, np.float64), np.ascontiguousarray(across, np.float64),
                          float(height), columns.start, rows.start, float(unit[0]), float(unit[1]), maps, valid)
    return maps, valid.view(bool)


def _plane_homography_maps(view: _View, other: _View, plane: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_plane_maps` of :func:`_plane_points` for two pinhole cameras without distortion, in closed
    form: through a plane, one view's pixels map onto another's by a homography, so the table point of
    each coarse pixel need not be found and projected one by one."""
    cw, ch = view.coarse_size
    to_full = np.array([[view.sx, 0.0, 0.5 * view.sx - 0.5], [0.0, view.sy, 0.5 * view.sy - 0.5], [0.0, 0.0, 1.0]])
    H, across, height = _plane_homography(view, other, plane, to_full)
    maps, valid = _homography_maps(H, across, height, slice(0, cw), slice(0, ch), (other.sx, other.sy))
    coarse_u, coarse_v = maps[..., 0], maps[..., 1]
    ow, oh = other.coarse_size
    inside = valid & (coarse_u >= 0) & (coarse_v >= 0) & (coarse_u <= ow - 1) & (coarse_v <= oh - 1)
    return maps, inside.ravel()


def _fine_window_maps(view: _View, other: _View, maps: np.ndarray, fine_window: tuple[slice, slice]) -> np.ndarray:
    """(h, w, 2) float32: where each fine pixel of ``view``'s window falls in ``other``'s fine image through
    the plane. The plane's mapping is smooth: the coarse ``maps`` (:meth:`_View.mapping`), interpolated,
    place the fine pixels."""
    fh, fw = _fine_grey(view).shape
    ofh, ofw = _fine_grey(other).shape
    fine_maps = cv2.resize(maps, (fw, fh), interpolation=cv2.INTER_LINEAR)[fine_window]
    fine_maps[..., 0] = (fine_maps[..., 0] + 0.5) * (ofw / other.coarse_size[0]) - 0.5
    fine_maps[..., 1] = (fine_maps[..., 1] + 0.5) * (ofh / other.coarse_size[1]) - 0.5
    return fine_maps


def _fine_warped(view: _View, other: _View, plane: np.ndarray, maps: np.ndarray,
                 fine_window: tuple[slice, slice]) -> np.ndarray:
    """``other``'s fine grey image mapped through ``plane`` onto ``view``'s ``fine_window`` (``maps``, the coarse
    mapping: :meth:`_View.mapping`): the texture's parallax and the grain's compare the same mapped image, so
    it is made once per pair of views and window."""
    rows, columns = fine_window
    key = (*_pair(other, plane), rows.start, rows.stop, columns.start, columns.stop)
    if key not in view.fine_warped:
        view.fine_warped[key] = _remapped(_fine_grey(other), _fine_window_maps(view, other, maps, fine_window),
                                          cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return view.fine_warped[key]


_CHROMA_OFFSET = 12.0
#: How far a shadow's chromaticity may move from the lit table's (a warm lamp's colour leaves it):
#: less than an object's print of another colour does.
_LAMP_HUE_SHIFT = 0.12


def _shadowless_difference(image: np.ndarray, background: np.ndarray) -> np.ndarray:
    difference = _relative_difference(image, background)
    # A shadow multiplies every channel by about the same factor below 1: compare chromaticities.
    # The offset keeps a dark pixel's noise from passing for a change of colour.
    brightness = _brightness(image) + 3 * _CHROMA_OFFSET
    ground = _brightness(background) + 3 * _CHROMA_OFFSET
    chroma = np.abs((image + _CHROMA_OFFSET) / brightness[..., None]
                    - (background + _CHROMA_OFFSET) / ground[..., None]).sum(axis=2) * 1.5
    darker = (brightness < 1.05 * ground) & (brightness > 0.15 * ground)
    return np.where(darker, np.minimum(difference, chroma), difference)


def _noise_level(evidence: np.ndarray) -> float:
    """A robust scale of the evidence on the table (most of the image): its median plus spread."""
    evidence = np.asarray(evidence)
    if evidence.dtype != np.float32:
        evidence = evidence.astype(np.float64)
    found = median_and_spread(np.ascontiguousarray(evidence).ravel())
    if found is None:
        return 0.05
    median, spread = found
    return median + 3.0 * 1.4826 * spread


def _component_near(binary: np.ndarray, point: np.ndarray, reach: float) -> np.ndarray | None:
    """The connected region of ``binary`` that holds ``point`` or, failing that (or where it is a mere
    speck), the largest region within ``reach`` px of it; None if there is none."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(binary, connectivity=8)
    if count <= 1:
        return None
    h, w = binary.shape
    x, y = int(round(min(max(point[0], 0), w - 1))), int(round(min(max(point[1], 0), h - 1)))
    label = labels[y, x]
    # The aim may fall on a speck inside the object's face (a white face that differs from the table in
    # its edges and print only): the object is the large region around it, not the speck.
    if label == 0 or stats[label, cv2.CC_STAT_AREA] < _SPECK:
        ys, xs = np.nonzero(labels)
        near = np.hypot(xs - point[0], ys - point[1]) <= reach
        if not near.any():
            return None
        candidates = np.unique(labels[ys[near], xs[near]])
        label = int(candidates[np.argmax(stats[candidates, cv2.CC_STAT_AREA])])
    return (labels == label).astype(np.uint8) * 255


def _regions_holding(binary: np.ndarray, marks: np.ndarray) -> np.ndarray:
    """The connected regions of ``binary`` (0/255) that hold a pixel of ``marks`` (0/255), 0/255."""
    count, labels = cv2.connectedComponents(binary, connectivity=8)
    holding = np.zeros(count, bool)
    holding[labels[marks > 0]] = True
    holding[0] = False
    return np.where(holding[labels], 255, 0).astype(np.uint8)


def _components_near(binary: np.ndarray, point: np.ndarray, reach: float) -> np.ndarray:
    """All connected regions of ``binary`` with a pixel within ``reach`` px of ``point`` (0/255)."""
    count, labels = cv2.connectedComponents(binary, connectivity=8)
    ys, xs = np.nonzero(labels)
    near = np.hypot(xs - point[0], ys - point[1]) <= reach
    chosen = np.zeros(count, bool)
    chosen[np.unique(labels[ys[near], xs[near]])] = True
    chosen[0] = False
    return np.where(chosen[labels], 255, 0).astype(np.uint8)


def auto_silhouettes(images: Sequence[np.ndarray], cameras: Sequence[Camera], *, support_plane=None,
                     backgrounds: Sequence[np.ndarray | None] | None = None,
                     aim_cameras: Sequence[Camera] | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """One filled silhouette per view, (H, W) uint8 0/255, of what stands where the views converge,
    and its outline ((M, 2) int32, as :func:`core_cy.segment.segment_with_outline` gives).

    Parameters
    ----------
    images : sequence of (H, W, 3) ndarray of uint8
        The views' BGR photographs, as the lens saw them.
    cameras : sequence of Camera
        The views' cameras, in the same order.
    support_plane : (4,) array_like, optional
        ``[nx, ny, nz, d]``, the object on the side where ``n . x + d >= 0``.
    backgrounds : sequence of (H, W, 3) ndarray of uint8 or None, optional
        Per view, a picture of the empty workspace from the same pose, or None.
    aim_cameras : sequence of Camera, optional
        The cameras whose optical axes give the aim (default: ``cameras``); a
        scan whose other views came with masks names all its cameras here.

    An object cut off by an image's edge gives a silhouette cut off there
    too: what the view shows of it. The reconstruction takes the edge on the
    image's border for no edge (:func:`core_cy.edges.edge_samples`) and carves
    nothing that projects out of an image, so the model is of what the views
    saw together.

    Raises
    ------
    ImageError
        If an image or background is not a (H, W, 3) uint8 array, or a background's size is not its
        image's.
    SilhouetteError
        If nothing stands out near the views' aim in a view (naming it).
    GeometryError
        If the views' optical axes do not converge.
    """
    if len(images) != len(cameras):
        raise ValueError(f"got {len(images)} images for {len(cameras)} cameras")
    backgrounds = list(backgrounds) if backgrounds is not None else [None] * len(images)
    if len(backgrounds) != len(images):
        raise ValueError(f"got {len(backgrounds)} backgrounds for {len(images)} images")
    views = []
    for index, (image, camera, background) in enumerate(zip(images, cameras, backgrounds)):
        if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
            raise ImageError("expected a (H, W, 3) uint8 BGR image", view=index)
        if background is not None:
            if (not isinstance(background, np.ndarray) or background.dtype != np.uint8 or background.ndim != 3
                    or background.shape[2] != 3):
                raise ImageError("expected the background as a (H, W, 3) uint8 BGR image", view=index)
            if background.shape != image.shape:
                raise ImageError(f"the background is {background.shape[1]}x{background.shape[0]} pixels, but its "
                                 f"image is {image.shape[1]}x{image.shape[0]}", view=index)
        views.append(_View(index, image, camera, background))
        if background is not None:
            _matched_exposure(views[-1])
    aim = aim_point(cameras if aim_cameras is None else aim_cameras)
    plane = None
    if support_plane is not None:
        # The cameras look down on the table, so they say which side of it the object is on. The views
        # may converge at a flat object's foot or a little under the table (an arm aims at where the
        # object touches it as well as at its middle): the aim is then taken on the table.
        plane = check_support_plane(support_plane, np.mean([camera.center for camera in cameras], axis=0))
        aim = aim + max(0.0, -float(plane[:3] @ aim + plane[3])) * plane[:3]
        if parallax_capable(len(views)):
            _even_the_light(views, plane)
    standing: list[np.ndarray | None] = [None] * len(views)
    # With two views the parallax cannot tell the object in one from the other's object mapped through
    # the plane onto the table beside it (each view's first look holds both): the aim seeds the cut.
    parallax = plane if parallax_capable(len(views)) else None
    # With every view's empty workspace, the change against it is compared through the plane.
    every_background = parallax is not None and all(view.background is not None for view in views)
    if parallax is not None and not every_background:
        # What stands out in each view, on the first look: where another view's plane point lies behind
        # it, that view sees the object, not the table, and cannot confirm or deny a pixel (nor, with
        # backgrounds, confirm that a darkening there is a shadow on the table).
        for view in views:
            evidence = np.nan_to_num(_parallax_evidence(view, [v for v in views if v is not view], parallax))
            first = np.where(evidence > 2.5 * max(_noise_level(evidence), _NOISE_FLOOR), 255, 0).astype(np.uint8)
            opened = cv2.morphologyEx(first, cv2.MORPH_OPEN, _SMALL)
            standing[view.index] = cv2.dilate(_grown_by_colour(view, opened, _coarse_aim(view, aim)), _SMALL)
    if every_background:
        assert parallax is not None
        cuts = _background_cuts(views, parallax, aim)
    else:
        cuts = [_first_cut(view, views, parallax, aim, standing) for view in views]
        if parallax is not None:
            # A view that sees none of its shadow in the open (a lamp behind a lying can, whose shadow the can
            # hides from every other view) cannot tell the shadow hidden behind the object from its side in
            # shade; the shadow's depth is the light's, the same from any view, and the others see it: it is
            # cut again knowing theirs.
            seen = [view.shadow_seen for view in views if view.background is None and view.shadow_seen is not None]
            for i, view in enumerate(views):
                if view.background is None and view.shadow_seen is None and seen:
                    view.open_shadow = functools.partial(np.concatenate, seen)
                    cuts[i] = _first_cut(view, views, parallax, aim, standing)
        if parallax is not None:
            # Once more with each view's silhouette hiding the table points behind it too: where another
            # view sees the object in front of the table point, it neither confirms nor denies it. The
            # second look adds what the first one's false agreements hid; what it drops (a part seen only
            # as hidden, which the graph cut gave the table this time) the first look keeps.
            hiding = [cv2.bitwise_or(first, cut) for first, (cut, _) in zip(standing, cuts) if first is not None]
            looking = set(range(len(views)))
            # A look may find in a view what the looks before missed: a low face (a flat box's top) stands
            # out through the plane only along its outline, a line that may hold only a corner, until the
            # other views' silhouettes hide the table points under it; each view found whole hides them
            # from the rest. So the other views are looked at again while some view's silhouette grows by
            # a part (:data:`_GROWN`); as many looks as views at most, each finding a view's part or ending.
            for _ in range(len(views)):
                again = {i: _first_cut(views[i], views, parallax, aim, hiding, cuts[i][1]) for i in looking}
                for i, (second, score) in again.items():
                    cuts[i] = (_filled_region(cv2.bitwise_or(cuts[i][0], second), views[i]), score)
                grown = set()
                for i, (cut, _) in enumerate(cuts):
                    gained = cv2.countNonZero(cv2.bitwise_and(cut, cv2.bitwise_not(hiding[i])))
                    if gained > _GROWN * cv2.countNonZero(cut):
                        grown.add(i)
                    hiding[i] = cv2.bitwise_or(hiding[i], cut)
                looking = {i for i in range(len(views)) if grown - {i}}
                if not looking:
                    break
    masks = [mask for mask, _ in cuts]
    masks = _agreed(views, masks, [score for _, score in cuts], plane, aim)
    for view, mask in zip(views, masks):
        # A speck is no silhouette: carved from, it would put the object's centre off the other views' rays,
        # and the error would blame the poses.
        if cv2.countNonZero(mask) < _SPECK:
            raise SilhouetteError(_SPECK_LEFT, view=view.index)
    return [_refined(view, mask, on_plane=plane is not None) for view, mask in zip(views, masks)]


def unsure_pixels(image: np.ndarray, silhouette: np.ndarray, asked: np.ndarray | None = None) -> np.ndarray:
    """(H, W) bool: the pixels about ``silhouette`` whose side its colours cannot confirm (issue 21).

    They are those clearly darker than the table (:data:`_SHADE_CLEAR`): inside the silhouette, those
    of the table's colour too (a shadow dims the table's light, not its colour: within
    :data:`_TABLE_FAR` of it, or of it darkened), or darker than the deepest shadow the table takes
    (:data:`_DEEPEST_SHADOW` of its brightness), where a shadow may have been taken in; outside it, any
    such, where a face of the object turned from the light may have been left out (in the dark, a face's
    colour tells it from a shadow's little). And the stretches of the outline across which the image
    shows no step (:func:`_unstepped_outline`): table on both sides, where a strip of table was taken in
    beside an object of the table's colour and light (issue 20). The table is the ring around the
    silhouette (:data:`_TABLE_RING`): its median colour, and its brightness's median and spread.

    Parameters
    ----------
    image : (H, W, 3) ndarray of uint8
        The view's BGR photograph, on the silhouette's pixel grid.
    silhouette : (H, W) ndarray of uint8
        Nonzero on the object, as :func:`auto_silhouettes` draws it.
    asked : (H, W) ndarray of bool, optional
        Only these pixels are asked about (the others come back sure): each is judged as it would be
        among all.

    Raises
    ------
    ImageError
        If the image is not (H, W, 3) uint8 or its size is not the silhouette's.
    """
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ImageError("expected a (H, W, 3) uint8 BGR image")
    if silhouette.shape != image.shape[:2]:
        raise ImageError(f"the silhouette is {silhouette.shape[1]}x{silhouette.shape[0]} pixels, but its image is "
                         f"{image.shape[1]}x{image.shape[0]}")
    inside = (silhouette > 0).astype(np.uint8)
    size = np.sqrt(cv2.countNonZero(inside))
    unsure = np.zeros(inside.shape, bool)
    if not size:
        return unsure
    # Within the silhouette's box grown by the ring, each pixel's distance from the silhouette.
    x, y, w, h = cv2.boundingRect(inside)
    reach = int(np.ceil(_TABLE_RING[1] * size))
    x0, y0 = max(0, x - reach), max(0, y - reach)
    x1, y1 = min(inside.shape[1], x + w + reach), min(inside.shape[0], y + h + reach)
    distance = cv2.distanceTransform(1 - inside[y0:y1, x0:x1], cv2.DIST_L2, 3)
    near = distance <= _TABLE_RING[0] * size
    window = image[y0:y1, x0:x1]
    table = window[~near & (distance <= _TABLE_RING[1] * size)]
    if not len(table):
        return unsure
    # The medians of grey levels and of their sums, whole numbers, by counting (the kernel's median).
    table_colour = np.array([median(np.ascontiguousarray(table[:, k], np.float64)) for k in range(3)])
    brightness = table.sum(axis=1, dtype=np.float64)
    table_brightness = median(brightness)
    spread = median(np.abs(brightness - table_brightness))
    rows, columns = np.nonzero(near if asked is None else near & asked[y0:y1, x0:x1])
    colours = window[rows, columns].astype(np.float64)
    darker = colours.sum(axis=1) < table_brightness - _SHADE_CLEAR * spread
    # Inside, darker than the deepest shadow the table takes (under the object's foot): no colour is left
    # there to tell a shadow from a face turned from the light.
    doubtful = darker & ((inside[y0:y1, x0:x1][rows, columns] == 0)
                         | (_unlike_table(colours[None], table_colour[None])[0] < _TABLE_FAR)
                         | (colours.sum(axis=1) < _DEEPEST_SHADOW * table_brightness))
    unsure[rows[doubtful] + y0, columns[doubtful] + x0] = True
    unstepped = _unstepped_outline(window, inside[y0:y1, x0:x1], spread)
    unsure[y0:y1, x0:x1] |= unstepped if asked is None else unstepped & asked[y0:y1, x0:x1]
    return unsure


def _unstepped_outline(image: np.ndarray, inside: np.ndarray, spread: float) -> np.ndarray:
    """(H, W) bool: the stretches of ``inside``'s outline (0/1 uint8, on ``image``'s grid) across which
    ``image`` shows no step, widened to a band (:data:`_STEP_REACH`).

    Where the mean colour just within the outline is that just beyond it, to within :data:`_STEP_CLEAR`
    of the table's own spread (``spread``, its brightness's median absolute deviation, over the three
    channels), nothing in the image says that the outline runs there: a strip of table taken in beside an
    object of the table's colour and light has a false edge with table on both sides. The band is wider
    than an edge's blur, so that :func:`core_cy.edges.samples_near` counts it.
    """
    within = cv2.erode(inside, _SMALL)
    beyond = 1 - cv2.dilate(inside, _SMALL)
    # Only the outline's own pixels are asked, so each side's sums are taken there alone.
    rows, columns = np.nonzero((inside > 0) & (within == 0))
    means, counts = [], []
    for side in (within, beyond):
        count, total = _window_sums(side, image * side[..., None], rows, columns, _STEP_REACH)
        means.append(total / np.maximum(count, 1.0)[:, None])
        counts.append(count)
    step = np.abs(means[0] - means[1]).sum(axis=1)
    # Each side's mean over a few pixels at least: at a thin spike of the outline one side is all but empty.
    flat = np.zeros(inside.shape, np.uint8)
    flat[rows, columns] = (counts[0] >= _STEP_REACH) & (counts[1] >= _STEP_REACH) & (step < _STEP_CLEAR * spread)
    return _dilated(flat, _STEP_REACH) > 0


def _window_sums(side: np.ndarray, colours: np.ndarray, rows: np.ndarray, columns: np.ndarray,
                 reach: int) -> tuple[np.ndarray, np.ndarray]:
    """(N,) and (N, 3) float32: the sums of ``side`` ((h, w) uint8) and of ``colours`` ((h, w, 3) uint8) over
    the window of ``reach`` px either way around each of the N pixels (``rows``, ``columns``), the images
    reflected about their edges as cv2.boxFilter's default border reflects them. Sums of whole numbers:
    the integral image's are exact, as the box filter's are, and need not be taken at every pixel."""
    size = 2 * reach + 1
    sums = []
    for image in (side, colours):
        integral = cv2.integral(cv2.copyMakeBorder(image, reach, reach, reach, reach, cv2.BORDER_REFLECT_101))
        sums.append((integral[rows + size, columns + size] - integral[rows, columns + size]
                     - integral[rows + size, columns] + integral[rows, columns]).astype(np.float32))
    return sums[0], sums[1]


#: The colour either side of the outline is averaged within this many pixels of each outline pixel (and the
#: outline without a step is widened by as much): beyond an edge's blur, over a few of a wood's grain lines.
_STEP_REACH = 5
#: An outline shows no step where its two sides' mean colours differ by less than this share of the
#: table's spread: measured against the true outlines of seeds 0-5, the table-coloured box's false edges
#: mostly lie under it and its true ones mostly over it, and hardly any other scene's edges do.
_STEP_CLEAR = 0.75


#: Within the first distance from the silhouette (a share of the square root of its area, its size) the
#: pixels are asked about; between it and the second lies the ring whose median colour is the table's:
#: beyond the object's blurred rim and most of its shadow, near enough to be lit as the table under it.
_TABLE_RING = (0.25, 0.6)
#: A pixel is darker than the table when its brightness lies this many times the ring's median absolute
#: deviation below the ring's median: beyond the table's own grain and print.
_SHADE_CLEAR = 3.0


#: A look that adds over this share of a view's silhouette found a part the looks before missed (a face);
#: less only redraws its edge, which hides hardly more of the table from the other views.
_GROWN = 0.25


def _grown_by_colour(view: _View, standing: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """``standing`` (0/255) with what joins its pieces near the aim in their own colours (issue 20).

    A low face of one colour (a flat box's top) stands out through the plane only where another view sees
    the table beside it, at its corners: elsewhere a view that sees the face in front of the table point
    agrees with it, and the first look finds only corners, so hides too little for the next. The corners'
    own colour joins the rest of the face: a pixel near the aim joins where it is within
    :data:`_SEED_NEAR` of a piece's colour and over :data:`_TABLE_FAR` from every colour of the table
    away from the aim, and from the table's colour darkened (a shadow is table)."""
    cw, ch = view.coarse_size
    reach = 0.25 * np.hypot(cw, ch)
    near = _components_near(standing, centre, reach)
    if not cv2.countNonZero(near):
        return standing
    distance = np.hypot((np.arange(cw) - centre[0])[None, :], (np.arange(ch) - centre[1])[:, None])
    table = view.coarse[(distance > reach) & (standing == 0)]
    seeds = view.coarse[near > 0]
    if len(table) < 20:
        return standing
    table = table[:: max(1, len(table) // _COLOUR_SAMPLES)]
    seeds = seeds[:: max(1, len(seeds) // _COLOUR_SAMPLES)]
    inside = distance <= reach
    colours = view.coarse[inside]
    # Only whether a colour lies within _SEED_NEAR of a piece's and beyond _TABLE_FAR of the table's counts,
    # not which is nearest (any_within: a grid of the samples, the distances cKDTree's), and the table is
    # looked at only for the colours that passed the pieces' test and the shade's.
    joins = np.empty(len(colours), np.uint8)
    any_within(colours, np.ascontiguousarray(seeds), _SEED_NEAR, False, joins)
    joins = joins.view(bool)
    # A shadow is the table's colour darkened: table too.
    from_shade = _unlike_table(colours[joins][None], np.median(table, axis=0)[None])[0]
    candidates = np.flatnonzero(joins)[from_shade > _TABLE_FAR]
    near_table = np.empty(len(candidates), np.uint8)
    any_within(np.ascontiguousarray(colours[candidates]), np.ascontiguousarray(table), _TABLE_FAR, True, near_table)
    joins[:] = False
    joins[candidates[near_table == 0]] = True
    like = np.zeros((ch, cw), np.uint8)
    like[inside] = np.where(joins, 255, 0)
    like = cv2.bitwise_or(like, near)
    count, labels = cv2.connectedComponents(like, connectivity=8)
    chosen = np.zeros(count, bool)
    chosen[np.unique(labels[near > 0])] = True
    chosen[0] = False
    return cv2.bitwise_or(standing, np.where(chosen[labels], 255, 0).astype(np.uint8))


#: Colours sampled of the pieces and of the table, at most.
_COLOUR_SAMPLES = 300
#: Grey levels (BGR distance) within a piece's colour, and beyond the table's, of a pixel that joins it.
_SEED_NEAR = 8.0
_TABLE_FAR = 40.0


def parallax_capable(view_count: int) -> bool:
    """Whether the plane's parallax can find the object in ``view_count`` views (see auto_silhouettes)."""
    return view_count > 2


def _even_the_light(views: Sequence[_View], plane: np.ndarray) -> None:
    """Divide each view's coarse pictures (image and background) by its own smooth light field, where
    the views' light differs by more than a lens's fall-off (:data:`_LIGHT_FIELD_BEYOND`).

    A table point is not equally bright in every picture: each camera sets its own exposure and white
    balance, a lens darkens its corners, a renderer may shade the ground in the picture rather than on
    the table. All of it is a smooth field over each view's own image, which no parallax makes; the
    plane's parallax compares one view's table with another's through the plane and takes any
    difference for something standing there. So each view's field, a plane per channel in its log over
    its own image's coordinates, is fitted to the log ratios of every pair of views at the table points
    they share, robustly (the half that differs most from the fit, where the object, its parallax and
    their edges are, is left out of the next fit). A view's field is known where it shares table points
    with another; beyond them it is held at the values found there, not extrapolated. Within
    exp(+-_LIGHT_FIELD_BEYOND) the cues' noise floors take the difference in their stride, and the
    pictures are left as they are."""
    rows_of_pairs = []
    for view in views:
        for other in views:
            if other.index <= view.index:
                continue
            maps, inside = view.mapping(other, plane)
            cw, ch = view.coarse_size
            sample = np.zeros((ch, cw), bool)
            sample[::_LIGHT_FIELD_STEP, ::_LIGHT_FIELD_STEP] = True
            sample &= inside.reshape(ch, cw)
            ys, xs = np.nonzero(sample)
            there = maps[ys, xs]
            seen = _remapped(other.coarse, there[None], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[0]
            here = view.coarse[ys, xs]
            lit = (here.min(axis=1) > _LIGHT_FIELD_DARKEST) & (seen.min(axis=1) > _LIGHT_FIELD_DARKEST)
            if lit.sum() < _LIGHT_FIELD_MIN_SAMPLES:
                continue
            rows_of_pairs.append((view.index, _light_basis(view, xs[lit], ys[lit]),
                                  other.index, _light_basis(other, there[lit, 0], there[lit, 1]),
                                  np.log(here[lit]) - np.log(seen[lit])))
    if not rows_of_pairs:
        return
    terms = 3
    columns = terms * len(views)
    design = np.zeros((sum(len(r[4]) for r in rows_of_pairs) + 1, columns))
    log_ratio = np.zeros((design.shape[0], 3))
    start = 0
    for i, basis_i, j, basis_j, ratio in rows_of_pairs:
        stop = start + len(ratio)
        design[start:stop, terms * i:terms * (i + 1)] = basis_i
        design[start:stop, terms * j:terms * (j + 1)] = -basis_j
        log_ratio[start:stop] = ratio
        start = stop
    # Only ratios are seen: the fields' overall level is free, and is held at no change on average.
    design[-1, ::terms] = 1.0
    # Started from each pair's median ratio (one gain per pair), which the object and its parallax, less
    # than half of the table the two share, cannot pull far; each fit is made of the half of the samples
    # closest to the one before (least trimmed squares). An object near the camera and its parallax come
    # near half of what two views share, and a textured table's misregistration spreads the table's own
    # residuals: a bound of three spreads about their median took the object's in, and they pulled the
    # field to them (a box filling an eighth of each view, on a grid, under even light: fields of
    # e^-0.7 to e^0.9, and every view lost).
    fitted = np.concatenate([np.broadcast_to(np.median(ratio, axis=0), ratio.shape)
                             for *_, ratio in rows_of_pairs] + [np.zeros((1, 3))])
    coefficients = np.zeros((columns, 3))
    for _ in range(4):
        residual = np.abs(log_ratio - fitted).sum(axis=1)
        keep = residual <= max(float(np.median(residual[:-1])), _LIGHT_FIELD_TOLERANCE)
        keep[-1] = True
        # The normal equations (a few columns a view against thousands of samples), held solvable where a
        # view shares too little table with any other to have rows: its field stays 1.
        kept = design[keep]
        coefficients = np.linalg.solve(kept.T @ kept + 1e-9 * np.eye(columns), kept.T @ log_ratio[keep])
        fitted = design @ coefficients
    relative = np.abs(fitted[:-1])
    if np.percentile(relative, 98) <= _LIGHT_FIELD_BEYOND or relative.max() > _LIGHT_FIELD_AT_MOST:
        return
    sampled: dict[int, list[np.ndarray]] = {view.index: [] for view in views}
    for i, basis_i, j, basis_j, _ in rows_of_pairs:
        sampled[i].append(basis_i @ coefficients[terms * i:terms * (i + 1)])
        sampled[j].append(basis_j @ coefficients[terms * j:terms * (j + 1)])
    for view in views:
        if not sampled[view.index]:
            continue
        found = np.concatenate(sampled[view.index])
        cw, ch = view.coarse_size
        ys, xs = np.mgrid[0:ch, 0:cw]
        log_field = _light_basis(view, xs.ravel(), ys.ravel()) @ coefficients[terms * view.index:terms * (view.index + 1)]
        field = np.exp(np.clip(log_field, found.min(axis=0), found.max(axis=0)))
        field = field.reshape(ch, cw, 3).astype(np.float32)
        view.coarse = view.coarse / field
        if view.background is not None:
            view.background = view.background / field
        view.light_field = field


def _light_basis(view: _View, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """(N, 3) the terms of a view's light field (its log, per channel) at its coarse pixels (xs, ys)."""
    cw, ch = view.coarse_size
    x = np.asarray(xs, np.float64) / max(cw - 1, 1) * 2.0 - 1.0
    y = np.asarray(ys, np.float64) / max(ch - 1, 1) * 2.0 - 1.0
    return np.column_stack([np.ones_like(x), x, y])


#: Every this many coarse pixels (each way) a shared table point samples the light fields.
_LIGHT_FIELD_STEP = 4
#: Channels this dark (grey levels) say little of a ratio: the noise is most of them.
_LIGHT_FIELD_DARKEST = 8.0
#: A pair of views sharing fewer table samples than this says nothing of the light.
_LIGHT_FIELD_MIN_SAMPLES = 200
#: Residuals (log ratio summed over channels) this small are always the table's.
_LIGHT_FIELD_TOLERANCE = 0.06
#: Two views' light within exp(+-0.2) of each other at the table points they share (a lens darkens its
#: corners by up to about a fifth against its centre) is left to the cues' noise floors; beyond it
#: (another exposure or white balance, a ground shaded in the picture) each view's is evened out.
_LIGHT_FIELD_BEYOND = 0.2
#: A field that would change a view's light by more than a factor of e (log 1) against another's is no
#: camera's or lamp's but the fit's failure (too little table shared): the pictures are left as they are.
_LIGHT_FIELD_AT_MOST = 1.0


def _excess_evidence(mask: np.ndarray, hull: np.ndarray, score: np.ndarray) -> np.ndarray:
    """The view's own evidence ``score`` at a silhouette's pixels outside a hull, (N,)."""
    return score[(mask > 0) & (hull == 0)]


def _excess_on_plane(mask: np.ndarray, hull: np.ndarray, score: np.ndarray) -> bool:
    """Whether at least :data:`_ON_PLANE` of a silhouette's pixels outside a hull are the plane by the view's
    own evidence (a score under 1: they do not stand out from the table, nor is their table point hidden)."""
    evidence = _excess_evidence(mask, hull, score)
    return bool(evidence.size) and float(np.mean(evidence < 1.0)) >= _ON_PLANE


#: A view's excess is taken to be on the plane when this share of it is by the view's own evidence: a
#: part of the object that the other views missed stands out or hides its table point somewhere.
_ON_PLANE = 0.95


def _excess_surely_standing_out(mask: np.ndarray, hull: np.ndarray, score: np.ndarray) -> bool:
    """Whether over half of a silhouette's pixels outside a hull stand out by the view's own evidence beyond
    :data:`_SURE` (in units of its noise): far beyond what a tint or the noise makes on the table."""
    evidence = _excess_evidence(mask, hull, score)
    return bool(evidence.size and 2 * np.count_nonzero(evidence > _SURE) > evidence.size)


def _excess(mask: np.ndarray, hull: np.ndarray) -> float:
    """The share of a silhouette outside a hull, in units of :data:`_DISAGREEMENT` (above 1: too much)."""
    area = max(cv2.countNonZero(mask), 1)
    return cv2.countNonZero(cv2.bitwise_and(mask, cv2.bitwise_not(hull))) / area / _DISAGREEMENT


def _agreed(views: Sequence[_View], masks: list[np.ndarray], scores: Sequence[np.ndarray | None],
            plane: np.ndarray | None, aim: np.ndarray) -> list[np.ndarray]:
    """The views checked against each other, one correction at a time, each view corrected once.

    A silhouette that reaches out of the other views' hull takes in too much (a shadow, a stretch of
    table); one that holds too little (the aim alone seeded it, and it found part of the object; or
    its evidence missed a face the others found) carves every other view's hull, so that they reach
    out of it. Which is which: a view without which none of the others reaches out holds too little,
    and is cut again within their hull (seeded by its evidence: within their hull and its own
    silhouette, by the colour models of its own seeds), unless what reaches out is on the plane by its
    own view's evidence (:func:`_excess_on_plane`): with three views, leaving any one out clears the
    others' excess, and the view reaching out is the one to blame;
    failing that, the view that reaches out most is cut again with what lies outside marked table (a
    view seeded by its own evidence only when no other view reaches out, and what reaches out does not
    stand out surely by that evidence: :func:`_excess_surely_standing_out`);
    when all agree, a view seeded by the aim alone that covers under :data:`_TOO_SMALL` of the
    others' hull is cut again within it.
    """
    done: set[int] = set()
    refused: set[int] = set()  # views whose cut again was given up: they keep their silhouettes, uncorrected
    trimmed: set[int] = set()  # views cut back to the others' hull: they lost only what reached out of it
    everyone = set(range(len(views)))
    hulls: _Hulls | None = None
    for _ in range(len(views)):
        hulls = _Hulls(views, masks, plane, aim)
        excess = {i: _excess(masks[i], hulls.of(everyone - {i})) for i in everyone}
        culprit, relief = -1, 0.0
        # With three views, leaving any one out of the carving clears the others' excess, so a view's own
        # evidence says which excess is real: one that lies (nearly) all on the plane by it is table or
        # shadow that the view's graph cut took in, and no other view is to blame for it.
        on_plane = {j for j, score in enumerate(scores) if score is not None and excess[j] > 1.0
                    and _excess_on_plane(masks[j], hulls.of(everyone - {j}), score)}
        for k in everyone - done:
            others = everyone - {k}
            if len(views) > 2 and max(excess[j] for j in others) > 1.0 and not on_plane & others:
                without = [_excess(masks[j], hulls.into(others - {j}, j)) for j in others]
                gain = sum(excess[j] for j in others) - sum(without)
                if max(without) <= 1.0 and gain > relief:
                    culprit, relief = k, gain
        if culprit >= 0:
            done.add(culprit)
            view, score = views[culprit], scores[culprit]
            hull = hulls.of(everyone - {culprit})
            if score is None:
                masks[culprit] = _cut_again_around_aim(views, masks, culprit, hull, aim)
            else:
                # The view's own evidence missed part of the object (a top of the table's colour and light,
                # a dark face taken for the shadow beside it) that the others agree on: what the others'
                # hull adds is looked for there too, by the colour models its own seeds trained, and
                # nothing beyond the two is. The colour models may take the shadow by the foot there too; the
                # plane's parallax, the evidence without an empty workspace, tells it (_shadows_left_out).
                cut = _cut_within(view, cv2.bitwise_or(masks[culprit], hull), score)
                if view.background is None:
                    cut = _shadows_left_out(view, masks[culprit], cut, score, hull)
                else:
                    cut = _shadows_keeping_the_grain_left_out(view, masks[culprit], cut, hull)
                masks[culprit] = cut
            continue
        # A view seeded by the aim alone is cut again within the others' hull. A view whose evidence seeded
        # it (the plane's parallax, the empty workspace) knows better than a hull that another view's miss
        # carved too small (on the benchmark's printed scenes every such cut lost), unless it is the only
        # one that reaches out: then two or more views, which agree with each other and with it elsewhere,
        # all see empty space where it sees more (a tint that JPEG put on the table in that view alone). But a view
        # alone in its excess that stands out there surely by its own evidence (a box's side against the empty
        # workspace) is not told by a tint: there the others missed what it sees (a box of the table's colour,
        # whose top two views left out), and it keeps its silhouette.
        candidates = [i for i in everyone - done - refused if excess[i] > 1.0 and (
            (evidence := scores[i]) is None
            or (_alone_in_excess(i, excess)
                and not _excess_surely_standing_out(masks[i], hulls.of(everyone - {i}), evidence)))]
        if not candidates:
            # All agree, but a view seeded by the aim alone may still hold only part of the object.
            small = {i: cv2.countNonZero(masks[i]) / max(cv2.countNonZero(hulls.of(everyone - {i})), 1)
                     for i in everyone - done if scores[i] is None}
            if not small or min(small.values()) >= _TOO_SMALL:
                break
            index = min(small, key=small.__getitem__)
            done.add(index)
            masks[index] = _cut_again_around_aim(views, masks, index, hulls.of(everyone - {index}), aim)
            continue
        index = max(candidates, key=excess.__getitem__)
        done.add(index)
        view, score = views[index], scores[index]
        hull = hulls.of(everyone - {index})
        if score is None:
            masks[index] = _cut_again_around_aim(views, masks, index, hull, aim)
        else:
            kept = cv2.bitwise_and(masks[index], hull)
            if cv2.countNonZero(kept) < _SPECK:
                raise SilhouetteError(_NOTHING + " (the other views see nothing there)", view=view.index)
            cut = _graph_cut(view, kept, score, cv2.bitwise_not(hull))
            # The cut is to drop what lies beyond the others' hull, not what they agree on: one that keeps
            # less than _KEPT_BY_CUT of that failed to model the object there (a box of its table's colour),
            # and the view keeps its silhouette, as one not corrected (its bays are looked into below).
            if cv2.countNonZero(cv2.bitwise_and(cut, kept)) >= _KEPT_BY_CUT * cv2.countNonZero(kept):
                masks[index] = cut
                trimmed.add(index)
            else:
                done.discard(index)
                refused.add(index)
    else:
        hulls = None  # the last round corrected a view: the hulls are to be carved again
    if len(views) > 2:
        hulls = hulls or _Hulls(views, masks, plane, aim)
        # A view cut back to the others' hull dropped what reached out of it (its shadow, a stretch of table),
        # but a face it missed (a dark can's top of its mat's colour and light) is still missing: its bays
        # are looked into too, as those of a view not corrected. A view cut again within the others' hull
        # has looked there already.
        # A look again asks what hid the table points from the others before any view grew in a look.
        before_the_looks = masks
        looked = _bays_looked_into(views, masks, scores, hulls, done - trimmed, plane, aim)
        # A face found in one view's bays widens the other views' hull, which was carved while that view still
        # missed it: their bays are looked into again, within the hull of the silhouettes as they are now,
        # while some view grows by a bay (as many looks as views at most).
        for _ in range(len(views) - 1):
            grown = {i for i in range(len(views))
                     if cv2.countNonZero(cv2.bitwise_and(looked[i], cv2.bitwise_not(masks[i])))
                     > _BAY * cv2.countNonZero(masks[i])}
            asked = {i for i in range(len(views)) if grown - {i}}
            if not asked:
                break
            masks = looked
            looked = _bays_looked_into(views, masks, scores, _Hulls(views, masks, plane, aim), done - trimmed, plane,
                                       aim, asked, before_the_looks)
        if plane is not None and _floats(hulls) is not None:
            # The bays only add to the silhouettes, so a hull that reached the plane before them still does;
            # one that floated is carved again from the silhouettes as they are now. Each look may find part
            # of the foot only: again while the hull floats and the look found something.
            for _ in range(len(views)):
                found = _foot_found(views, looked, scores, plane, aim)
                if all(new is old for new, old in zip(found, looked)):
                    break
                looked = found
        masks = looked
    if plane is not None and len(views) > 2:
        masks = _shadows_under_object_dropped(views, masks, scores, plane, aim)
        masks = _table_lit_at_the_rim_dropped(views, masks, scores, plane)
        # The lamp is fitted to the object as whole as the views give it: a top one view lost is found first.
        # Fitted first, the shadows it drops changed the silhouettes the top's height is read from, and a dark
        # can's top, found in every view, was taken for lost (33/rubber-mat-dark-can 0 and 1: 0.947 and 0.853
        # with this order, 0.791 and 0.710 with the other).
        masks = _tops_beyond_a_side_added(views, masks, plane, aim)
        masks = _cast_shadows_dropped(views, masks, scores, plane, aim)
    return masks


def _table_lit_at_the_rim_dropped(views: Sequence[_View], masks: list[np.ndarray],
                                  scores: Sequence[np.ndarray | None], plane: np.ndarray) -> list[np.ndarray]:
    """The silhouettes without the table at their rim that is lit as the table round them and of its colour
    (within a shadow's tint, :func:`_off_colour`), where it lies before a side's foot or beyond a top.

    Where the object has the table's colour, its top lit as the table is, the colour models take the table
    lit beside it. Two places are the table's whatever its look:

    Before a side's foot: the table just before the object's foot, as a view sees it, may lie behind the
    object from every other view, so nothing but its look tells it from the object. Hidden is each table
    point that no other view sees past its silhouette as it stands now, or that none saw past the looks of
    the first cut (its score :data:`_HIDDEN`): where another view's silhouette missed the face in front of
    the table point, that face's colour stood out there, for the object. Below a side (darker than the lit
    table by more than the light varies over a table, :data:`_LIGHT_FIELD_BEYOND`: turned from the lamp
    more than the table is), down the plane's normal as the view sees it, at the silhouette's rim, the
    object's surface goes on down to its foot or turns under it, away from the lamp: none of it is lit as
    the table (7/oak-table-colour-box 1: 0.845 -> 0.947; 5/... 1: 0.709 -> 0.885). But a side may be darker
    than the table by its print, not its light, and an object that wears the table's look on faces away
    from its foot (more than :data:`_BAY` of its silhouette lit as the table and of its colour, and not
    hidden as above) may wear it at its foot too: there the side must be a shade of the table's colour
    (within a shadow's tint). Below a soup can's red label, its white band on white laminate goes on down
    to the foot (``printed_products_set(10)``, view 1: 0.911 -> 0.747 when the band was dropped).

    Beyond a top: above a face lit as the table (:meth:`_BeyondOutline.beyond_a_top`), up the plane's
    normal, the object ends; a stretch there whose table point the other views confirm, colour and grain
    (its score under 1, a grain seen in it and in the table round the silhouette), is the table behind the
    top (2/... 2: 0.781 -> 0.874). Where the table has no grain to compare (white laminate), a face of its
    colour and light looks as the table point behind it does, print and all (the other views' flat table
    says nothing of a grain), and the others' confirming says nothing.

    Without an empty workspace only: with one, the table's change against it says where the table is."""
    found = list(masks)
    for i, (view, mask, score) in enumerate(zip(views, masks, scores)):
        if score is None or view.background is not None:
            continue
        round_it = _table_round(mask, mask)
        if not round_it.any():
            continue
        brightness = _brightness(view.coarse)
        lit_table = float(np.median(brightness[round_it]))
        inside = mask > 0
        table_like = inside & (np.abs(np.log(np.maximum(brightness, 1.0) / lit_table)) <= _LIGHT_FIELD_BEYOND)
        if not table_like.any():
            continue
        table = _median_colour(view.coarse, round_it)
        table_like &= _off_colours(view.coarse, table, table_like) < 1.0
        seen = np.zeros(inside.shape, bool)
        behind = np.zeros(inside.shape, bool)
        for other in views:
            if other is not view:
                _, sees, hides = view.sees(other, plane, masks[other.index])
                seen |= sees
                behind |= hides
        hidden = (behind & ~seen) | (score == _HIDDEN)
        grain = functools.cache(lambda: _grain_seen(view))

        # The object's own faces of the table's look, away from its foot: lit as the table and of its colour,
        # and not hidden.
        wears_the_table = np.count_nonzero(table_like & ~hidden) > _BAY * np.count_nonzero(inside)

        def below_a_side(part: np.ndarray) -> bool:
            side = _just_below(view, plane, part, upward=True) & inside & ~part
            if not side.any() or _lit_as(brightness, side, lit_table):
                return False
            return not wears_the_table or float(np.median(_off_colour(view.coarse[side], table))) < 1.0

        def beyond_a_top(part: np.ndarray) -> bool:
            return (_lit_below(view, plane, mask, brightness, lit_table, part) is True
                    and float(np.median(grain()[part])) >= 0.5 and float(np.median(grain()[round_it])) >= 0.5)

        kept = mask.copy()
        for candidates, is_table in ((table_like & hidden, below_a_side), (table_like & (score < 1.0), beyond_a_top)):
            for part in _rim_parts(candidates, mask):
                if is_table(part):
                    kept[part] = 0
        if not np.array_equal(kept, mask):
            found[i] = _filled_region(kept, view)
    return found


def _tops_beyond_a_side_added(views: Sequence[_View], masks: list[np.ndarray], plane: np.ndarray,
                              aim: np.ndarray) -> list[np.ndarray]:
    """The silhouettes with the top that a view lost beyond a side's upper edge, where another view found it.

    A box's top of the table's colour, lit by the lamp as the table is, looks as the table behind it does:
    neither colour, light nor parallax tells them apart, and a view may keep the box's sides only. Its
    silhouette's upper rim is then the top's near edge, with a side just below it (darker than the lit table
    beyond the light's spread over a table, :data:`_LIGHT_FIELD_BEYOND`: turned from the lamp); a view that
    found the top has the top just below its rim, lit as the table. Geometry says the rest. The near edge
    lies at the top's height: the rays through that view's rim leave, at that height, the other views'
    silhouettes swept down to the table (:func:`_under_silhouettes`: the side outlines, which every view
    found, bound the object whatever its top; :func:`_upper_rim_height`). At that height the top's section
    is where the views that found the top see it within their silhouettes and the others' side outlines
    allow it; seen from a view that lost it, it lies beyond the rim, and is added there.

    Only where some view has a side below its rim and some other a face lit as the table, and only where that
    section is a top that was lost for its look: the views that found it hold most of it (:data:`_FITS_WHOLE`;
    a height read off the far rim of a top that every view found, a dark can's on its dark mat, lies above the
    top, where the views that see the top lower hold the section's near part only), and they see it of the
    table's look (:func:`_of_the_table_s_look`; a print's, an ellipsoid's or a bottle's shoulder is not, and the
    view would have told it from the table). Where every view found its top, none is lost (a stretch of table
    beyond it, the opposite error, is left as it is)."""
    brightness = [_brightness(view.coarse) for view in views]
    side_below: list[bool | None] = []
    rounds = [_table_round(mask, mask) for mask in masks]
    for view, mask, bright, round_it in zip(views, masks, brightness, rounds):
        beyond = _beyond_the_upper_rim(view, plane, mask)
        side_below.append(None if not (round_it.any() and beyond.any()) else _lit_below(
            view, plane, mask, bright, float(np.median(bright[round_it])), beyond) is False)
    lost = [i for i, side in enumerate(side_below) if side]
    found = [i for i, side in enumerate(side_below) if side is False]
    if not lost or not found:
        return masks
    reach = _reach(views, masks, aim)
    highest, lowest = np.array([_upper_rim_height(views, masks, plane, i, reach) for i in lost]).T
    if not np.isfinite(highest).any():
        return masks
    # One top: its near edge lies within every lost view's span of heights, at or below the highest.
    height, floor = float(np.nanmin(highest)), float(np.nanmax(lowest))
    # A top at its height fits, whole, in the silhouettes of the views that found it: they hold over half of
    # the section the side outlines allow (the rest, the corners three views' outlines leave, lies beyond its
    # far edge). A section taken above the top (a can's far rim, dark, in views that found its top) reaches
    # beyond the rim of the views that see the top lower: they hold its near part alone. Where two views or
    # more found the top, their silhouettes, each holding all of it, let the rim's rays in above it
    # (23/laminate-sugar-box-tall-box 0: 0.188 m read off the rim, the top at 0.172 m, and the section there
    # held by 0.11): the top is the highest section down the span that fits. Where one view found it, a
    # section below the height read fits that one silhouette above the top as well (a dark can's far rim:
    # 0.123 m fitted, the top at 0.110 m), and the height read is the only one asked.
    step = _HEIGHT_STEP * reach
    below: list[float] = np.arange(height - step, floor, -step).tolist() if len(found) > 1 else []
    for height in [height, *below]:
        points, spacing = _plane_samples(plane, aim, height, reach)
        outlined = _under_every_silhouette(views, masks, points, plane)
        top = outlined.copy()
        for j in found:
            top &= _in_silhouette(views[j], masks[j], points)
        if np.count_nonzero(top) > _FITS_WHOLE * np.count_nonzero(outlined):
            break
    else:
        return masks
    # The top a view lost for the table's look has that look where the views that found it see it: a top of
    # another look (a print, a bottle's shoulder) the lost view would have told from the table.
    for j in found:
        seen = cv2.bitwise_and(_projected_points(views[j], points[top], spacing), masks[j]) > 0
        if not seen.any() or not _of_the_table_s_look(views[j].coarse, brightness[j], seen, rounds[j]):
            return masks
    # The top's edges are where the views' rims meet its height (the near edges of the views that lost it, the
    # far edges of those that found it), and a top is flat and convex: the corners of the section that three
    # views' side outlines leave beyond them are table.
    top &= _within_the_rims(views, masks, plane, height, points)
    added = list(masks)
    for i in lost:
        section = _projected_points(views[i], points[top], spacing)
        beyond = cv2.bitwise_and(section, cv2.bitwise_not(masks[i]))
        # The rim and the height read off it are known to a coarse pixel or two: the section's near edge may
        # stop that short of the rim, and the gap between them is the top's too.
        near = cv2.dilate(masks[i], _CLOSING) > 0
        for part in _opened_parts(beyond > 0):
            if (part & near).any():
                joined = cv2.morphologyEx(cv2.bitwise_or(masks[i], part.astype(np.uint8) * 255), cv2.MORPH_CLOSE,
                                          _CLOSING)
                around = cv2.dilate(part.astype(np.uint8), _CLOSING)
                added[i] = cv2.bitwise_or(added[i], cv2.bitwise_and(joined, around))
        added[i] = _holes_filled(added[i])
    return added


#: The upper rim of a silhouette: its pixels from which this many coarse pixels up the plane's normal leave it.
_RIM_STEP = 2
#: Heights are looked at in steps of this share of the hull's reach; a section is sampled so finely across.
_HEIGHT_STEP = 1 / 80
#: A column down to the table is sampled at this many points.
_COLUMN_SAMPLES = 48
#: A lost top's section fits in the silhouettes of the views that found it over this share of what the side
#: outlines allow (:func:`_tops_beyond_a_side_added`): all but the corners that three views' outlines leave
#: (a third of it: a lost box top 0.67 to 0.69), where a section taken above a top holds its near part only
#: (a dark can's found top, 0.28 to 0.54).
_FITS_WHOLE = 0.6


def _moved(binary: np.ndarray, by: np.ndarray) -> np.ndarray:
    """(h, w) bool: ``binary`` (bool) moved by the coarse offset ``by`` (2,)."""
    shift = np.array([[1.0, 0.0, by[0]], [0.0, 1.0, by[1]]], np.float32)
    return cv2.warpAffine(binary.astype(np.uint8), shift, binary.shape[::-1], flags=cv2.INTER_NEAREST) > 0


def _up_in_silhouette(view: _View, plane: np.ndarray, region: np.ndarray) -> np.ndarray:
    """(2,) the unit direction in the coarse image in which the plane's normal points, at the table point
    under the centre of ``region`` (bool or 0/255, not empty)."""
    ys, xs = np.nonzero(region)
    centre = view.from_coarse(np.array([xs.mean()]), np.array([ys.mean()]))
    ray = view.rays(centre)[0]
    normal = np.asarray(plane[:3], np.float64)
    height = float(normal @ view.camera.center + plane[3])
    on_plane = view.camera.center - height / float(ray @ normal) * ray
    # Up is toward the camera's side of the plane; a step of a hundredth of the camera's height only sets
    # the direction.
    ends = view.to_coarse(view.project(np.array([on_plane, on_plane + 0.01 * height * normal]))[0])
    return (ends[1] - ends[0]) / max(float(np.linalg.norm(ends[1] - ends[0])), 1e-9)


def _upper_rim(view: _View, plane: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(h, w) bool: the pixels of ``mask`` (0/255, not empty) from which :data:`_RIM_STEP` pixels up the
    plane's normal leave it: the silhouette's upper rim, where a face ends up the normal."""
    inside = mask > 0
    return inside & ~_moved(inside, -_RIM_STEP * _up_in_silhouette(view, plane, mask))


def _beyond_the_upper_rim(view: _View, plane: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(h, w) bool: the pixels just beyond the silhouette's upper rim (:func:`_upper_rim`), up the normal."""
    up = _up_in_silhouette(view, plane, mask)
    return _moved(_upper_rim(view, plane, mask), _RIM_STEP * up) & ~(mask > 0)


def _on_plane(view: _View, plane: np.ndarray, uv: np.ndarray, height: float | np.ndarray = 0.0) -> np.ndarray:
    """(N, 3) where the rays through full-resolution pixels ``uv`` (N, 2) meet the plane raised by ``height``;
    (H, N, 3) for ``height`` an (H,) array of heights, each ray traced once for all of them."""
    rays = view.rays(uv)
    normal = np.asarray(plane[:3], np.float64)
    above = float(normal @ view.camera.center + plane[3]) - np.asarray(height, np.float64)[..., None]
    return view.camera.center - (above / (rays @ normal))[..., None] * rays


def _in_silhouette(view: _View, mask: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) bool: whether world ``points`` (N, 3) fall in ``mask`` (0/255), the view's coarse silhouette; a
    point the view does not see is not in it."""
    return _projected_into(view, mask, points, unseen_hit=False)[3]


def _projected_into(view: _View, mask: np.ndarray, points: np.ndarray,
                    unseen_hit: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """World ``points`` (N, 3) projected into the view's coarse image of ``mask`` (0/255): (N, 2) int64 their
    nearest coarse pixels (column, row), (N,) bool whether the view sees them (in front of the camera, within
    the image), (N,) their depths, and (N,) bool whether they fall in ``mask``, ``unseen_hit`` for those it
    does not see (a silhouette's point must be seen; a hull is not carved by a view that does not see it)."""
    coarse, seen, depth = view.coarse_pixels(points)
    hit = np.full(len(points), unseen_hit)
    hit[seen] = mask[coarse[seen, 1], coarse[seen, 0]] > 0
    return coarse, seen, depth, hit


def _under_silhouettes(view: _View, mask: np.ndarray, points: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """(N,) bool: whether the column under each world point (N, 3), down the plane's normal to the plane, meets
    the view's silhouette ``mask`` (0/255): the silhouette swept down to the table, which its side outlines
    bound whatever the view missed of its top. Each column is sampled at :data:`_COLUMN_SAMPLES` points."""
    shares = np.linspace(0.0, 1.0, _COLUMN_SAMPLES)
    if view.camera.dist is None:
        # A pinhole's columns in one pass, each stopped at its first sample in the silhouette (the sections of a
        # lost top are asked at many heights, each of thousands of columns); a lens's below, share by share.
        met = np.empty(len(points), np.uint8)
        columns_meet_mask(np.ascontiguousarray(points, np.float64), np.asarray(plane, np.float64),
                          view.camera.projection, view.sx, view.sy, np.ascontiguousarray(mask), shares, met)
        return met.view(bool)
    normal = np.asarray(plane[:3], np.float64)
    heights = points @ normal + plane[3]
    met = np.zeros(len(points), bool)
    for share in shares:
        # A column met already is not looked down any further.
        asked = _to_project(~met)
        if asked is None:
            break
        met[asked] |= _in_silhouette(view, mask, points[asked] - (share * heights[asked])[:, None] * normal)
    return met


def _under_every_silhouette(views: Sequence[_View], masks: Sequence[np.ndarray], points: np.ndarray,
                            plane: np.ndarray) -> np.ndarray:
    """(N,) bool: whether the column under each world point (N, 3) meets every one of the views' silhouettes
    ``masks`` (:func:`_under_silhouettes`); a view is asked only of the points under all the silhouettes
    before it."""
    under = np.ones(len(points), bool)
    for view, mask in zip(views, masks):
        asked = _to_project(under)
        if asked is None:
            break
        under[asked] &= _under_silhouettes(view, mask, points[asked], plane)
    return under


def _to_project(wanted: np.ndarray) -> np.ndarray | None:
    """(N,) bool: which of N points to project when ``wanted`` (N,) bool are asked about; None if none is.
    A single point is projected with all the others: NumPy multiplies a matrix of one row by another way
    than one of many rows, whose last bits differ, and every point is to be projected as in one call."""
    count = np.count_nonzero(wanted)
    if count == 0:
        return None
    return wanted if count >= 2 else np.ones_like(wanted)


def _reach(views: Sequence[_View], masks: Sequence[np.ndarray], aim: np.ndarray) -> float:
    """How far from the aim the silhouettes reach, in world units (with a fifth to spare): the half side of
    the cube the hulls are carved in (:class:`_Hulls`)."""
    radius = 0.0
    for view, mask in zip(views, masks):
        ys, xs = np.nonzero(mask)
        centre = _coarse_aim(view, aim)
        reach_px = float(np.max(np.hypot(xs - centre[0], ys - centre[1]), initial=1.0)) * max(view.sx, view.sy)
        aim_depth = float(view.camera.project(aim[None, :])[1][0])
        radius = max(radius, float(1.2 * reach_px * aim_depth / view.camera.focal_length))
    return radius


def _of_the_table_s_look(image: np.ndarray, brightness: np.ndarray, region: np.ndarray, round_it: np.ndarray) -> bool:
    """Whether ``region`` (bool) is lit as the table round the silhouette (``round_it``, bool, not empty; its
    median ``brightness`` no darker than the table's beyond the light's spread, :func:`_lit_as`) and of the
    table's colour there (its median :func:`_off_colour` from the table's median colour under 1)."""
    table = _median_colour(image, round_it)
    return (_lit_as(brightness, region, float(np.median(brightness[round_it])))
            and float(np.median(_off_colour(image[region], table))) < 1.0)


def _upper_rim_height(views: Sequence[_View], masks: Sequence[np.ndarray], plane: np.ndarray, i: int,
                      reach: float) -> tuple[float, float]:
    """The medians over view ``i``'s upper rim of the highest and of the lowest height at which the ray through a
    rim pixel lies within every other view's silhouette swept down to the table (:func:`_under_silhouettes`);
    NaN where no ray does. A top's near edge lies between the two: above the highest the ray passes in front
    of the object, below the lowest behind it. The other views' silhouettes are looser than the object, the
    more so the more of it they found, so the near edge may lie below the highest."""
    view = views[i]
    ys, xs = np.nonzero(_upper_rim(view, plane, masks[i]))
    if not len(xs):
        return float("nan"), float("nan")
    uv = view.from_coarse(xs, ys)
    heights = np.arange(0.0, 2.0 * reach, _HEIGHT_STEP * reach)
    # Every height's points at once: the rays are traced once, each other view looked into once.
    points = _on_plane(view, plane, uv, heights).reshape(-1, 3)
    others = [j for j in range(len(views)) if j != i]
    within = _under_every_silhouette([views[j] for j in others], [masks[j] for j in others], points,
                                     plane).reshape(len(heights), len(xs))
    if not within.any():
        return float("nan"), float("nan")
    # Per rim pixel, the last height (the highest) and the first (the lowest) at which its ray lies within; NaN
    # where it never does.
    crossed = within.any(axis=0)
    last = len(heights) - 1 - np.argmax(within[::-1], axis=0)
    first = np.argmax(within, axis=0)
    return (float(np.nanmedian(np.where(crossed, heights[last], np.nan))),
            float(np.nanmedian(np.where(crossed, heights[first], np.nan))))


def _plane_axes(plane: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two (3,) unit vectors along the plane, square to each other and to its normal."""
    normal = np.asarray(plane[:3], np.float64)
    across = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    return across, np.cross(normal, across)


def _within_the_rims(views: Sequence[_View], masks: Sequence[np.ndarray], plane: np.ndarray, height: float,
                     points: np.ndarray) -> np.ndarray:
    """(N,) bool: whether each of ``points`` (N, 3), at ``height`` over the plane, lies within the convex
    outline of where the rays through every view's upper rim (:func:`_upper_rim`) meet that height."""
    axes = np.column_stack(_plane_axes(plane))
    rims = []
    for view, mask in zip(views, masks):
        ys, xs = np.nonzero(_upper_rim(view, plane, mask))
        uv = view.from_coarse(xs, ys)
        rims.append(_on_plane(view, plane, uv, height) @ axes)
    outline = cv2.convexHull(np.concatenate(rims).astype(np.float32))[:, 0].astype(np.float64)
    return _in_convex(outline, points @ axes)


def _in_convex(outline: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) bool: whether each of ``points`` (N, 2) lies within or on the convex polygon ``outline`` (M, 2),
    its corners in order either way round: on the inner side of every edge, as all the edges turn."""
    left = np.ones(len(points), bool)
    right = np.ones(len(points), bool)
    for corner, edge in zip(outline, np.roll(outline, -1, axis=0) - outline):
        turn = edge[0] * (points[:, 1] - corner[1]) - edge[1] * (points[:, 0] - corner[0])
        left &= turn >= 0
        right &= turn <= 0
    return left | right


def _plane_samples(plane: np.ndarray, aim: np.ndarray, height: float, reach: float) -> tuple[np.ndarray, float]:
    """(N, 3) points on a square grid in the plane raised by ``height``, within ``reach`` of the aim's foot,
    :data:`_HEIGHT_STEP` of the reach apart, and that spacing."""
    normal = np.asarray(plane[:3], np.float64)
    across, along = _plane_axes(plane)
    centre = aim - (float(normal @ aim) + plane[3] - height) * normal
    steps = np.arange(-reach, reach, _HEIGHT_STEP * reach)
    u, v = (grid.reshape(-1, 1) for grid in np.meshgrid(steps, steps))
    return centre + u * across + v * along, _HEIGHT_STEP * reach


def _projected_points(view: _View, points: np.ndarray, spacing: float) -> np.ndarray:
    """(h, w) 0/255: the world ``points`` (N, 3), sampled ``spacing`` apart, projected into the view's coarse
    image and closed over the gaps between their pixels."""
    coarse, inside, depth = view.coarse_pixels(points)
    width, height = view.coarse_size
    drawn = np.zeros((height, width), np.uint8)
    drawn[coarse[inside, 1], coarse[inside, 0]] = 255
    if not inside.any():
        return drawn
    gap = int(np.ceil(spacing * view.camera.focal_length / float(np.median(depth[inside])) / min(view.sx, view.sy)))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * gap + 3, 2 * gap + 3))
    return cv2.morphologyEx(drawn, cv2.MORPH_CLOSE, kernel)


def _rim_parts(candidates: np.ndarray, mask: np.ndarray) -> list[np.ndarray]:
    """The pieces of ``candidates`` (bool, opened by :data:`_SMALL`) that reach the rim of ``mask`` (0/255)."""
    rim = (mask > 0) & ~(cv2.erode(mask, _SMALL) > 0)
    return [part for part in _opened_parts(candidates) if (part & rim).any()]


def _opened_parts(binary: np.ndarray) -> list[np.ndarray]:
    """The 8-connected parts (bool) of ``binary`` (bool or uint8, any non-zero value set) opened by
    :data:`_SMALL`: a sliver or a speck of a few pixels is no part."""
    opened = cv2.morphologyEx(binary.astype(np.uint8), cv2.MORPH_OPEN, _SMALL)
    count, labels = cv2.connectedComponents(opened, connectivity=8)
    return [labels == label for label in range(1, count)]


def _touching_over(parts: list[np.ndarray], touching: np.ndarray, least: float) -> list[np.ndarray]:
    """The ``parts`` (bool) that touch ``touching`` (bool) and are over ``least`` pixels."""
    return [part for part in parts if (part & touching).any() and part.sum() > least]


def _grain_seen(view: _View) -> np.ndarray:
    """(h, w) float32: the share of each coarse pixel's fine pixels whose window shows a grain (a variance
    over the flat's, :func:`_window_statistics`), where the plane's parallax of the grain says something."""
    _, _, variance, floor = _window_statistics(_fine_grey(view), _flat_below(view))
    return cv2.resize((variance > floor).astype(np.float32), view.coarse_size, interpolation=cv2.INTER_AREA)


def _shadows_left_out(view: _View, before: np.ndarray, found: np.ndarray, score: np.ndarray,
                      hull: np.ndarray) -> np.ndarray:
    """``found`` (0/255), a view's cut again within the others' ``hull``, without the pieces it added to
    ``before`` that are the shadow by the object's foot: a piece with a shadow's look over most of it
    (:data:`_MOSTLY`; darker than the table the view's evidence ``score``, the plane's parallax, confirms
    round it, of its chromaticity), whose table points the other views see over half of it and confirm
    (the evidence's median under 1), and darker than the shadow cast in the open
    (:func:`_darker_than_the_open_shadow`).

    The others' hull is looser than the object and holds a band of table round its foot, with the shadow
    there; where the object's faces in shade are of the shadow's colour (a white box on white laminate),
    the colour models the view's seeds trained give that shadow to the object. A face in shade may match
    the shadow behind it as well, so the evidence alone does not tell; but such a face is lit by the sky
    and no darker than the open shadow, while the table by the foot, whose sky the object hides in part,
    is. A face that looks like the table (a dark can's top on its mat) has no shadow's look. A piece whose
    table points the others see over half of it at most is asked in the parts where they do
    (:func:`_parts_the_others_see`)."""
    pieces = _pieces_added(found, before)
    if not pieces:
        return found
    x0, y0, x1, y1 = _cut_box(view, found)
    crop = (slice(y0, y1), slice(x0, x1))
    confirmed = score[crop] < 1.0
    open_shadow = None
    kept = found.copy()
    for whole in pieces:
        for piece in _parts_the_others_see(whole, score):
            area = int(piece.sum())
            evidence = score[piece & (score != _HIDDEN)]
            if 2 * len(evidence) <= area or median(np.ascontiguousarray(evidence, np.float32)) >= 1.0:
                continue
            if np.count_nonzero(_shadow_look(view, crop, confirmed, piece)) <= _MOSTLY * area:
                continue
            if open_shadow is None:
                open_shadow = _confirmed_shadow_round(view, score, crop, cv2.bitwise_or(hull, before))
            if _darker_than_the_open_shadow(_brightness(view.coarse), piece, open_shadow):
                kept[piece] = 0
    return kept


def _parts_the_others_see(piece: np.ndarray, score: np.ndarray) -> list[np.ndarray]:
    """``piece`` (bool, coarse) whole if the other views see the table points of over half of it (``score``,
    the view's evidence, not :data:`_HIDDEN`), else the parts (bool, each 8-connected, opened by
    :data:`_SMALL`, a speck's size at least) where they do. A face in shade whose table points the object
    hides from the others may join the shadow by the foot, whose table points they see, in one piece: that
    part is asked alone."""
    seen = piece & (score != _HIDDEN)
    if 2 * np.count_nonzero(seen) > np.count_nonzero(piece):
        return [piece]
    return [part for part in _opened_parts(seen) if np.count_nonzero(part) >= _SPECK]


def _pieces_added(found: np.ndarray, before: np.ndarray) -> list[np.ndarray]:
    """The pieces (bool, each 8-connected) that a view's cut again, ``found`` (0/255), adds to ``before``
    (0/255), opened by :data:`_SMALL`: a sliver along ``before``'s edge is no piece."""
    return _opened_parts(cv2.bitwise_and(found, cv2.bitwise_not(before)))


def _shadows_keeping_the_grain_left_out(view: _View, before: np.ndarray, found: np.ndarray,
                                        hull: np.ndarray) -> np.ndarray:
    """``found`` (0/255), a view's cut again within the others' ``hull`` with its empty workspace, without the
    pieces it added to ``before`` that are the shadow by the object's foot: a piece with a shadow's look
    against the empty workspace over most of it (:data:`_MOSTLY`) that keeps its grain as the table round
    it does (:func:`_grain_kept`). The others' hull holds a band of table round the object's foot, with the
    shadow there, which the colour models the view's seeds trained may give to the object (a box of its
    table's colour, whose face in shade is of its shadow's colour); a face in shade hides the grain."""
    if view.shadow_look is None or view.grain_sums is None:
        return found
    known = cv2.bitwise_or(hull, before)
    kept = found.copy()
    for piece in _pieces_added(found, before):
        if np.count_nonzero(view.shadow_look[piece]) <= _MOSTLY * np.count_nonzero(piece):
            continue
        # The cut may join a face in shade to the shadow beside it.
        kept[_parts_keeping_the_grain(view, piece, known, in_shade=True)] = 0
    return found if np.array_equal(kept, found) else _filled_region(kept, view)


def _parts_keeping_the_grain(view: _View, piece: np.ndarray, known: np.ndarray, in_shade: bool) -> np.ndarray:
    """(h, w) bool: the parts of ``piece`` (bool) that keep the empty workspace's grain, where a face that
    hides it is joined to the table beside it, each part told whole (:func:`_grain_kept`). The parts are
    split off by each pixel's own window: ``in_shade`` (the table beside the face in the object's shadow),
    a dimmed grain is too faint for a window to show it kept, so the face is the pixels whose window has
    lost it (:func:`_grain_lost_pixels`) and the parts are what is left; in the light, the parts are the
    pixels whose window keeps it (:func:`_grain_kept_pixels`). None where the table round the piece keeps
    no grain clear of its uncertainty."""
    assert view.grain_sums is not None and view.shadow_look is not None  # set together (_background_cuts)
    found = np.zeros(piece.shape, bool)
    table = _table_grain_round(view, piece, known, view.grain_sums, view.shadow_look)
    if table is None:
        return found
    if in_shade:
        split = piece & ~_grain_lost_pixels(view.grain_sums, piece, table[0], _fine_per_coarse(view))
    else:
        split = _grain_kept_pixels(view.grain_sums, piece, table[0], _fine_per_coarse(view))
    for part in _opened_parts(split):
        if _grain_kept(view, part, known):
            found |= part
    return found


def _shadows_under_object_dropped(views: Sequence[_View], masks: list[np.ndarray],
                                  scores: Sequence[np.ndarray | None], plane: np.ndarray,
                                  aim: np.ndarray) -> list[np.ndarray]:
    """The silhouettes without the table under the object's overhang.

    The strip of table under a lying can is hidden from every other view by the can itself, so nothing but
    its look tells it from the object. The first cut seeds it as probably table where it looks like the
    shadow the other views confirm (:func:`_hidden_shadow`), and as table for sure only where the object has
    none of the table's colour (:func:`_graph_cut`); the graph cut keeps what is only probably table wherever
    the object's colour model holds a dark colour (a navy tin's shaded underside, which a colour model cannot
    tell from dark grey). It is darker than any shadow seen in the open: the object hides the sky from it
    as well as the lamp. A face turned from the lamp (a box's of its table's colour, a white box's on white
    laminate) looks like the table in shadow too, but the sky and the lit table light it: it is no darker
    than the cast shadow. So a hidden pixel with a shadow's look that is darker than
    :data:`_UNDER_OBJECT` of the deepest shadow the other views confirm (its :data:`_SHADOW_DEEPEST`
    quantile) is dropped, unless a point of the other views' hull above the plane on its ray looks alike
    from another view (:func:`_seen_alike`): a dark can whose lower body is its mat's shadow's colour.
    With the empty workspace too: it shows the strip darkened as a shadow is, but the graph cut's colour
    models, holding the tin's dark underside, keep it all the same."""
    hulls: _Hulls | None = None  # carved only for a view that has such pixels: most scans have none
    found = list(masks)
    for i, (view, mask, score) in enumerate(zip(views, masks, scores)):
        if score is None:
            continue
        x0, y0, x1, y1 = _cut_box(view, mask)
        crop = (slice(y0, y1), slice(x0, x1))
        hidden = score[crop] == _HIDDEN
        _, seen = _shadow_in_box(view, crop, score)
        if seen is None:
            continue
        under = np.zeros(mask.shape, bool)
        under[crop] = _hidden_shadow(seen, hidden) & (mask[crop] > 0) & _under_the_object(seen)
        if not under.any():
            continue
        hulls = hulls or _Hulls(views, masks, plane, aim)
        under &= ~_seen_alike(views, masks, hulls, i, np.where(under, 255, 0).astype(np.uint8))
        if under.any():
            kept = mask.copy()
            kept[under] = 0
            found[i] = _filled_region(kept, view)
    return found


def _cast_shadows_dropped(views: Sequence[_View], masks: list[np.ndarray], scores: Sequence[np.ndarray | None],
                          plane: np.ndarray, aim: np.ndarray) -> list[np.ndarray]:
    """The silhouettes without the object's cast shadow where the lamp, fitted to the scan, puts it.

    A dark object on a dark table is of its shadow's colour, and where each view hides behind the object
    the stretch of shadow that another view sees, no view confirms that stretch through the plane: the
    silhouettes that took it in carve a hull that holds it too (a wedge over the shadow, high by the object
    and falling away from it), and nothing said so far tells it from the object. But the lamp is one,
    distant, the same for every view, and the shadow on the plane is the object's upper part projected
    along its light: the hull's voxels at :data:`_TALL` of its height or more are the object's (the wedge
    stays lower but right by the object), and the light is the one whose projection of them covers, beyond
    their footprint, the silhouettes' pixels under which the other views' hull stays low, and not the lit
    table the views confirm (:func:`_light_fitted`). Where it explains too little of them (a wide base
    round the object, low parts on every side), nothing is dropped. Else each view drops what lies in that
    predicted shadow, beyond the tall part's footprint, of its silhouette: the pixels in front of which
    nothing of the hull over that footprint stands, and, joined to them, those low under the others' hull
    (the shadow right by the object, where the voxels round the footprint stand in front of it). A view
    that sees the object in front of its shadow keeps it: the hull over the footprint stands there. Without
    an empty workspace only: with one, the change against it tells the shadow by itself."""
    if any(view.background is not None for view in views):
        return masks
    hulls = _Hulls(views, masks, plane, aim)
    voxels = _hull_voxels(hulls)
    assert hulls.height is not None
    # A view that misses much of what the other views' hull holds (its colour models gave a face of the
    # table's colour to the table) carved the hull short of the object: its tall part is not the object's.
    if not voxels.any() or max(_hull_missed(hulls, mask, i) for i, mask in enumerate(masks)) > _HULL_MISSED:
        return masks
    normal = plane[:3]
    across = _plane_basis(normal)
    top = float(hulls.height[voxels].max())
    tall = voxels & (hulls.height >= _TALL * top)
    feet = (hulls.grid - hulls.height[:, None] * normal[None, :]) @ across.T  # each voxel's foot, on the plane
    origin = feet[tall].mean(axis=0)
    # The plane's grid, a voxel a cell, as far round the tall part as the lowest lamp casts its shadow.
    cell = hulls.voxel
    side = 2 * int(np.ceil((top / np.tan(np.radians(_LOWEST_LAMP)) + np.ptp(feet[tall], axis=0).max()) / cell)) + 1

    def on_grid(points: np.ndarray) -> np.ndarray:
        return np.rint((points - origin) / cell).astype(np.int64) + side // 2

    footprint = np.zeros((side, side), np.uint8)
    cv2.fillConvexPoly(footprint, cv2.convexHull(on_grid(feet[tall]).astype(np.int32)), 1)
    footprint = _dilated(footprint, 1)  # a voxel round it: the tall voxels' own width
    # Per view: each coarse pixel's plane point on the grid, whether it lies beyond the footprint, and whether
    # the others' hull in front of it is low (None for a view seeded by the aim alone, or that the others
    # confirm nowhere).
    on_plane: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] = []
    shown, lit = [], []
    for i, (view, mask, score) in enumerate(zip(views, masks, scores)):
        if score is None:
            on_plane.append(None)
            continue
        cw, ch = view.coarse_size
        points, valid = _plane_points(view, plane)
        cells = on_grid(points @ across.T)
        valid &= np.all((cells >= 0) & (cells < side), axis=1)
        cells = np.where(valid[:, None], cells, 0)
        beyond = (valid & (footprint[cells[:, 1], cells[:, 0]] == 0)).reshape(ch, cw)
        cells = cells.reshape(ch, cw, 2)
        low = _others_hull_height(hulls, i) < _TALL * top
        on_plane.append((cells, beyond, low) if np.any(score < 1.0) else None)
    # What the light is fitted to: the silhouettes' low part beyond the footprint, but for what is lit as the
    # table, and against it the table the other views confirm (``score`` under 1) lit so (no shadow's
    # darkness). No light is fitted to fewer than _SPECK pixels (_light_fitted): most scans stop here.
    if sum(np.count_nonzero((mask > 0) & seen[2] & seen[1]) for mask, seen in zip(masks, on_plane)
           if seen is not None) < _SPECK:
        return masks
    for view, mask, score, seen_on_plane in zip(views, masks, scores, on_plane):
        if seen_on_plane is None:
            continue
        cells, beyond, low = seen_on_plane
        assert score is not None
        confirmed = score < 1.0
        lit_table = _brightness(view.coarse) >= _SHADOW_DIMMER * float(_median_colour(view.coarse, confirmed).sum())
        shown.append(cells[(mask > 0) & low & beyond & ~lit_table])
        lit.append(cells[confirmed & lit_table & beyond])
    offset = _light_fitted(on_grid(feet[tall]), hulls.height[tall], np.concatenate(shown), np.concatenate(lit), side,
                           cell)
    if offset is None:
        return masks
    # A cell wider all round: the penumbra, and the voxels' own width.
    _, shadow_cells = _cast_shadow(on_grid(feet[tall]), hulls.height[tall], offset, side, cell, penumbra=1)
    # The hull over the tall part's footprint: what stands there, in front of which a view sees no shadow.
    foot_cells = on_grid(feet)
    inside_grid = np.all((foot_cells >= 0) & (foot_cells < side), axis=1)
    standing = voxels & inside_grid
    standing[standing] = footprint[foot_cells[standing, 1], foot_cells[standing, 0]] > 0
    found = list(masks)
    for i, (view, mask) in enumerate(zip(views, masks)):
        seen_on_plane = on_plane[i]
        if seen_on_plane is None:
            continue
        cells, beyond, low = seen_on_plane
        shaded = beyond & (shadow_cells[cells[..., 1], cells[..., 0]] > 0) & (mask > 0)
        clear = shaded & (_voxels_into(hulls, standing, i) == 0)
        clear = cv2.morphologyEx(clear.astype(np.uint8), cv2.MORPH_OPEN, _SMALL) > 0
        if np.count_nonzero(clear) < _SPECK:
            continue
        count, parts = cv2.connectedComponents((shaded & low).astype(np.uint8), connectivity=4)
        touched = np.unique(parts[clear])
        dropped = clear | np.isin(parts, touched[touched > 0])
        kept = mask.copy()
        kept[dropped] = 0
        found[i] = _filled_region(kept, view)
    return found


#: The hull's voxels at this share of its height or more are the object's: the wedge that a shadow taken in
#: carves stays below it away from the object.
_TALL = 0.5
#: A view that misses over this share of the other views' hull carved the hull short of the object.
_HULL_MISSED = 0.4
#: The lamps fitted: from this many degrees above the plane up to :data:`_HIGHEST_LAMP`.
_LOWEST_LAMP = 15.0
_HIGHEST_LAMP = 85.0
#: The fitted light must explain this share of what it is fitted to (less what it covers of the lit table).
_LIGHT_EXPLAINS = 0.5


def _hull_missed(hulls: _Hulls, mask: np.ndarray, i: int) -> float:
    """The share of the other views' hull, of the voxels view ``i`` sees, that falls outside its ``mask``."""
    coarse, seen, _ = hulls.pixels[i]
    kept = hulls.carved(set(range(len(hulls.views))) - {i}) & seen
    return float(np.mean(mask[coarse[kept, 1], coarse[kept, 0]] == 0)) if kept.any() else 0.0


def _plane_basis(normal: np.ndarray) -> np.ndarray:
    """(2, 3) two orthonormal directions across the plane of unit ``normal``."""
    first = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    first /= np.linalg.norm(first)
    return np.stack([first, np.cross(normal, first)])


def _hull_voxels(hulls: _Hulls) -> np.ndarray:
    """(N,) bool: the voxels inside every view's silhouette and seen by two views at least."""
    everyone = range(len(hulls.views))
    inside = np.ones(len(hulls.grid), bool)
    for i in everyone:
        inside &= hulls.inside[i]
    inside &= np.sum([hulls.pixels[i][1] for i in everyone], axis=0) >= 2
    return inside


def _others_hull_height(hulls: _Hulls, i: int) -> np.ndarray:
    """(h, w) float32: per coarse pixel of view ``i``, the height above the plane of the highest voxel of the
    other views' hull (as :meth:`_Hulls.into` keeps it) in front of the plane there, 0 where none is."""
    assert hulls.height is not None
    coarse, seen, depth = hulls.pixels[i]
    keep = hulls.carved(set(range(len(hulls.views))) - {i}) & seen
    heights = np.zeros(hulls.shape[i], np.float32)
    if not keep.any():
        return heights
    np.maximum.at(heights, (coarse[keep, 1], coarse[keep, 0]), np.maximum(hulls.height[keep], 0.0).astype(np.float32))
    reach = _voxel_reach(hulls, i, depth[keep])
    return cv2.dilate(heights, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1)))


def _voxel_reach(hulls: _Hulls, i: int, depth: np.ndarray) -> int:
    """How many coarse pixels of view ``i`` a voxel at ``depth`` (their median) covers either way."""
    view = hulls.views[i]
    return int(np.ceil(hulls.voxel * view.camera.focal_length / float(np.median(depth)) / min(view.sx, view.sy))) + 1


def _voxels_into(hulls: _Hulls, chosen: np.ndarray, i: int) -> np.ndarray:
    """The ``chosen`` voxels (bool (N,)) projected into view ``i`` (0/255), each as wide as it is there."""
    coarse, seen, depth = hulls.pixels[i]
    keep = chosen & seen
    points = np.zeros(hulls.shape[i], np.uint8)
    if not keep.any():
        return points
    points[coarse[keep, 1], coarse[keep, 0]] = 255
    return _dilated(points, _voxel_reach(hulls, i, depth[keep]))


def _cast_shadow(cells: np.ndarray, heights: np.ndarray, offset: np.ndarray, side: int, cell: float,
                 penumbra: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """On the plane's grid (``side`` cells a side, ``cell`` wide), the shadow that points at ``cells`` (M, 2)
    and ``heights`` (M,) cast where a unit of height moves a point's shadow by ``offset`` ((2,), along the
    plane): the convex outline of their feet and their shadows ((K, 1, 2) int32, :func:`_shadow_outline`) and
    its cells, with ``penumbra`` cells round it ((side, side) uint8 0/1)."""
    outline = _shadow_outline(cells, heights, offset, cell)
    shadow = np.zeros((side, side), np.uint8)
    cv2.fillConvexPoly(shadow, outline, 1)
    if penumbra:
        cv2.polylines(shadow, [outline], True, 1, thickness=2 * penumbra + 1)
    return outline, shadow


def _shadow_outline(cells: np.ndarray, heights: np.ndarray, offset: np.ndarray, cell: float) -> np.ndarray:
    """The convex outline ((K, 1, 2) int32, on the plane's grid) of the feet at ``cells`` (M, 2) of points
    ``heights`` (M,) high and of the shadows they cast where a unit of height moves a point's shadow by
    ``offset`` ((2,), along the plane; cells ``cell`` wide)."""
    moved = cells + np.rint(heights[:, None] * offset[None, :] / cell).astype(np.int64)
    return cv2.convexHull(np.concatenate([cells, moved]).astype(np.int32))


def _light_fitted(cells: np.ndarray, heights: np.ndarray, shown: np.ndarray, lit: np.ndarray, side: int,
                  cell: float) -> np.ndarray | None:
    """The light that casts the shadow of the tall voxels (their feet at ``cells`` (M, 2) of the plane's grid,
    ``side`` cells a side and ``cell`` wide; ``heights`` (M,)) over the most of ``shown`` (K, 2 cells: what
    looks like shadow beyond their footprint) and the least of ``lit`` (the lit table the views confirm): as
    (2,) how far along the plane a unit of height moves a point's shadow, or None when the best light
    explains under :data:`_LIGHT_EXPLAINS` of ``shown`` (less the lit table it covers) or lies on the
    search's bounds (no lamp within them fits).

    Azimuths 10 degrees apart and elevations 5 apart (:data:`_LOWEST_LAMP` to :data:`_HIGHEST_LAMP`) are
    tried, then the best one's neighbours half as far; of equally good ones the shortest shadow is taken."""
    if len(shown) < _SPECK:
        return None
    # Only the corners of each layer of voxels matter to a convex shadow.
    corners = []
    layers = np.rint(heights / cell).astype(np.int64)
    for layer in np.unique(layers):
        members = np.nonzero(layers == layer)[0]
        corners.append(members[cv2.convexHull(cells[members].astype(np.int32), returnPoints=False).ravel()])
    corner = np.concatenate(corners)
    points, lifted = cells[corner], heights[corner]
    # What a shadow covers is counted cell by cell: shown counts for it, the lit table against it, but not on
    # the shadow's rim (its penumbra, lit in part).
    shown_count, lit_count = (np.bincount(found[:, 1] * side + found[:, 0], minlength=side * side).reshape(side, side)
                              for found in (shown, lit))

    def fit(azimuth: float, elevation: float) -> tuple[float, float]:
        outline = _shadow_outline(points, lifted, _shadow_offset(azimuth, elevation), cell)
        # Drawn and counted within the shadow's box alone, a cell wider for the erosion: beyond it are no
        # shadow's cells, and (the counts being whole numbers) the sums are the grid's.
        x, y, w, h = cv2.boundingRect(outline)
        x0, y0, x1, y1 = max(x - 1, 0), max(y - 1, 0), min(x + w + 1, side), min(y + h + 1, side)
        shadow = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.fillConvexPoly(shadow, outline - np.array([x0, y0], np.int32), 1)
        inner = cv2.erode(shadow, _SMALL)
        box = (slice(y0, y1), slice(x0, x1))
        return (float(np.sum(lit_count[box], where=inner > 0) - np.sum(shown_count[box], where=shadow > 0)),
                cv2.contourArea(outline))

    tried = {(azimuth, elevation): fit(azimuth, elevation)
             for elevation in np.arange(_LOWEST_LAMP, _HIGHEST_LAMP + 1e-9, 5.0)
             for azimuth in np.arange(0.0, 360.0, 10.0)}
    azimuth, elevation = min(tried, key=tried.__getitem__)
    for near in ((azimuth + da) % 360.0 for da in (-5.0, 0.0, 5.0)):
        for height in (elevation - 2.5, elevation, elevation + 2.5):
            if _LOWEST_LAMP <= height <= _HIGHEST_LAMP and (near, height) not in tried:
                tried[(near, height)] = fit(near, height)
    azimuth, elevation = min(tried, key=tried.__getitem__)
    explained = -tried[(azimuth, elevation)][0]
    if explained < _LIGHT_EXPLAINS * len(shown) or elevation in (_LOWEST_LAMP, _HIGHEST_LAMP):
        return None
    return _shadow_offset(azimuth, elevation)


def _shadow_offset(azimuth: float, elevation: float) -> np.ndarray:
    """(2,) how far along the plane a unit of height moves a point's shadow under a lamp at ``azimuth`` (degrees,
    in the plane's basis) and ``elevation`` (degrees above the plane)."""
    a = np.radians(azimuth)
    return -np.array([np.cos(a), np.sin(a)]) / np.tan(np.radians(elevation))


#: The deepest shadow the other views confirm is taken at this quantile of its pixels' brightness, and the
#: table under the object's overhang is darker than this share of it.
_SHADOW_DEEPEST = 0.1
_UNDER_OBJECT = 0.7
#: An object with under this share of the pixels where it is surely seen of the table's colour has none of it.
_NONE_OF_IT = 0.02


def _under_the_object(seen: _ShadowSeen) -> np.ndarray:
    """(h, w) bool: the pixels darker than :data:`_UNDER_OBJECT` of the deepest shadow in the open (``seen``'s
    ``shadow``, not empty; its :data:`_SHADOW_DEEPEST` quantile): darker than a shadow can be where the sky
    lights it, as the table under the object's overhang is, which the object hides from the sky too."""
    return seen.brightness < _UNDER_OBJECT * np.quantile(seen.brightness[seen.shadow], _SHADOW_DEEPEST)


def _none_of_the_table_s_colour(image: np.ndarray, table_colour: np.ndarray, seen: np.ndarray) -> bool:
    """Whether under :data:`_NONE_OF_IT` of the object's ``seen`` pixels (bool) of ``image`` have the colour
    ``table_colour`` at their own brightness (:func:`_off_colour` under 1): no face of it, lit or in shade, looks
    like the table, nor like the table in shadow. False where none is seen: nothing is known of its colours."""
    count = np.count_nonzero(seen)
    return bool(count > 0 and np.count_nonzero(_off_colour(image[seen], table_colour) < 1.0) < _NONE_OF_IT * count)


def _alone_in_excess(index: int, excess: dict[int, float]) -> bool:
    """Whether view ``index`` is the only one of three or more that reaches out of the others' hull."""
    return len(excess) > 2 and all(share <= 1.0 for other, share in excess.items() if other != index)


def _floats(hulls: _Hulls) -> np.ndarray | None:
    """Whether the hull of all the views stands over :data:`_FLOATING` voxels above the plane: the voxels
    inside every view's silhouette (and seen by two at least) if it does, else None."""
    inside = _hull_voxels(hulls)
    if hulls.height is None or not inside.any() or float(hulls.height[inside].min()) <= _FLOATING * hulls.voxel:
        return None
    return inside


def _foot_found(views: Sequence[_View], masks: list[np.ndarray], scores: Sequence[np.ndarray | None],
                plane: np.ndarray, aim: np.ndarray) -> list[np.ndarray]:
    """The silhouettes, each looked into again down to the table where their hull floats above it.

    What stands on the table touches it, and the point where it does is the object's: every view has it
    inside its silhouette, so the hull of the silhouettes reaches down to the plane. A hull that stops
    short of it by more than :data:`_FLOATING` voxels is missing the object's foot in some views (a dark
    can's lower body taken for the shadow beside it in two views, each confirming the other's). Below the
    hull, down to the plane, is where the foot is looked for: each view whose silhouette leaves over
    :data:`_BAY` of it out is cut again within its silhouette and the column's picture, by the colour
    models its own evidence trains."""
    hulls = _Hulls(views, masks, plane, aim)
    everyone = set(range(len(views)))
    inside = _floats(hulls)
    if inside is None or hulls.height is None:
        return masks
    low = float(hulls.height[inside].min())
    # The hull let down to the plane, half a voxel at a time.
    points = hulls.grid[inside]
    drops = np.arange(0.5 * hulls.voxel, low + hulls.voxel, 0.5 * hulls.voxel)
    column = (points[:, None, :] - drops[None, :, None] * plane[:3]).reshape(-1, 3)
    column = column[column @ plane[:3] + plane[3] >= 0.0]
    found = list(masks)
    for i in everyone:
        score = scores[i]
        if score is None:
            continue
        view = views[i]
        coarse, seen, depth = view.coarse_pixels(column)
        cw, ch = view.coarse_size
        picture = np.zeros((ch, cw), np.uint8)
        picture[coarse[seen, 1], coarse[seen, 0]] = 255
        footprint = hulls.voxel * view.camera.focal_length / float(np.median(depth[seen])) / min(view.sx, view.sy) \
            if seen.any() else 1.0
        picture = _dilated(picture, int(np.ceil(footprint)))
        missing = cv2.countNonZero(cv2.bitwise_and(picture, cv2.bitwise_not(masks[i])))
        if missing <= _BAY * cv2.countNonZero(masks[i]):
            continue
        try:
            cut = _cut_within(view, cv2.bitwise_or(masks[i], picture), score)
        except SilhouetteError:
            continue
        found[i] = _filled_region(cv2.bitwise_or(masks[i], cut), view)
    return found


#: A hull whose lowest voxels stand this many voxels above the plane floats: some view missed the foot.
_FLOATING = 2.0


def _bays_looked_into(views: Sequence[_View], masks: list[np.ndarray], scores: Sequence[np.ndarray | None],
                      hulls: _Hulls, done: set[int], plane: np.ndarray | None, aim: np.ndarray,
                      asked: set[int] | None = None,
                      before_the_looks: list[np.ndarray] | None = None) -> list[np.ndarray]:
    """Each silhouette seeded by its view's evidence (and not corrected yet) with its bays looked into: a bay
    is what lies within the silhouette's convex outline and within the other views' hull but outside the
    silhouette (over :data:`_BAY` of its area). A face of the table's colour and light that the view's
    evidence missed (a box's or a can's top) leaves such a bay between the faces found around it; the two
    other views' hull is too loose to show it missing, but it holds it. The graph cut, seeded by the view's
    own evidence, looks for the object there too; what the view had found is kept. A view corrected already
    (cut again within the others' hull) is looked into only for faces standing out
    (:func:`_faces_standing_out`), which no cut by colour finds. Only the views ``asked``, if given, are
    looked into (a look again, after another view grew: faces standing out by the view's own light and
    parallax, which nothing seen since changes, are not looked for again in a view not corrected; the
    silhouettes ``before_the_looks`` say which table points were hidden from the others before they grew)."""
    everyone = set(range(len(views)))
    looked = list(masks)
    for i in sorted(everyone if asked is None else asked):
        score = scores[i]
        if score is None:
            continue
        hull = hulls.of(everyone - {i})
        seen_alike = functools.partial(_seen_alike, views, masks, hulls, i)
        if i in done:
            # A view cut again within the others' hull has looked into its bays, by the colour models of its
            # own seeds; but they cannot find a top of the table's colour, nor can the cut, that the view's
            # light or parallax shows standing out.
            if len(views) == 3 and views[i].background is None:
                looked[i] = _faces_standing_out(views[i], looked[i], score, hull, seen_alike)
            elif plane is not None and views[i].shadow_look is not None:
                # Nor does the empty workspace show it (below): the parallax the view has without it does.
                looked[i] = _faces_standing_out(views[i], looked[i], _parallax_score(views, masks, i, plane), hull,
                                                seen_alike)
            continue
        outline = cv2.fillConvexPoly(np.zeros_like(masks[i]), cv2.convexHull(cv2.findNonZero(masks[i])), 255)
        bay = cv2.bitwise_and(cv2.bitwise_and(outline, hull), cv2.bitwise_not(masks[i]))
        # An object in parts leaves bays of table too: the bend of a hammer between its handle and head, within
        # the other views' hull, which holds the space under the raised handle. Where the object has none of
        # the table's colour, the table in shadow there is no face of it, and is not looked into.
        bay[_table_in_shadow(views[i], masks[i], cv2.bitwise_or(masks[i], bay), score)] = 0
        bay = cv2.morphologyEx(bay, cv2.MORPH_OPEN, _SMALL)
        if cv2.countNonZero(bay) > _BAY * cv2.countNonZero(masks[i]):
            found = _cut_within(views[i], cv2.bitwise_or(masks[i], bay), score)
            looked[i] = _filled_region(cv2.bitwise_or(masks[i], found), views[i])
        if views[i].grain_sums is not None and hulls.height is not None:
            looked[i] = _faces_hiding_the_grain(views[i], looked[i], hull, seen_alike)
        if len(views) == 3 and views[i].background is None:
            others = [view for view in views if view is not views[i]]
            # The grain mapped once, for the faces in shade and the lit faces both.
            plane_grain = None if plane is None else functools.cache(functools.partial(
                _plane_grain_sums, views[i], others, plane, [masks[view.index] for view in others],
                _coarse_aim(views[i], aim)))
            grain_before_the_looks = None if plane is None or before_the_looks is None else functools.cache(
                functools.partial(_plane_grain_sums, views[i], others, plane,
                                  [before_the_looks[view.index] for view in others], _coarse_aim(views[i], aim)))
            looked[i] = _faces_beyond_outline(views[i], looked[i], score, hull, seen_alike, plane_grain=plane_grain,
                                              plane=plane, grain_before_the_looks=grain_before_the_looks)
            if asked is None:
                # A face standing out does so by the view's own light and parallax, which a look again does not
                # change: what does is the hull and what the others see alike through their new parts, and
                # on a box of the table's colour that is the table behind its top seen alike with a stretch of
                # table another view took before its foot (9/oak-table-colour-box 2: 0.946 -> 0.878 looked
                # again). So they are looked for in the first look only.
                looked[i] = _faces_standing_out(views[i], looked[i], score, hull, seen_alike)
            if plane_grain is not None:
                looked[i] = _lit_faces_hiding_the_grain(views[i], looked[i], score, hull, seen_alike, plane_grain)
        elif plane is not None and views[i].shadow_look is not None:
            # The empty workspace does not show a face of the table's colour and light either (a white box's
            # top on white laminate changes hardly at all): the plane's parallax that the view has without
            # it decides, and a piece with a shadow's look must be seen alike by the others too; in a scan of
            # any number of views (_faces_beyond_outline says why).
            parallax = _parallax_score(views, masks, i, plane)
            looked[i] = _faces_beyond_outline(views[i], looked[i], score, hull, seen_alike, parallax,
                                              views[i].shadow_look, plane=plane)
            looked[i] = _faces_standing_out(views[i], looked[i], parallax, hull, seen_alike)
    return looked


def _parallax_score(views: Sequence[_View], masks: Sequence[np.ndarray], i: int, plane: np.ndarray) -> np.ndarray:
    """View ``i``'s :func:`_colour_parallax` against the other views, or its :func:`_tint_parallax` where that
    says more, their silhouettes ``masks`` hiding the table behind them, with :data:`_HIDDEN` where no other
    view sees the table point."""
    others = [view for view in views if view is not views[i]]
    hiding = [masks[view.index] for view in others]
    parallax = _colour_parallax(views[i], others, plane, hiding)
    # The tint through the plane too, as the first cut without an empty workspace counts it: a dark can's top
    # of its mat's brightness but not its tint changes too little against the empty workspace to count as
    # changed there, nor, a little darker than it, as a tint no shadow's (_tint_change); the table point
    # behind it, seen from the other views, has the mat's tint.
    tint_score = _tint_parallax(views[i], others, plane, hiding)
    # JPEG keeps the colour at half the resolution, so an object's tint runs onto the table beside its outline
    # (up to half a colour block), which the other views see clean at that table point: the tint says nothing
    # there (a printed ellipsoid's or a tin's colour beside it on a dark mat).
    bleed = _dilated(masks[i], _half_a_colour_block(views[i])) > 0
    tint_score[bleed & (masks[i] == 0)] = 0.0
    parallax = np.where(np.isnan(parallax), parallax, np.fmax(parallax, tint_score))
    return np.where(np.isnan(parallax), _HIDDEN, parallax)


def _faces_hiding_the_grain(view: _View, mask: np.ndarray, hull: np.ndarray,
                            seen_alike: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """``mask`` with the pieces beyond it, within the other views' ``hull``, that hide the table's grain.

    Against the empty workspace a face of the table's colour and light (a dark can's top on a dark mat)
    changes nothing but the grain, and a grain too faint for a pixel's window (a rubber mat's) says nothing
    pixel by pixel. Beyond the silhouette, within the other views' hull, a piece that those views see
    alike (``seen_alike``, :func:`_seen_alike` within a region, called only where the hull reaches a
    face's size beyond the silhouette: the voxels there look as a point on the object does), that has
    no shadow's look over half of it, touches the silhouette and is of a face's size (:data:`_BAY`), is
    told whole: it is a face where it hides the grain that the table round it keeps (:func:`_grain_hidden`)."""
    area = cv2.countNonZero(mask)
    beyond = cv2.morphologyEx(cv2.bitwise_and(hull, cv2.bitwise_not(mask)), cv2.MORPH_OPEN, _CLOSING)
    if cv2.countNonZero(beyond) <= _BAY * area:
        return mask
    beyond[~seen_alike(cv2.dilate(beyond, _SMALL))] = 0
    beyond = cv2.morphologyEx(beyond, cv2.MORPH_OPEN, _CLOSING)
    count, labels = cv2.connectedComponents(beyond, connectivity=8)
    if count <= 1:
        return mask
    assert view.shadow_look is not None  # set with the grain's sums (_background_cuts)
    touching = cv2.dilate(mask, _SMALL) > 0
    known = cv2.bitwise_or(hull, mask)
    grown = mask.copy()
    for label in range(1, count):
        piece = labels == label
        if not (piece & touching).any() or piece.sum() <= _BAY * area or view.shadow_look[piece].mean() >= 0.5:
            continue
        if _grain_hidden(view, piece, known):
            # Told whole, a face joined to the lit table beside it hides the grain as well.
            grown[piece & ~_parts_keeping_the_grain(view, piece, known, in_shade=False)] = 255
    return _filled_region(grown, view)


def _grain_hidden(view: _View, piece: np.ndarray, known: np.ndarray, sums: np.ndarray | None = None,
                  shade: np.ndarray | None = None) -> bool:
    """Whether ``piece`` (bool, coarse) hides the table's grain that the table round it keeps, told over the
    piece whole: the image's grain regressed on the empty workspace's (the view's ``grain_sums``,
    :func:`_texture_change`) over the piece's inner pixels, against the same over the table round it beyond
    ``known`` (0/255, the silhouette and the other views' hull) with no shadow's look. The table keeps a
    grain where its slope is over :data:`_GRAIN_TABLE_SLOPE`, clear of 3 standard errors; the piece has lost
    it where its slope is under half the table's by 3 standard errors. The table is taken round the piece: a
    grain far away (another floor) says nothing of this one. Without an empty workspace, ``sums`` are the
    other views' grain mapped through the plane (:func:`_plane_grain_sums`), and the table round the piece
    is taken in its shadow too (``shade``, where the view has a shadow's look, None: everywhere)."""
    if sums is None:
        assert view.grain_sums is not None and view.shadow_look is not None  # set together (_background_cuts)
        sums, shade = view.grain_sums, view.shadow_look
    told = _piece_and_table_grain(view, piece, known, sums, shade)
    return told is not None and told[0] + 3.0 * told[1] < 0.5 * told[2]


def _grain_kept(view: _View, piece: np.ndarray, known: np.ndarray) -> bool:
    """Whether ``piece`` (bool) keeps the grain the empty workspace shows, as the table round it does: the
    converse of :func:`_grain_hidden`, its slope over half the table's by 3 standard errors. A shadow keeps
    the grain; a face in shade hides it, and a piece that is both holds less than half of it."""
    assert view.grain_sums is not None and view.shadow_look is not None  # set together (_background_cuts)
    told = _piece_and_table_grain(view, piece, known, view.grain_sums, view.shadow_look)
    return told is not None and told[0] - 3.0 * told[1] > 0.5 * told[2]


def _piece_and_table_grain(view: _View, piece: np.ndarray, known: np.ndarray, sums: np.ndarray,
                           shade: np.ndarray | None) -> tuple[float, float, float] | None:
    """The slope of the grain over ``piece``'s inner pixels, its standard error, and the slope the table round
    it keeps (:func:`_table_grain_round`), as :func:`_grain_hidden` and :func:`_grain_kept` weigh them; None
    where the table keeps no grain clear of its uncertainty, or the piece's is not known."""
    table = _table_grain_round(view, piece, known, sums, shade)
    if table is None:
        return None
    found = _pooled_grain(sums, piece & (cv2.erode(piece.astype(np.uint8), _SMALL) > 0), _fine_per_coarse(view))
    return None if found is None else (found[0], found[1], table[0])


def _table_grain_round(view: _View, piece: np.ndarray, known: np.ndarray, sums: np.ndarray,
                       shade: np.ndarray | None) -> tuple[float, float] | None:
    """The slope of the grain the table round ``piece`` keeps, beyond ``known`` and out of ``shade`` (as
    :func:`_grain_hidden` takes them), and the power of the grain compared with there; None where it keeps
    none clear of its uncertainty."""
    round_it = _table_round(piece.astype(np.uint8), known)
    if shade is not None:
        round_it &= ~shade
    table = _pooled_grain(sums, round_it, _fine_per_coarse(view))
    if table is None or table[0] < max(3.0 * table[1], _GRAIN_TABLE_SLOPE):
        return None
    return table[0], float(np.nanmean(sums[round_it][:, 1]))


def _grain_lost_pixels(sums: np.ndarray, region: np.ndarray, table_slope: float, fine_per_coarse: float) -> np.ndarray:
    """(h, w) bool: the pixels of ``region`` whose grain, regressed as :func:`_pooled_grain` does over the
    window of :data:`_CLOSING`'s size round each, has a slope under half the table's (``table_slope``) by 3
    standard errors, where over half of that window's grain is known."""
    slope, error, enough = _window_grain(sums, fine_per_coarse)
    with np.errstate(invalid="ignore"):
        return region & enough & (slope + 3.0 * error < 0.5 * table_slope)


def _grain_kept_pixels(sums: np.ndarray, region: np.ndarray, table_slope: float, fine_per_coarse: float) -> np.ndarray:
    """(h, w) bool: the converse of :func:`_grain_lost_pixels`, the pixels of ``region`` whose window's slope
    is over half the table's by 3 standard errors."""
    slope, error, enough = _window_grain(sums, fine_per_coarse)
    with np.errstate(invalid="ignore"):
        return region & enough & (slope - 3.0 * error > 0.5 * table_slope)


def _window_grain(sums: np.ndarray, fine_per_coarse: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per coarse pixel, the slope of the grain regressed as :func:`_pooled_grain` does over the window of
    :data:`_CLOSING`'s size round it, its standard error, and whether over half of that window's grain is
    known (and any of it)."""
    known = np.isfinite(sums[..., 0])
    size = _CLOSING.shape[::-1]
    shared, power, own = (cv2.boxFilter(np.where(known, sums[..., k], 0.0).astype(np.float64), -1, size)
                          for k in range(3))
    counted = cv2.boxFilter(known.astype(np.float64), -1, size, normalize=False)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = shared / power
        error = np.sqrt(np.maximum(own - slope * shared, 0.0) / (counted * fine_per_coarse * power))
    return slope, error, (2.0 * counted > _CLOSING.size) & (power > 0.0)


def _pooled_grain(sums: np.ndarray, region: np.ndarray, fine_per_coarse: float) -> tuple[float, float] | None:
    """The slope of the image's grain (brought back to the light) regressed on the empty workspace's over
    ``region`` whole (``sums`` as :func:`_texture_change` gives them), and its standard error; None where
    the region holds no grain known."""
    known = region & np.isfinite(sums[..., 0])
    count = int(np.count_nonzero(known))
    if not count:
        return None
    shared, power, own = sums[known][:, :3].astype(np.float64).mean(axis=0)
    if power <= 0.0:
        return None
    slope = shared / power
    return slope, float(np.sqrt(max(own - slope * shared, 0.0) / (count * fine_per_coarse * power)))


#: The grain the other views see at a piece's table points is the table's where its power is within this
#: factor of the power they see round it (twice or half its amplitude).
_GRAIN_POWER_SPREAD = 4.0
#: The table round a piece keeps a grain where its slope (the image's grain on the empty workspace's, which
#: the empty workspace's own noise lowers on a faint grain) is over this.
_GRAIN_TABLE_SLOPE = 0.2


def _seen_alike(views: Sequence[_View], masks: Sequence[np.ndarray], hulls: _Hulls, i: int,
                where: np.ndarray | None = None) -> np.ndarray:
    """(h, w) bool: the coarse pixels of view ``i`` on which a point of the other views' hull, above the
    plane, projects that looks alike from another view which has it well inside its silhouette.

    A point on the object looks alike from every view that sees it (a matte surface sends the same light
    every way); so a pixel of view ``i`` whose ray passes through such a point may see the object there,
    even where its own evidence says nothing (its table point hidden from every other view). The other
    view must have the point a coarse pixel inside its silhouette, whose edge is known to that, and may
    hold a pixel of table; and the point must stand over :data:`_ALIKE_ABOVE` voxels above the plane, where
    the table seen alike through it would be no sign of anything. Each point is compared with the other
    view's colours within a pixel of it (the points project to the nearest coarse pixel), relative to the
    colour's brightness as :func:`_relative_difference` does, and alike within :data:`_ALIKE`. Only the
    points that project within ``where`` (0/255), if given, are looked at."""
    view = views[i]
    others = [other.index for other in views if other.index != i]
    points = np.ones(len(hulls.grid), bool) if hulls.height is None else hulls.height > _ALIKE_ABOVE * hulls.voxel
    for j in others:
        points &= hulls.inside[j] & hulls.pixels[j][1]
    coarse, seen, _ = hulls.pixels[i]
    points &= seen
    found = np.zeros(masks[i].shape, bool)
    index = np.flatnonzero(points)
    at = coarse[index]
    if where is not None:
        within = where[at[:, 1], at[:, 0]] > 0
        index, at = index[within], at[within]
    if not len(index):
        return found
    here = view.coarse[at[:, 1], at[:, 0]]
    best = np.full(len(here), np.inf, np.float32)
    for j in others:
        there = hulls.pixels[j][0][index]
        rows, columns = there[:, 1], there[:, 0]
        well_inside = cv2.erode(masks[j], _SMALL)[rows, columns] > 0
        low = cv2.erode(views[j].coarse, _SMALL)[rows, columns]
        high = cv2.dilate(views[j].coarse, _SMALL)[rows, columns]
        difference = (np.maximum(low - here, 0) + np.maximum(here - high, 0)).sum(axis=1) / (here.sum(axis=1) + 30.0)
        np.minimum(best, np.where(well_inside, difference, np.inf), out=best)
    alike = best < _ALIKE
    found[at[alike, 1], at[alike, 0]] = True
    # A voxel is larger than a coarse pixel where it projects: its neighbours are on its ray's side too.
    return cv2.dilate(found.astype(np.uint8), _SMALL) > 0


#: Two views' colours of one point are alike within this relative difference (the plane's parallax on a
#: flat table, JPEG and a pixel's misregistration, stays within it), for a point over this many voxels
#: above the plane.
_ALIKE = 0.08
_ALIKE_ABOVE = 1.5


class _BeyondOutline:
    """What every question about a piece beyond a view's silhouette asks of (:func:`_faces_beyond_outline`):
    the view, its silhouette ``mask``, its evidence ``score`` and ``parallax``, the other views' ``hull``, and
    what is worked out once, when first asked (the table's level, the open shadow, the grain mapped from the
    other views, the other views' likeness)."""

    def __init__(self, view: _View, mask: np.ndarray, score: np.ndarray, hull: np.ndarray,
                 parallax: np.ndarray | None, seen_alike: Callable[[], np.ndarray] | None,
                 plane_grain: Callable[[], np.ndarray] | None, plane: np.ndarray | None = None) -> None:
        self.view, self.mask, self.score, self.hull, self.plane = view, mask, score, hull, plane
        self.parallax = score if parallax is None else parallax
        # The first cut gives the pixels whose table point no other view sees the score _HIDDEN.
        self.seen = self.parallax != _HIDDEN
        self.known = cv2.bitwise_or(hull, mask)
        x0, y0, x1, y1 = _cut_box(view, mask)
        self.crop = (slice(y0, y1), slice(x0, x1))
        self.low = score[self.crop] < 1.0
        self._seen_alike = seen_alike
        self._plane_grain = plane_grain

    @functools.cached_property
    def table_level(self) -> float:
        """What the table round the hull stands out by (its :data:`_TABLE_LEVEL` quantile, 1 at least), as for
        the faces standing out (:func:`_faces_standing_out`): beside the object's foot, in its shadow or over a
        coarse grain, the parallax is not all noise, and a stretch of table there stands out over 1 as a face
        does (a stretch of lit oak beside a mustard bottle stood out by 1.2, the oak round the hull by 1.8)."""
        round_it = _table_round(self.hull, self.hull) & self.seen
        return max(1.0, float(np.quantile(self.parallax[round_it], _TABLE_LEVEL))) if round_it.any() else 1.0

    @functools.cached_property
    def lit_table_ceiling(self) -> float | None:
        """:func:`_lit_table_ceiling` of the table round the silhouette and the other views' hull."""
        return _lit_table_ceiling(self.view, self.known)

    @functools.cached_property
    def open_shadow(self) -> np.ndarray:
        """The open shadow the view's evidence confirms round the object, clear of the silhouette and the other
        views' hull (:func:`_confirmed_shadow_round`)."""
        return _confirmed_shadow_round(self.view, self.score, self.crop, self.known)

    @functools.cached_property
    def alike(self) -> np.ndarray:
        """Where the other views see the view's pixels alike (``seen_alike``: :func:`_seen_alike`)."""
        assert self._seen_alike is not None
        return self._seen_alike()

    @property
    def mapped_grain(self) -> np.ndarray:
        """The table's grain the other views see at each pixel's table point (``plane_grain``, worked out once
        by its maker, which :func:`_lit_faces_hiding_the_grain` asks too)."""
        assert self._plane_grain is not None
        return self._plane_grain()

    @functools.cached_property
    def seen_behind(self) -> np.ndarray:
        """Where the other views see the table point behind each pixel as their silhouettes stand now. The
        evidence's ``seen`` is of their first look, which may have missed the faces that now hide those table
        points from them; the grain mapped from them (``plane_grain``, given without an empty workspace) is
        of their silhouettes as they are."""
        if self._plane_grain is None:
            return self.seen
        return self.seen & np.isfinite(self.mapped_grain[..., 0])

    def stands_out(self, piece: np.ndarray) -> bool:
        """Whether the other views see the table points behind over half of ``piece`` and its parallax's
        median there is over the table's level: where another view confirms the table point behind a piece
        within the table's own noise over most of it, the piece is table. The parallax against a white top
        on a white table is faint, yet above the table's noise over most of the face (the tint and the light
        of a face above the plane are not quite those of the table point behind it)."""
        evidence = self.parallax[piece & self.seen]
        return bool(2 * len(evidence) > np.count_nonzero(piece)
                    and median(np.ascontiguousarray(evidence, np.float32)) > self.table_level)

    def confirmed_shadow(self, piece: np.ndarray, least: float) -> np.ndarray:
        """(h, w) bool: the parts of ``piece`` whose table points the other views see and confirm (the parallax
        within the table's level), opened by :data:`_SMALL`, each over ``least`` pixels, with a shadow's look
        over half of it (:meth:`looks_a_shadow`) and keeping the table's grain that the other views see there
        wherever the table round it shows one: the shadow on the table beside a face. A shadow lies on the
        plane, which maps it, grain and all, exactly from view to view. A face of the table's colour in shade
        matches the table in shadow behind it too, but keeps its grain in part at most (an oak box's face kept
        0.3 to 0.8 of the oak's, short of all of it by over 3 standard errors); on a table whose grain the
        views do not show (a rubber mat's), the parallax alone speaks. None without the grain the other
        views map (``plane_grain``)."""
        found = np.zeros(piece.shape, bool)
        if self._plane_grain is None:
            return found
        for part in _opened_parts(piece & self.seen & (self.parallax <= self.table_level)):
            if part.sum() <= least or not self.looks_a_shadow(part):
                continue
            told = _piece_and_table_grain(self.view, part, self.known, self.mapped_grain, None)
            if told is None or told[0] - 3.0 * told[1] > 0.5 * told[2]:
                found |= part
        return found

    def seen_alike_over(self, piece: np.ndarray, share: float) -> bool:
        """Whether the other views see over ``share`` of ``piece`` alike. Where the object hides the table
        points behind most of a piece from the other views (a tall box's white top, whose table points lie
        behind the box from the others), the view has no evidence there, and their likeness speaks for it."""
        return bool(self._seen_alike is not None
                    and np.count_nonzero(self.alike[piece]) > share * np.count_nonzero(piece))

    @functools.cached_property
    def lit_table(self) -> float | None:
        """The median brightness of the table round the silhouette and the other views' hull (None where
        none is clear of them)."""
        round_it = _table_round(self.known, self.known)
        return float(np.median(self.brightness[round_it])) if round_it.any() else None

    @functools.cached_property
    def brightness(self) -> np.ndarray:
        """(h, w) the view's coarse pixels' channels summed (:func:`_brightness`), made once for every piece."""
        return _brightness(self.view.coarse)

    def lit_as_the_table(self, piece: np.ndarray) -> bool:
        """Whether ``piece``'s median brightness is within the light's spread over a table
        (:data:`_LIGHT_FIELD_BEYOND`) of the table's round the silhouette and the other views' hull, or above
        it: a face turned up is lit as the table is, a stretch of the object's shadow is not."""
        return self.lit_table is not None and _lit_as(self.brightness, piece, self.lit_table)

    def on_a_side(self, piece: np.ndarray) -> bool:
        """Whether the silhouette just below ``piece`` (:meth:`lit_below`) is darker than the lit table beyond
        the light's spread over a table (:data:`_LIGHT_FIELD_BEYOND`): a top seen from above the object's side
        sits on that side, which the lamp above lights less than a face turned up. Where the silhouette below
        is lit as the table, it already holds the face turned up (a box's top), and what lies beyond it is the
        table behind."""
        return self.lit_below(piece) is False

    def beyond_a_top(self, piece: np.ndarray) -> bool:
        """Whether the silhouette just below ``piece`` (:meth:`lit_below`) is lit as the table, within the
        light's spread over a table or brighter: a face turned up, a top, beyond which, up the plane's
        normal, the object ends and the table behind it lies."""
        return self.lit_below(piece) is True

    def lit_below(self, piece: np.ndarray) -> bool | None:
        """Whether the silhouette just below ``piece`` (within :data:`_SIDE_BELOW` of it, down the plane's
        normal as the view sees it) is lit as the table round it (its median brightness no darker than the
        lit table's beyond the light's spread over a table, :data:`_LIGHT_FIELD_BEYOND`); None where nothing
        of the silhouette lies below it, or without a plane or a table round it."""
        if self.plane is None or self.lit_table is None:
            return None
        return _lit_below(self.view, self.plane, self.mask, self.brightness, self.lit_table, piece)

    def darker_than_the_open_shadow(self, piece: np.ndarray) -> bool:
        """:func:`_darker_than_the_open_shadow`, against the open shadow beyond the silhouette and the hull."""
        return _darker_than_the_open_shadow(self.brightness, piece, self.open_shadow)

    def looks_a_shadow(self, piece: np.ndarray) -> bool:
        """Whether ``piece`` has a shadow's look over half of it: darker than the table the view's evidence
        confirms round the object, of its chromaticity (:func:`_shadow_like`)."""
        looks = _shadow_look(self.view, self.crop, self.low, piece)
        return bool(2 * np.count_nonzero(looks) >= np.count_nonzero(piece))

    def hides_the_mapped_grain(self, piece: np.ndarray) -> bool:
        """Whether ``piece`` has a shadow's look over half of it (darker than the table the other views
        confirm round the object, of its chromaticity), hides the grain the other views see at its table
        points, and is no darker than the open shadow unless the other views see most of its table points.

        Without an empty workspace, a face of the table's colour turned from the lamp matches the table in the
        object's shadow behind it, which the other views see, so the parallax of its colour says table. But
        they see the table's grain there, which a shadow on the table carries and a face above it does not
        (:func:`_grain_hidden`, told over the part of the piece whose table points the others see, however
        small: its standard error says how sure). The table under the object's overhang is hidden from the
        other views by the object above it, so the grain they show is told there from a few points only; a
        face in shade stands in front of the table points behind it, which they see: its darkness beside the
        open shadow says nothing (a face turned from the lamp sees half of the sky, the shadow round the
        object most of it)."""
        if self._plane_grain is None or not self.looks_a_shadow(piece):
            return False
        if not _grain_hidden(self.view, piece, self.known, self.mapped_grain):
            return False
        others_see_behind = bool(2 * np.count_nonzero(self.seen[piece]) > np.count_nonzero(piece))
        return others_see_behind or not self.darker_than_the_open_shadow(piece)

    def hides_the_empty_workspace_grain(self, piece: np.ndarray) -> bool:
        """Whether ``piece`` hides the grain the empty workspace shows and is no darker than the open shadow:
        a shadow keeps the table's grain, a face in shade hides it whatever the other views see (they may see
        a lit face where it stands, which looks nothing like it); but so does the dark under the object's
        overhang, where the object hides the sky too and the grain fades under JPEG's floor."""
        return (self.view.grain_sums is not None and _grain_hidden(self.view, piece, self.known)
                and not self.darker_than_the_open_shadow(piece))

    def keeps_the_empty_workspace_grain(self, piece: np.ndarray) -> bool:
        """Whether ``piece`` keeps the empty workspace's grain as the table round it does: a shadow, whatever
        the other views see above it (the object beside it may look as dark from them)."""
        return self.view.grain_sums is not None and _grain_kept(self.view, piece, self.known)


def _lit_below(view: _View, plane: np.ndarray, mask: np.ndarray, brightness: np.ndarray, lit_table: float,
               piece: np.ndarray, upward: bool = False) -> bool | None:
    """Whether the silhouette ``mask`` (0/255) just below ``piece`` (bool; :func:`_just_below`, ``upward``:
    just above it) is lit as the table, its median ``brightness`` (:func:`_brightness`) no darker than
    ``lit_table`` beyond the light's spread over a table (:data:`_LIGHT_FIELD_BEYOND`); None where nothing
    of the silhouette lies there."""
    there = _just_below(view, plane, piece, upward) & (mask > 0) & ~piece
    return _lit_as(brightness, there, lit_table) if there.any() else None


def _lit_as(brightness: np.ndarray, region: np.ndarray, lit_table: float) -> bool:
    """Whether ``region``'s (bool, not empty) median ``brightness`` is no darker than ``lit_table`` beyond the
    light's spread over a table (:data:`_LIGHT_FIELD_BEYOND`): lit as the table is, or brighter."""
    return bool(float(np.median(brightness[region])) >= np.exp(-_LIGHT_FIELD_BEYOND) * lit_table)


def _just_below(view: _View, plane: np.ndarray, region: np.ndarray, upward: bool = False) -> np.ndarray:
    """(h, w) bool: where ``region`` (bool) lands moved down the plane's normal (``upward``: up it), as the
    view sees it at the region's centre, by each whole coarse pixel up to :data:`_SIDE_BELOW`."""
    up = _up_in_silhouette(view, plane, region)
    below = np.zeros(region.shape, bool)
    sign = 1.0 if upward else -1.0
    for step in range(1, _SIDE_BELOW + 1):
        below |= _moved(region, sign * step * up)
    return below


def _faces_beyond_outline(view: _View, mask: np.ndarray, score: np.ndarray, hull: np.ndarray,
                          seen_alike: Callable[[], np.ndarray] | None = None,
                          parallax: np.ndarray | None = None, shadow: np.ndarray | None = None,
                          plane_grain: Callable[[], np.ndarray] | None = None,
                          plane: np.ndarray | None = None,
                          grain_before_the_looks: Callable[[], np.ndarray] | None = None) -> np.ndarray:
    """``mask`` with the faces that the graph cut finds within the other views' ``hull`` beyond it, where
    the view's own evidence there is not contrary.

    A face of the table's colour and light (a white box's top on white laminate, seen from the side) may
    lie beyond the convex outline of the faces found, where no bay shows it: three views' hull is loose
    enough to hold a box with or without its top. Cut again within the hull, by the colour models its own
    seeds trained, the view finds such a face by its edges and its shade. But the hull holds a band of
    table around the object too, which the colour models may take (a print of the table's colour, a
    shadow): each piece the cut adds, of a face's size (:data:`_BAY` of the silhouette) and touching it, is
    asked in turn what the view's evidence says of it (:class:`_BeyondOutline`'s questions).

    Without an empty workspace, only in a scan of three views, where the hull is of two and cannot show a
    face missing. With one, in a scan of any number: the hull of three views or more forgives one view's
    miss (:meth:`_Hulls.into`), so :func:`_agreed` does not see a face that one view alone missed either.

    ``seen_alike`` (:func:`_seen_alike`, called only when asked) gives where the other views see the view's
    pixels alike; ``parallax``, the plane's parallax in units of its noise (:data:`_HIDDEN` where hidden)
    where ``score`` is other evidence (against the empty workspace); ``shadow`` (bool), where the view has a
    shadow's look against the empty workspace, if it has one; ``plane_grain``, without one, the table's
    grain the other views see (:func:`_plane_grain_sums`, called only when asked), and in a look again
    ``grain_before_the_looks``, the same through their silhouettes before the looks. Where the cut gave a face
    in shade to the shadow beside it, the grain (the other views' or the empty workspace's) splits the two
    (:func:`_split_by_lost_grain`); a lit piece that keeps the empty workspace's grain is the table."""
    try:
        found = _cut_within(view, cv2.bitwise_or(mask, hull), score)
    except SilhouetteError:
        return mask
    pieces = _pieces_added(found, mask)
    if not pieces and plane_grain is None and (shadow is None or view.grain_sums is None):
        return mask
    ask = _BeyondOutline(view, mask, score, hull, parallax, seen_alike, plane_grain, plane)
    touching = cv2.dilate(mask, _SMALL) > 0
    grown = mask.copy()
    area_found = cv2.countNonZero(mask)
    for piece in pieces:
        area = int(piece.sum())
        # A piece apart from the silhouette is not a face of it.
        if not (piece & touching).any() or area <= _BAY * area_found:
            continue
        # With the empty workspace: whether the piece has a shadow's look over half of it or more.
        shaded = None if shadow is None else bool(2 * np.count_nonzero(shadow[piece]) >= area)
        if shaded is False and ask.keeps_the_empty_workspace_grain(piece):
            # Lit, and keeping the empty workspace's grain as the table round it does: the table seen through a
            # gap of the object (between a drill's barrel and its battery), which the hull holds (the space
            # under the barrel) and the colour models may give to the object. A face, even one of the table's
            # colour, hides the grain.
            continue
        if _lit_above_its_surroundings(view, piece, mask):
            grown[piece] = 255
            continue
        # The parallax of a top of the table's colour says nothing: its table point looks as it does.
        if (seen_alike is not None and _nearer_the_lamp_than_the_table(view, piece, ask.lit_table_ceiling)
                and ask.seen_alike_over(piece, 0.5)):
            grown[piece] = 255
            continue
        mostly_seen = 2 * np.count_nonzero(ask.seen_behind[piece]) > area
        if shaded:
            # A piece with a shadow's look against the empty workspace over half of it may be the shadow
            # beside the object, whose table points the other views' feet hide from them here and there: the
            # parallax must say a face where it can, and the other views see it alike.
            if not ask.stands_out(piece) and mostly_seen:
                continue
            if ask.hides_the_empty_workspace_grain(piece):
                grown[piece] = 255
                continue
            if ask.keeps_the_empty_workspace_grain(piece):
                continue
        elif mostly_seen:
            # A face in shade may match the colour of the shadow behind it, but not carry the table's grain
            # that the other views see there.
            if ask.stands_out(piece) or ask.hides_the_mapped_grain(piece):
                # The cut may give a face and the shadow beside it one piece (a dark can's side in shade and
                # its shadow cast on a dark mat), which stands out over most of it: the part whose table
                # points the other views see and confirm through the plane lies on it. From the images alone:
                # with the empty workspace, its own shadow's look decides above.
                if view.background is None:
                    piece = piece & ~ask.confirmed_shadow(piece, _BAY * area_found)
                grown[piece] = 255
            elif (ask.lit_as_the_table(piece)
                  and ask.seen_alike_over(piece, _ALL_BUT_RIM) and ask.on_a_side(piece)):
                # A top of the table's colour and light (a dark can's on its dark mat) looks as the table point
                # behind it does, so its parallax says nothing either way; but the other views see it alike,
                # over all of it but its rim, where their hull holds it. The shadow beside the foot is seen
                # alike too where the object behind it is as dark (the can's side), but it is darker than the
                # lit table, which a face turned up to the lamp is not. The top sits on the object's side,
                # darker than a face turned up; a stretch of table lit alike beyond a box's own top does not
                # (oak behind an oak-coloured box, which the others see alike because the box behind it has
                # the oak's colour). With the empty workspace too: such a top changes it by no more than the
                # table's noise (a white box's top on white laminate), so its cues say nothing there either.
                grown[piece] = 255
            else:
                # The cut may give a face and the table beside it one piece (a dark can's side in shade and
                # its shadow on a dark mat): the part that stands out over the table's level, of a face's
                # size, is the face.
                standing = piece & ask.seen & (ask.parallax > ask.table_level)
                grown[_standing_parts(standing, touching, _BAY * area_found)] = 255
            continue
        elif ask.hides_the_mapped_grain(piece):
            grown[piece] = 255
            continue
        # Mostly hidden from the other views' table (or a shadow's look): a face the others see, alike,
        # over most of it (over half of it with an empty workspace; without one their likeness is all that
        # speaks for it, and the table beside a lying can, which the can hides from them, is seen alike
        # over half of it where the can behind it has the table's colour).
        if ask.seen_alike_over(piece, 0.5 if view.background is not None else _MOSTLY):
            grown[piece] = 255
    # The colour models cannot tell a face of the table's colour turned from the lamp from the box's shadow
    # beside it, so the cut may give both to the table, or find one piece of the two. The table's grain (the
    # other views' mapped through the plane, or the empty workspace's) tells them apart pixel by pixel: the
    # shadow keeps it, the face hides it. So each stretch beyond the silhouette with a shadow's look is split
    # where the grain is lost, and a part weighed as a piece of the cut is.
    beyond = (hull > 0) & (grown == 0)
    if plane_grain is not None:
        looks = _shadow_look(view, ask.crop, ask.low, beyond)
        grown = _split_by_lost_grain(view, grown, mask, looks, plane_grain, None, ask.known,
                                     ask.hides_the_mapped_grain)
        if seen_alike is not None:
            grown = _hidden_faces_seen_alike(ask, grown, grain_before_the_looks)
    elif shadow is not None and view.grain_sums is not None:
        empty_workspace_grain = view.grain_sums
        grown = _split_by_lost_grain(view, grown, mask, beyond & shadow, lambda: empty_workspace_grain,
                                     view.shadow_look, ask.known, ask.hides_the_empty_workspace_grain)
    if not pieces and np.array_equal(grown, mask):
        return mask
    return _filled_region(grown, view)


def _hidden_faces_seen_alike(ask: _BeyondOutline, grown: np.ndarray,
                             grain_before_the_looks: Callable[[], np.ndarray] | None = None) -> np.ndarray:
    """``grown`` with the parts beyond it, within the other views' hull, whose table points the other views'
    silhouettes hide from them, that touch it, are of a face's size (:data:`_BAY` of the silhouette), that
    the other views see alike over :data:`_HIDDEN_FACE_ALIKE` of them, and that are either lit by the lamp
    (brighter than the shadow cast in the open) and not beyond a top, or have a shadow's look and are as
    dark as the shadow cast in the open.

    A face in shade of the table's colour looks as a shadow on the table does, and the table points behind
    it lie behind the object from the other views, so neither the plane's parallax nor the grain they map
    says anything there. But a shadow on the table lies at its own table point: where the others'
    silhouettes hide that point from them, the points of their hull on its ray stand in the air before the
    object, and they see there the object's other faces, mostly unlike it; a face stands on the object's
    surface, which they see alike (over 0.61 to 0.67 of each such face of the printed set's oak boxes, the
    table beside a lying can or an ellipsoid over 0.50 to 0.52). A face turned from the lamp is lit by the
    sky alone, as the open shadow is (:data:`_LIGHT_FIELD_BEYOND`), and no darker than it
    (:func:`_darker_than_the_open_shadow`); the shadow's soft edge is lighter, the table under the
    object's overhang darker. A face the lamp lights, wholly or in part, is told from the table beside the
    foot the same way, by the others' likeness (an oak box's lit face, its table points hidden from the
    others, was dropped with 0.67 of it seen alike: its view 0.573; a face half turned from the lamp, with
    0.91 of it: 0.829); it is brighter than the open shadow by the light's spread both ways, which the
    shadow on fabric, faint and lit nearly as the table, is not. But the table behind a top, beyond it up
    the plane's normal (:meth:`_BeyondOutline.beyond_a_top`), is seen alike over as much of it where the
    object in front of it in the others' views has the table's colour (0.64 of it, its view 0.746 if kept,
    in test_a_dark_face_of_the_table_s_colour_beside_its_shadow): no face. The lit table before a side's
    foot, which they may see alike too, is dropped after (:func:`_table_lit_at_the_rim_dropped`).

    In a look again (``grain_before_the_looks``, the table's grain mapped through the other views'
    silhouettes before the looks), a lit part must have its table points hidden from them over half of it
    by those silhouettes: what hides the rest is what they gained in the looks, on their likeness too, and
    the lit table before a foot that another view took before its own foot hides the same stretch of the
    plane from it (14/fabric-soup-can-can 2: 0.978 -> 0.939 looked again, under half of its table points
    hidden before the looks; the faces the looks again found, in shade, are kept as before)."""
    beyond = (ask.hull > 0) & (grown == 0) & ~ask.seen_behind
    open_shadow = ask.open_shadow
    if not open_shadow.any() or ask.lit_table is None:
        return grown
    brightness = ask.brightness
    # As dark as the open shadow within the light's spread over a table, and darker than the lit table by
    # that spread both ways: the shade of a face turned from the lamp, not the light varied over a table
    # where the object's shadow is faint (on fabric, the shadow is 0.74 of the lit table, the oak's 0.36).
    shadow_level = float(np.median(brightness[open_shadow]))
    shade = min(shadow_level * np.exp(_LIGHT_FIELD_BEYOND), np.exp(-2.0 * _LIGHT_FIELD_BEYOND) * ask.lit_table)
    # Brighter than the open shadow by that spread both ways: lit by the lamp, in part at least.
    lit = np.exp(2.0 * _LIGHT_FIELD_BEYOND) * shadow_level
    grown = grown.copy()
    near = cv2.dilate(grown, _SMALL) > 0
    for part in _touching_over(_opened_parts(beyond), near, _BAY * cv2.countNonZero(ask.mask)):
        if np.count_nonzero(ask.alike[part]) <= _HIDDEN_FACE_ALIKE * part.sum():
            continue
        level = float(np.median(brightness[part]))
        if level > lit and grain_before_the_looks is not None and 2 * np.count_nonzero(
                part & (~ask.seen | ~np.isfinite(grain_before_the_looks()[..., 0]))) < part.sum():
            continue
        if ((level > lit and not ask.beyond_a_top(part))
                or (level <= shade and ask.looks_a_shadow(part) and not ask.darker_than_the_open_shadow(part))):
            grown[part] = 255
    return grown


#: A face in shade whose table points the object hides from the other views is seen alike by them over
#: this share of it.
_HIDDEN_FACE_ALIKE = 0.6


def _standing_parts(standing: np.ndarray, touching: np.ndarray, least: float) -> np.ndarray:
    """(h, w) bool: the parts of ``standing`` (bool; closed, then opened by :data:`_SMALL`) that touch
    ``touching`` (bool) and are over ``least`` pixels."""
    kept = np.zeros(standing.shape, bool)
    for part in _touching_over(_opened_parts(cv2.morphologyEx(standing.astype(np.uint8), cv2.MORPH_CLOSE, _SMALL)),
                               touching, least):
        kept |= part
    return kept


def _split_by_lost_grain(view: _View, grown: np.ndarray, mask: np.ndarray, stretches: np.ndarray,
                         grain: Callable[[], np.ndarray], shade: np.ndarray | None, known: np.ndarray,
                         accepts: Callable[[np.ndarray], bool]) -> np.ndarray:
    """``grown`` with the parts of ``stretches`` (bool, beyond it) that hide the table's grain and that
    ``accepts`` takes for faces.

    Each stretch is split where the grain is lost (:func:`_grain_lost_pixels`: clear of its uncertainty in
    each pixel's own window, so that a few noisy windows chosen for their low slope do not pass the test
    told over the piece), against the grain the table round it keeps beyond ``known`` (0/255) and out of
    ``shade`` (:func:`_table_grain_round`; ``grain``: the other views' mapped through the plane, or the
    empty workspace's, called only where a stretch is weighed); a part that touches ``grown`` and is of a
    face's size (:data:`_BAY` of ``mask``) is weighed by ``accepts``. The grain compared with there must be
    the table's, as strong as round it within :data:`_GRAIN_POWER_SPREAD`: a shadow deep enough on a faint
    grain (white laminate) leaves none above JPEG's floor, and the object's own print seen at a table point
    is stronger than any grain of the table."""
    near = cv2.dilate(grown, _SMALL) > 0
    least = _BAY * cv2.countNonZero(mask)
    for stretch in _touching_over(_opened_parts(stretches), near, least):
        table = _table_grain_round(view, stretch, known, grain(), shade)
        if table is None:
            continue
        slope, power = table
        lost = _grain_lost_pixels(grain(), stretch, slope, _fine_per_coarse(view))
        for piece in _touching_over(_opened_parts(lost), near, least):
            seen_there = float(np.nanmean(grain()[piece][:, 1]))
            if power / _GRAIN_POWER_SPREAD < seen_there < power * _GRAIN_POWER_SPREAD and accepts(piece):
                grown[piece] = 255
    return grown


def _lit_faces_hiding_the_grain(view: _View, mask: np.ndarray, score: np.ndarray, hull: np.ndarray,
                                seen_alike: Callable[[np.ndarray], np.ndarray],
                                grain: Callable[[], np.ndarray]) -> np.ndarray:
    """``mask`` with the lit faces of the table's colour within the other views' ``hull`` that neither the
    cut nor the light found, told by the grain the other views see at their table points (``grain``,
    :func:`_plane_grain_sums`, called only where a stretch is weighed).

    A lit face of an oak box on oak is of the table's colour and light, and no brighter than the lit table
    round it where the lamp is low: the colour models give it to the table, and
    :func:`_faces_standing_out` finds only what stands out over a face's size. But the face hides the grain
    that the table behind it shows to the other views. So each lit stretch beyond the silhouette (no
    shadow's look) is split where the grain is lost (:func:`_split_by_lost_grain`), after the faces
    standing out are in: a part of a face found there would leave the rest of the face too small to stand
    out. A part is a face where it hides the grain over it whole (:func:`_grain_hidden`) and the other views
    see it alike (:func:`_seen_alike`) over most of it (:data:`_MOSTLY`): a stretch of table beside a tall
    object may lose its grain to the object's print that the others see at its table points, but they do
    not see that stretch alike. The parallax says nothing here: the lit face matches the table point
    behind it."""
    known = cv2.bitwise_or(hull, mask)
    x0, y0, x1, y1 = _cut_box(view, mask)
    crop = (slice(y0, y1), slice(x0, x1))
    beyond = (hull > 0) & (mask == 0)
    lit = np.zeros(mask.shape, bool)
    lit[crop] = ~_shadow_like(view.coarse[crop], (score[crop] < 1.0) | beyond[crop]) & beyond[crop]

    def a_lit_face(piece: np.ndarray) -> bool:
        if not _grain_hidden(view, piece, known, grain()):
            return False
        alike = seen_alike(cv2.dilate(np.where(piece, 255, 0).astype(np.uint8), _SMALL))
        return bool(np.count_nonzero(alike[piece]) > _MOSTLY * np.count_nonzero(piece))

    grown = _split_by_lost_grain(view, mask.copy(), mask, lit, grain, None, known, a_lit_face)
    return mask if np.array_equal(grown, mask) else _filled_region(grown, view)


def _faces_standing_out(view: _View, mask: np.ndarray, score: np.ndarray, hull: np.ndarray,
                        seen_alike: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """``mask`` with the pieces beyond it, within the other views' ``hull``, where the view's own evidence
    ``score`` (the plane's parallax in units of its noise, :data:`_HIDDEN` where no other view sees the
    table point) stands out and the other views see the object alike.

    A lit top of the table's colour and light (a white box's on white laminate, an oak box's on oak) gives
    the colour models nothing to tell it from the table, so the cut within the hull
    (:func:`_faces_beyond_outline`) gives it to the table. Yet it lies above the plane, and the plane maps
    the table behind it from another view to another place: the parallax stands out over all of it, if
    faintly. So does the table here and there (near another object's edge, over a coarse grain), so a pixel
    stands out where its evidence is over what the table round the hull shows (its :data:`_TABLE_LEVEL`
    quantile, 1 at least), over a piece wider than a 5-pixel disc (the band beside an edge is narrower).
    Where the parallax is within the noise (the table point behind the top, far off, looks as the top does),
    a pixel stands out by its light too: over what the lit table round the hull reaches
    (:func:`_lit_table_ceiling`), as a top nearer the lamp than the table is.
    The two cues must agree: the piece touches the silhouette, or is parted from it only by the blur of its
    edge (a box's edge, rounded or in shade, is lit as neither face it parts, and joins them), is of a face's
    size (:data:`_BAY`), and the other views see a point of their hull on its rays alike over all of it but
    its rim (:data:`_ALL_BUT_RIM`, :func:`_seen_alike`). The table seen through the hull, which is looser
    than the object, is seen alike only where the object behind happens to have its colour. A face so found
    reaches as far as its evidence stands out at all (over 1) and the other views see it alike.

    A piece nearer the lamp than the table (:func:`_nearer_the_lamp_than_the_table`) is told from the table
    by its light already, and needs the others' likeness over :data:`_MOSTLY` of it only: where another view
    missed its own view of the same top (two low side views of a tall box), that view carves the far part of
    the top from the hull, and nothing is seen alike there. Such a top reaches as far as its light stands
    out over the lit table round the hull, beyond the hull too: the model's fit takes a top found in part
    for a rounded or tilted one, and one left out whole for nothing."""
    seen = score != _HIDDEN
    round_it = _table_round(hull, hull) & seen
    if not round_it.any():
        return mask
    level = max(1.0, float(np.quantile(score[round_it], _TABLE_LEVEL)))
    beyond = (hull > 0) & (mask == 0) & seen
    above = beyond & (score > level)
    ceiling = _lit_table_ceiling(view, cv2.bitwise_or(hull, mask))
    # Beyond the silhouette, brighter than the lit table round it (none where no table is round it).
    brighter = (mask == 0) & (_brightness(view.coarse) > ceiling) if ceiling is not None else None
    if brighter is not None:
        # A top nearer the lamp than the table stands out by its light, whatever its parallax says.
        above |= (hull > 0) & brighter
    stands: np.ndarray = np.where(above, 255, 0).astype(np.uint8)
    stands = cv2.morphologyEx(cv2.morphologyEx(stands, cv2.MORPH_CLOSE, _SMALL), cv2.MORPH_OPEN, _CLOSING)
    count, labels = cv2.connectedComponents(stands, connectivity=8)
    if count <= 1:
        return mask
    at_all: np.ndarray = np.where(beyond & (score > 1.0), 255, 0).astype(np.uint8)
    at_all = cv2.morphologyEx(cv2.morphologyEx(at_all, cv2.MORPH_CLOSE, _SMALL), cv2.MORPH_OPEN, _SMALL)
    _, reach = cv2.connectedComponents(cv2.bitwise_or(at_all, stands), connectivity=8)
    # A top meets the face below it along the box's edge, rounded or bevelled, whose light is neither face's:
    # a lit top stands out up to that edge, within its blur of the silhouette (two steps of _SMALL).
    touching = ~_clear_of(mask)
    area = cv2.countNonZero(mask)
    grown = mask.copy()
    for label in range(1, count):
        piece = labels == label
        if not (piece & touching).any() or piece.sum() <= _BAY * area:
            continue
        alike = seen_alike(cv2.dilate(np.where(piece, 255, 0).astype(np.uint8), _SMALL))
        nearer_the_lamp = _nearer_the_lamp_than_the_table(view, piece, ceiling)
        # Another view may have missed its own view of a top (a tall box's, seen low from the side, as this
        # one did), and that carves the far part of the top from the others' hull: there they see nothing
        # alike. A top nearer the lamp than the table, which its light tells from the table already, is seen
        # alike over most of it, not all but its rim.
        if np.count_nonzero(alike[piece]) <= (_MOSTLY if nearer_the_lamp else _ALL_BUT_RIM) * piece.sum():
            continue
        face = reach == int(np.argmax(np.bincount(reach[piece])))
        alike = seen_alike(cv2.dilate(np.where(face, 255, 0).astype(np.uint8), _SMALL))
        grown[piece | (face & alike)] = 255
        # The edge between the piece and the silhouette is the object's too.
        grown[touching & (cv2.dilate(piece.astype(np.uint8), _SMALL, iterations=2) > 0)] = 255
        if nearer_the_lamp:
            # Such a top reaches as far as its light stands out over the lit table, beyond the hull too.
            assert brighter is not None
            lit = np.where(piece | brighter, 255, 0).astype(np.uint8)
            _, lit_labels = cv2.connectedComponents(cv2.morphologyEx(lit, cv2.MORPH_CLOSE, _SMALL), connectivity=8)
            grown[lit_labels == int(np.argmax(np.bincount(lit_labels[piece])))] = 255
    return _filled_region(grown, view)


#: The table round the other views' hull stands out by no more than this quantile of its evidence.
_TABLE_LEVEL = 0.9
#: A face the other views see is seen alike by them over all of it but its rim: over this share of it.
_ALL_BUT_RIM = 0.85
#: The silhouette just below a piece (the side under a top) is looked at over this many coarse pixels down
#: the plane's normal: a few, within the side of the smallest can the coarse image shows.
_SIDE_BELOW = 6


def _confirmed_shadow_round(view: _View, score: np.ndarray, crop: tuple[slice, slice],
                            known: np.ndarray) -> np.ndarray:
    """(h, w) bool: the open shadow, as the table under the overhang is told from it: the table that the view's
    evidence ``score`` confirms within ``crop`` (the graph cut's box), with a shadow's look, round the object
    and clear of ``known`` (0/255, the silhouette and the other views' hull; :func:`_clear_of`)
    (:func:`_shadows_under_object_dropped`)."""
    _, found = _shadow_in_box(view, crop, score)
    open_shadow = np.zeros(score.shape, bool)
    if found is not None:
        open_shadow[crop] = found.shadow
    return open_shadow & _clear_of(known)


def _darker_than_the_open_shadow(brightness: np.ndarray, piece: np.ndarray, open_shadow: np.ndarray) -> bool:
    """Whether ``piece`` (bool, coarse) is darker, by the view's ``brightness`` (:func:`_brightness`), than the
    deepest ``open_shadow`` (bool, :func:`_confirmed_shadow_round`; its :data:`_SHADOW_DEEPEST` quantile of
    brightness). A face of the table's colour turned from the lamp is lit by the sky and is no darker than the
    shadow cast in the open; the table under the object's overhang is (:func:`_shadows_under_object_dropped`).
    Without an open shadow to compare with, it is taken to be."""
    if not open_shadow.any():
        return True
    deepest = float(np.quantile(brightness[open_shadow], _SHADOW_DEEPEST))
    return float(np.median(brightness[piece])) < deepest


def _lit_above_its_surroundings(view: _View, piece: np.ndarray, mask: np.ndarray) -> bool:
    """Whether most of the image round ``piece`` (bool, coarse) beyond the silhouette ``mask`` is darker than
    the piece by over :data:`_DARKER_ROUND`.

    What the cut takes beyond the silhouette as table is the shadow cast on the table, or a stretch of lit
    table beside it: the lamp lights the table beyond a shadow, and a lit stretch has the shadow on one
    side at most, so neither is brighter than most of what lies round it. A face of the object is: a face of
    the table's colour in shade, under the sky alone, is as bright as the table in shadow, but stands over
    the table's darkest points, the shadow it casts and the rim round its foot, where the object hides part
    of the sky from the table too. Its colour matches the table point behind it; this does not."""
    beyond = _clear_of(mask)
    round_it = (cv2.dilate(piece.astype(np.uint8), _SMALL, iterations=2) > 0) & ~piece & beyond
    if not round_it.any():
        return False
    brightness = _brightness(view.coarse)
    darker = brightness[round_it] < (1.0 - _DARKER_ROUND) * float(np.median(brightness[piece]))
    return bool(np.count_nonzero(darker) > _MOSTLY * darker.size)


def _nearer_the_lamp_than_the_table(view: _View, piece: np.ndarray, ceiling: float | None) -> bool:
    """Whether ``piece`` (bool, coarse) is brighter over most of it than the brightest of the table round
    the silhouette and the other views' hull, its :data:`_LIT_TABLE` quantile, by more than that quantile
    stands above the table's median: beyond the spread of the table's own brightness (``ceiling``, as
    :func:`_lit_table_ceiling` gives it; None where no table is round them: never).

    A face turned up above the table (a white box's top on white laminate) stands nearer the lamp than the
    table and sees all of the sky, so it is lit more than any table point beside the object, whose sky the
    object hides in part: a top of the table's colour is brighter than the lit table round it, and a
    stretch of that table, lit or in shadow, is not. The table's grain, print and JPEG's noise spread its
    brightness (on a dark mat a few grey levels are much of it), so the margin is that spread."""
    return ceiling is not None and float(np.median(view.coarse[piece].sum(axis=1))) > ceiling


def _lit_table_ceiling(view: _View, known: np.ndarray) -> float | None:
    """The brightness that the table round ``known`` (0/255) stays under: its :data:`_LIT_TABLE` quantile and
    as much again as that stands above its median (:func:`_nearer_the_lamp_than_the_table`); None where no
    table is round it."""
    round_it = _table_round(known, known)
    if not round_it.any():
        return None
    table = _brightness(view.coarse)[round_it]
    middle, bright = float(np.median(table)), float(np.quantile(table, _LIT_TABLE))
    return 2.0 * bright - middle


def _clear_of(region: np.ndarray) -> np.ndarray:
    """(h, w) bool: the coarse pixels clear of ``region`` (uint8, nonzero in it) by two steps of
    :data:`_SMALL`, where its soft rim and the blur of its edge no longer reach."""
    return cv2.dilate(region, _SMALL, iterations=2) == 0


def _table_round(region: np.ndarray, clear_of: np.ndarray) -> np.ndarray:
    """(h, w) bool: the band round ``region`` (uint8, nonzero in it; four steps of :data:`_CLOSING`) that is
    clear of ``clear_of`` (uint8, :func:`_clear_of`): the table beside an object or a piece, measured to
    compare with it."""
    return _clear_of(clear_of) & (cv2.dilate(region, _CLOSING, iterations=4) > 0)


#: The brightest of the lit table round an object: this quantile of its brightness.
_LIT_TABLE = 0.9
#: A piece's surroundings are darker than it where their brightness is under its own by over this share.
_DARKER_ROUND = 0.1
#: Most of a piece's surroundings: over this share of them.
_MOSTLY = 0.75


def _cut_within(view: _View, region: np.ndarray, score: np.ndarray) -> np.ndarray:
    """The graph cut of ``region`` (0/255) seeded by the view's evidence ``score``, with nothing beyond it
    but the edge's blur (two small dilations) allowed: what else the view holds is looked for there, by the
    colour models its own seeds train."""
    return _graph_cut(view, region, score, cv2.bitwise_not(cv2.dilate(region, _SMALL, iterations=2)))


#: A bay of a silhouette (:func:`_bays_looked_into`) is looked into when it holds over this share of its area.
_BAY = 0.05


#: A view whose silhouette reaches this share of its area out of the other views' hull is cut again.
_DISAGREEMENT = 0.03
#: Seeded by the aim alone, a silhouette under this share of the other views' hull is cut again
#: within that hull (two views' hull is larger than the object, but seldom three times as large).
_TOO_SMALL = 0.35


class _Hulls:
    """The coarse hulls of sets of views' silhouettes, projected into another view."""

    def __init__(self, views: Sequence[_View], masks: Sequence[np.ndarray], plane: np.ndarray | None,
                 aim: np.ndarray) -> None:
        radius = _reach(views, masks, aim)
        steps = np.linspace(-radius, radius, _HULL_GRID)
        # The voxels' centres, as aim + np.stack(np.meshgrid(steps, steps, steps, indexing="ij"), axis=-1) gives
        # them, written axis by axis into one array.
        grid = np.empty((_HULL_GRID,) * 3 + (3,))
        grid[..., 0] = aim[0] + steps[:, None, None]
        grid[..., 1] = aim[1] + steps[None, :, None]
        grid[..., 2] = aim[2] + steps[None, None, :]
        grid = grid.reshape(-1, 3)
        self.height: np.ndarray | None = None
        if plane is not None:
            height = grid @ plane[:3] + plane[3]
            kept = height >= -radius / _HULL_GRID
            grid, self.height = grid[kept], height[kept]
        self.voxel = 2 * radius / (_HULL_GRID - 1)
        self.grid = grid
        self.views = views
        self.inside: list[np.ndarray] = []
        self.pixels: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        grid = np.ascontiguousarray(grid)
        for view, mask in zip(views, masks):
            if view.camera.dist is None:
                # One pass over the voxels instead of one array operation after another.
                coarse = np.empty((len(grid), 2), np.int64)
                seen, hit = np.empty(len(grid), np.uint8), np.empty(len(grid), np.uint8)
                depth = np.empty(len(grid))
                project_into_mask(grid, view.camera.projection, view.sx, view.sy, np.ascontiguousarray(mask),
                                  coarse, seen, depth, hit)
                seen, hit = seen.view(bool), hit.view(bool)
            else:
                # A voxel out of a view's image is not carved by it.
                coarse, seen, depth, hit = _projected_into(view, mask, grid, unseen_hit=True)
            self.inside.append(hit)
            self.pixels.append((coarse, seen, depth))
        self.shape = [mask.shape for mask in masks]

    def of(self, carving: set[int]) -> np.ndarray:
        """The hull of the views ``carving`` projected into the one view not among them (0/255)."""
        (i,) = set(range(len(self.views))) - carving
        return self.into(carving, i)

    def into(self, carving: set[int], i: int) -> np.ndarray:
        """The hull of the views ``carving`` projected into view ``i`` (0/255)."""
        return _voxels_into(self, self.carved(carving), i)

    def carved(self, carving: set[int]) -> np.ndarray:
        """(N,) bool: the voxels of the hull of the views ``carving``."""
        seen_by, misses = np.zeros(len(self.grid), np.intp), np.zeros(len(self.grid), np.intp)
        for j in carving:
            seen_by += self.pixels[j][1]
            misses += ~self.inside[j]
        # With three carving views or more, one of them may miss a voxel (a view that found only part
        # of the object carves the others' hulls less); a voxel that fewer than two carving views
        # (or all of them, if fewer) see within their images is not known to be anything.
        return (misses <= (1 if len(carving) >= 3 else 0)) & (seen_by >= min(2, len(carving)))


def _refined(view: _View, coarse_mask: np.ndarray, on_plane: bool) -> tuple[np.ndarray, np.ndarray]:
    """The full-resolution silhouette and its outline: the coarse edge, moved along its normal onto the
    image's own edge, to a fraction of a pixel.

    The coarse silhouette's edge lies within about a coarse pixel of the object's. Along each normal of
    its outline (smoothed, one sample a pixel), within a band of that width either side, the edge is
    where the colour steps most sharply (a blurred step is steepest half-way between its two sides:
    where a pixel is half object), but not with colour unlike the table's left outside it: an object's
    edge is often a dark rim (its surface turns away from the light there) or a print within a pixel
    or two of its outline, each a sharper step than the one from the table, and only the outermost
    step leaves nothing but table beyond. The table's colour is that just beyond the band, the median
    over a few neighbouring normals (its print and grain vary; a normal that ends on the object is
    outvoted); the table darkened, its colour kept, is the table too (the object's shadow beside its
    foot, which the coarse cut often gives the object), and the table's colour just within a candidate,
    where the object's own is plainly unlike it, puts the edge further in when the object stands on a
    known support plane (``on_plane``; :func:`_table_within`: the dark ring round the foot, a step as
    sharp as the object's). The edge runs smoothly from one normal
    to the next (a cheapest path round the outline), which carries it across stretches where object and
    table look alike, and its offsets, each found on one noisy profile, are averaged over a few
    neighbours. Each pixel whose centre lies inside the edge so found is object: the truth's rule for
    a pixel the edge crosses (half of it or more is object).

    Earlier, each pixel of the band went to the side whose nearest sure pixel's colour it was closer
    to; a sure pixel lies a band's width inside, and there the object's colour is not its rim's nor
    its print's at the edge, which sent edge pixels to the table (about half a pixel all round).
    """
    height, width = view.image.shape[:2]
    band = int(np.ceil(max(view.sx, view.sy))) + 1
    x, y, w, h = cv2.boundingRect(coarse_mask)
    reach = 4 * band
    x0, y0 = max(0, int(x * view.sx) - reach), max(0, int(y * view.sy) - reach)
    x1, y1 = min(width, int((x + w) * view.sx) + reach), min(height, int((y + h) * view.sy) + reach)
    # The coarse mask, resampled smoothly and cut at its half-way line, within the box.
    up = cv2.resize(coarse_mask, (width, height), interpolation=cv2.INTER_LINEAR)[y0:y1, x0:x1]
    mask = (up >= 128).astype(np.uint8)
    image = view.image[y0:y1, x0:x1].astype(np.float32)
    inside_edge = np.zeros_like(mask)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    for contour in contours:
        if cv2.contourArea(contour) < (2 * band) ** 2:
            # Too small for a band either side of its edge: kept as the coarse mask has it.
            cv2.drawContours(inside_edge, [contour], -1, 1, thickness=cv2.FILLED)
            continue
        loop, normals = _outline_loop(contour.reshape(-1, 2), _OUTLINE_SMOOTHING * max(view.sx, view.sy))
        offsets = _edge_offsets(image, loop, normals, band, on_plane)
        _fill_centres_inside(inside_edge, loop + offsets[:, None] * normals)
    # The edge moves at most the band's width: beyond it the coarse mask stands.
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band + 1, 2 * band + 1))
    sure, table = cv2.erode(mask, kernel), cv2.dilate(mask, kernel) == 0
    chosen = np.where((sure > 0) | ((inside_edge > 0) & ~table), 255, 0).astype(np.uint8)
    if not cv2.countNonZero(chosen):
        raise SilhouetteError(_NOTHING, view=view.index)
    silhouette = np.zeros((height, width), np.uint8)
    silhouette[y0:y1, x0:x1] = chosen
    return mask_with_outline(silhouette, view=view.index)


#: The coarse outline is smoothed along its length over this many coarse pixels (a Gaussian's
#: standard deviation) before its normals are taken: the coarse mask's staircase is no edge.
_OUTLINE_SMOOTHING = 1.25
#: Candidate offsets of the edge along a normal are this far apart (px); each is refined by a parabola.
_EDGE_STEP = 0.5
#: The table's colour is taken over the outermost this-many px of profiles that run on this far beyond
#: the band, and over this many normals.
_TABLE_DEPTH_PX = 1.5
_TABLE_BEYOND_PX = 1.0
_TABLE_NORMALS = 7
#: A colour within this many grey levels (beyond the table's own spread) of the table's is the table:
#: sensor noise and JPEG.
_TABLE_TOLERANCE = 6.0
#: Colour unlike the table's left outside the edge costs this much per grey level and px.
_OUTSIDE_WEIGHT = 1.0
#: A shadow darkens the table's colour to no less than this share of it (under the object's foot, where
#: the lamp and most of the sky are hidden) and changes it by under this share of its brightness there.
_DEEPEST_SHADOW = 0.15
_SHADOW_COLOUR_CHANGE = 0.15
#: The offsets found are smoothed along the outline over this many normals (a Gaussian's standard deviation).
_EDGE_SMOOTHING = 2.0
#: The edge's offset changing from one normal (a pixel along the outline) to the next costs this much
#: per candidate step (in grey levels of the colour step it must beat).
_EDGE_BEND_COST = 2.0


def _outline_loop(contour: np.ndarray, smoothing: float) -> tuple[np.ndarray, np.ndarray]:
    """A closed outline ((N, 2) pixel coordinates, in order, as cv2.findContours gives) smoothed along
    its length by a Gaussian of ``smoothing`` px, resampled one point a pixel of length, and the
    outward unit normal at each point: ((M, 2), (M, 2)) float64."""
    points = _smoothed_round(contour.astype(np.float64), smoothing)
    closed = np.vstack([points, points[:1]])
    length = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))])
    count = max(8, int(round(length[-1])))
    along = np.linspace(0.0, length[-1], count, endpoint=False)
    loop = np.column_stack([np.interp(along, length, closed[:, 0]), np.interp(along, length, closed[:, 1])])
    tangents = np.roll(loop, -1, axis=0) - np.roll(loop, 1, axis=0)
    tangents /= np.maximum(np.hypot(tangents[:, 0], tangents[:, 1]), 1e-9)[:, None]
    normals = np.column_stack([tangents[:, 1], -tangents[:, 0]])
    # (ty, -tx) points out of a loop of positive signed area (the shoelace formula), in of a negative one.
    signed_area = 0.5 * float(np.sum(loop[:, 0] * np.roll(loop[:, 1], -1) - np.roll(loop[:, 0], -1) * loop[:, 1]))
    return loop, (normals if signed_area >= 0 else -normals)


def _edge_offsets(image: np.ndarray, loop: np.ndarray, normals: np.ndarray, band: int,
                  on_plane: bool) -> np.ndarray:
    """(M,) how far along each outward normal (px, within ``band``) the object's edge lies: the sharpest
    colour step that leaves only the table's colour beyond it, and, standing ``on_plane``, none of it just
    within, on a path smooth round the loop (see :func:`_refined`). ``image`` is float32 BGR, ``loop``
    and ``normals`` as :func:`_outline_loop`.

    Without a support plane the scan names no table that the object stands on (a turntable's dark cloth, a
    studio's backdrop), so no ring of it darkened round the object's foot is looked for."""
    # The profiles run on a little beyond the band, so that the table's colour is taken where the blur of
    # an edge at the band's end does not reach, and a little within it, so that the candidates at its
    # inner end have what lies just within them too.
    within = int(round(_TABLE_WITHIN_PX / _EDGE_STEP)) + 1
    offsets = np.arange(-band - within * _EDGE_STEP, band + _TABLE_BEYOND_PX + 1e-9, _EDGE_STEP)
    count, candidates = len(loop), int(np.sum(offsets <= band + 1e-9))

    # The profiles at the candidates and half a pixel either side, in one: half a pixel is one candidate step,
    # so the profile shifted either way is the same samples one step along (the offsets are multiples of a
    # half, exact in floating point), read from a profile one step longer at each end.
    shift = int(round(0.5 / _EDGE_STEP))
    assert shift * _EDGE_STEP == 0.5
    extended = np.concatenate([offsets[0] - _EDGE_STEP * np.arange(shift, 0, -1), offsets,
                               offsets[-1] + _EDGE_STEP * np.arange(1, shift + 1)])
    at = loop[:, None, :] + extended[None, :, None] * normals[:, None, :]
    sampled = cv2.remap(image, at[..., 0].astype(np.float32), at[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE)
    colours = sampled[:, shift:shift + len(offsets)]
    # The colour step across each candidate, over one pixel: blur makes an edge's step steepest where
    # it is half-way.
    step = np.linalg.norm(sampled[:, 2 * shift:] - sampled[:, :len(offsets)], axis=2)
    depth = max(1, int(round(_TABLE_DEPTH_PX / _EDGE_STEP)))
    ends = colours[:, -depth:, :]
    table = _wrapped_median(np.median(ends, axis=1), _TABLE_NORMALS)
    spread = _wrapped_median(np.median(np.linalg.norm(ends - table[:, None, :], axis=2), axis=1), _TABLE_NORMALS)
    tolerance = (2 * spread + _TABLE_TOLERANCE)[:, None]
    off_table = _unlike_table(colours, table)
    unlike = np.maximum(off_table - tolerance, 0.0) * _EDGE_STEP
    # What lies beyond a candidate (from one blur's width outside it, past the edge's blur) and is not table.
    band_start = colours[:, within:within + depth, :].mean(axis=1)
    gap = max(1, int(round(_edge_blur(band_start, table, step[:, within:candidates]) / _EDGE_STEP)))
    beyond = np.zeros_like(unlike)
    beyond[:, :len(offsets) - gap - 1] = np.cumsum(unlike[:, ::-1], axis=1)[:, ::-1][:, gap + 1:]
    cost = _OUTSIDE_WEIGHT * beyond - step
    if on_plane:
        cost += _INSIDE_WEIGHT * _table_within(colours, off_table < tolerance, table, tolerance, gap)
    path = np.empty(count, np.intp)
    smoothest_path(np.ascontiguousarray(cost[:, within:candidates], dtype=np.float64), _EDGE_BEND_COST, 1, path)
    path += within
    # To a fraction of a step: the vertex of the parabola through the step's strength either side.
    rows = np.arange(count)
    before = step[rows, np.maximum(path - 1, 0)]
    at = step[rows, path]
    after = step[rows, path + 1]  # the profiles run on beyond the last candidate
    curvature = before - 2 * at + after
    interior = (path > within) & (curvature < 0)
    fraction = np.where(interior, 0.5 * (before - after) / np.where(interior, curvature, -1.0), 0.0)
    # Each offset is found on one noisy profile, while the edge runs on smoothly from one to the next.
    return _smoothed_round(offsets[path] + np.clip(fraction, -0.5, 0.5) * _EDGE_STEP, _EDGE_SMOOTHING)


def _table_within(colours: np.ndarray, table_like: np.ndarray, table: np.ndarray, tolerance: np.ndarray,
                  gap: int) -> np.ndarray:
    """(M, D) what each candidate of the profiles ``colours`` (M, D, 3) pays for the samples with the
    table's colour (``table_like``, (M, D) bool: within its row's ``tolerance`` (M, 1) of ``table`` (M, 3),
    :func:`_unlike_table`) in the :data:`_TABLE_WITHIN_PX` just within it, past the edge's blur (``gap``
    samples): per px, the contrast of the object's own colour (the profile's innermost
    :data:`_OBJECT_DEPTH_PX`) with the table, where that contrast is plain (:data:`_OBJECT_UNLIKE`) and the
    object's colour is no shade of the table's either; nothing where the object looks like the table, lit
    or in shade.

    The table darkened round the object's foot (the lamp and the sky hidden there) and its cast shadow
    are the table's colour in shade: a candidate at their outer end leaves only the table beyond it, and
    their step to the lit table is often as sharp as the object's own to them. What tells them from the
    object is what lies within: the table's colour just within a candidate says the object ends further
    in, unless the object's colour is the table's too, or the table's in shade (a dark can on a dark mat,
    whose near-black a shadow gives the mat as well), where it says nothing."""
    deep = max(1, int(round(_OBJECT_DEPTH_PX / _EDGE_STEP)))
    own = np.median(colours[:, :deep, :], axis=1)[:, None, :]
    contrast = _unlike_table(own, table)
    plain = (contrast > _OBJECT_UNLIKE * tolerance) & (_off_every_shade(own, table)[0] > tolerance)
    cost_per_px = np.where(plain, contrast, 0.0)
    run = np.concatenate([np.zeros((len(colours), 1)), np.cumsum(table_like * _EDGE_STEP, axis=1)], axis=1)
    end = np.clip(np.arange(colours.shape[1]) - gap, 0, None)
    start = np.clip(end - int(round(_TABLE_WITHIN_PX / _EDGE_STEP)), 0, None)
    return cost_per_px * (run[:, end] - run[:, start])


#: The stretch (px) just within a candidate edge, past its blur, where the table's colour costs.
_TABLE_WITHIN_PX = 1.0
#: The table's colour there costs this share of the object's contrast with the table per px.
_INSIDE_WEIGHT = 0.5
#: The object's own colour: the median over the profile's innermost this-many px.
_OBJECT_DEPTH_PX = 2.0
#: The object's colour is plainly not the table's when it lies this many times the table's tolerance
#: (its spread and the sensor's noise) from it.
_OBJECT_UNLIKE = 3.0


def _edge_blur(inside: np.ndarray, table: np.ndarray, steps: np.ndarray) -> float:
    """How far (px, a Gaussian's standard deviation) the image blurs the object's edge: from each normal's
    contrast between the object's colour at its inner end and the table's (``inside``, ``table``: (M, 3))
    and its steepest step over one pixel (``steps``: (M, K)), a step of contrast C blurred by sigma being
    C erf(1 / (2 sqrt(2) sigma)) over a pixel at its steepest; the median over the normals of contrast
    :data:`_BLUR_CONTRAST` or more, one pixel where there are fewer than :data:`_BLUR_NORMALS`.

    A softer lens, or a larger image of the same scene, spreads the object's colour further beyond its
    edge; counted as colour unlike the table beyond a candidate, it pushed the edge outward."""
    contrast = np.linalg.norm(inside - table, axis=1)
    sure = contrast >= _BLUR_CONTRAST
    if int(sure.sum()) < _BLUR_NORMALS:
        return 1.0
    share = np.clip(steps[sure].max(axis=1) / contrast[sure], 1e-3, 1.0 - 1e-6)
    return float(np.median(0.5 / (np.sqrt(2.0) * erfinv(share))))


#: Normals whose object and table colours differ by less (grey levels) say little of the blur.
_BLUR_CONTRAST = 40.0
#: Fewer normals of that contrast than this, and the blur is taken to be a pixel's.
_BLUR_NORMALS = 10


def _smoothed_round(values: np.ndarray, sigma: float) -> np.ndarray:
    """``values`` (N, ...) round a closed loop, smoothed along it by a Gaussian of ``sigma`` entries."""
    radius = min(int(np.ceil(3 * sigma)), (len(values) - 1) // 2) if sigma > 0 else 0
    if radius < 1:
        return values
    taps = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sigma) ** 2)
    taps /= taps.sum()
    wrapped = np.concatenate([values[-radius:], values, values[:radius]])
    columns = wrapped.reshape(len(wrapped), -1)
    smoothed = np.column_stack([np.convolve(columns[:, k], taps, mode="valid") for k in range(columns.shape[1])])
    return smoothed.reshape(values.shape)


def _unlike_table(colours: np.ndarray, table: np.ndarray) -> np.ndarray:
    """(M, D) how far each colour of ``colours`` (M, D, 3) lies from its row's ``table`` colour (M, 3), in
    grey levels, the table in shade included: a colour close to the table's darkened (a shadow dims
    the table's light, not its colour) is as far as it is from that darkened colour."""
    from_shade, darkening, power = _off_every_shade(colours, table)
    from_table = np.linalg.norm(colours - table[:, None, :], axis=2)
    in_shade = from_shade < _SHADOW_COLOUR_CHANGE * darkening * np.sqrt(power)
    return np.where(in_shade, np.minimum(from_table, from_shade), from_table)


def _off_every_shade(colours: np.ndarray, table: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M, D) how far each colour of ``colours`` (M, D, 3) lies from its row's ``table`` colour (M, 3) in the
    shade that comes closest to it (from :data:`_DEEPEST_SHADOW` of its light to all of it), in grey levels;
    and (M, D) that shade, and (M, 1) the table colour's squared length."""
    power = np.maximum(np.einsum("mk,mk->m", table, table), 1.0)[:, None]
    darkening = np.clip(np.einsum("mdk,mk->md", colours, table) / power, _DEEPEST_SHADOW, 1.0)
    return np.linalg.norm(colours - darkening[..., None] * table[:, None, :], axis=2), darkening, power


def _wrapped_median(values: np.ndarray, window: int) -> np.ndarray:
    """The running median of ``values`` (N, ...) round a closed loop, over ``window`` (odd) neighbours."""
    half = min(window // 2, (len(values) - 1) // 2)
    return np.median(np.stack([np.roll(values, k, axis=0) for k in range(-half, half + 1)]), axis=0)


def _fill_centres_inside(binary: np.ndarray, polygon: np.ndarray) -> None:
    """Set to 1 each pixel of ``binary`` (h, w) whose centre lies inside ``polygon`` ((N, 2) pixel
    coordinates, closed, even-odd rule). cv2.fillPoly rounds the vertices and fills every pixel the
    edge touches, which grows a polygon by about half a pixel all round."""
    height, width = binary.shape
    start, end = polygon, np.roll(polygon, -1, axis=0)
    low, high = np.minimum(start[:, 1], end[:, 1]), np.maximum(start[:, 1], end[:, 1])
    rows = np.arange(max(0, int(np.ceil(low.min()))), min(height - 1, int(np.floor(high.max()))) + 1)
    if not len(rows):
        return
    # Each edge crosses the rows in [low, high): a vertex on a row is counted once.
    row_index, edge = np.nonzero((low[None, :] <= rows[:, None]) & (rows[:, None] < high[None, :]))
    across = (rows[row_index] - start[edge, 1]) / (end[edge, 1] - start[edge, 1])
    x = start[edge, 0] + across * (end[edge, 0] - start[edge, 0])
    order = np.lexsort((x, row_index))
    row_index, x = row_index[order], x[order]
    first = np.clip(np.ceil(x[0::2]), 0, width).astype(np.int64)
    last = np.clip(np.floor(x[1::2]), -1, width - 1).astype(np.int64)
    for row, a, b in zip(rows[row_index[0::2]], first, last):
        if b >= a:
            binary[row, a:b + 1] = 1


def _coarse_aim(view: _View, aim: np.ndarray) -> np.ndarray:
    uv, depth = view.project(aim[None, :])
    if depth[0] <= 0:
        raise SilhouetteError("the views' aim lies behind this camera: its pose does not look at the object",
                              view=view.index)
    return view.to_coarse(uv)[0]


def _brightness(image: np.ndarray) -> np.ndarray:
    """(h, w) each pixel's channels summed, as ``image.sum(axis=2)`` (float32 or float64, any strides) adds
    them, in one pass (NumPy's sum over so short an axis is slow)."""
    brightness = np.empty(image.shape[:2], image.dtype)
    channel_sum(image, brightness)
    return brightness


def _first_cut(view: _View, views: Sequence[_View], plane: np.ndarray | None, aim: np.ndarray,
               standing: Sequence[np.ndarray | None],
               earlier: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """The view's coarse silhouette from its own cues (0/255, the coarse size), and the evidence
    it came from, in units of its noise (None without a plane or a background). ``earlier``, the
    evidence of a look with less of the table taken to be hidden: where a table point is hidden now,
    what that look saw stands."""
    cw, ch = view.coarse_size
    centre = _coarse_aim(view, aim)
    floor = _NOISE_FLOOR
    if view.background is not None:
        evidence = _background_evidence(view)
        floor = _BACKGROUND_NOISE_FLOOR
        if plane is not None:
            # A pixel darker than the empty workspace with its chromaticity looks like a shadow, and is
            # taken for one; but so looks an object of the table's colour, or a white one on white. A
            # shadow lies on the table: another view that sees the same table point, with nothing in
            # front of it, sees it darkened alike. Where such a view does not, something stands there.
            others = [v for v in views if v is not view and v.background is not None]
            contradicted = _darkening_contradicted(view, others, plane, standing)
            evidence = np.where(contradicted | _texture_lost(view), _relative_difference(view.coarse, view.background),
                                evidence)
            # A shadow under a coloured lamp is not of the table's chromaticity (the lamp's colour is
            # gone from it), but it is on the table: darker than the empty workspace, and mapped
            # through the plane by the other views like the rest of the table.
            mapped = _parallax_evidence(view, [v for v in views if v is not view], plane,
                                        [standing[v.index] for v in views if v is not view])
            mapped_score = np.nan_to_num(mapped, nan=np.inf) / max(_noise_level(mapped), _NOISE_FLOOR)
            brightness, ground, hue_shift = _hue_shift(view)
            shadow = (brightness < 0.95 * ground) & (hue_shift < _LAMP_HUE_SHIFT) & (mapped_score < 1.5)
            evidence = np.where(shadow, np.minimum(evidence, mapped), evidence)
    elif plane is not None:
        evidence = _parallax_evidence(view, [v for v in views if v is not view], plane,
                                      [standing[v.index] for v in views if v is not view])
    else:
        return _cut_around_aim(view, centre), None
    noise = max(_noise_level(evidence), floor)
    score = evidence / noise
    if plane is not None and view.background is None and earlier is not None:
        # A face as bright as the table (a white box's top under the lamp, on white laminate) differs from
        # the table point behind it only in its tint; the brightness of one table point differs more from
        # view to view (the light's fall-off, a sheen) than its tint does, which buries a tint in the noise
        # of the colour difference. Measured apart, against its own noise, the tint stands out. Only on the
        # second look: on the first, the other views' objects are known only in part, and the table beside
        # this object's foot, which they see behind their object, takes that object's tint.
        tint_score = _tint_parallax(view, [v for v in views if v is not view], plane,
                                    [standing[v.index] for v in views if v is not view])
        score = np.where(np.isnan(score), score, np.fmax(score, tint_score))
    texture_score = None
    if plane is not None and view.background is None:
        # A face of the table's colour differs from the table mapped through the plane by its grain alone.
        texture = _texture_parallax(view, [v for v in views if v is not view], plane,
                                    [standing[v.index] for v in views if v is not view], centre)
        texture_score = texture / max(_noise_level(texture), _TEXTURE_NOISE_FLOOR)
        score = np.where(np.isnan(score), score, np.fmax(score, texture_score))
    if earlier is not None:
        score = np.where(np.isnan(score) & (earlier > _HIDDEN), earlier, score)
    # Where the object hides the table point behind a pixel from every other view, the pixel is next
    # to the object's foot, or on it: it joins what stands out, for the graph cut to decide; but only
    # what differs from the table says that something stands there at all.
    hidden = np.isnan(score)
    score = np.where(hidden, _HIDDEN, score)
    differs = cv2.morphologyEx(np.where(score > 2.5, 255, 0).astype(np.uint8), cv2.MORPH_OPEN, _SMALL)
    differs[hidden] = 0
    if plane is not None and view.background is None:
        # A table point no other view sees (the top of a tall object maps far behind it, out of their
        # pictures) says nothing: beside what stands out near the aim, it is hidden, for the graph cut to decide.
        seen = np.zeros((ch, cw), bool)
        for other in views:
            if other is not view:
                seen |= view.sees(other, plane)[1]
        view.unconfirmable = ~seen
        near = _component_near(differs, centre, reach=0.25 * np.hypot(cw, ch))
        if near is not None:
            _, _, w, h = cv2.boundingRect(near)
            beside = _dilated(near, max(2, int(round(_BESIDE * max(w, h))))) > 0
            attached = beside & ~seen
            score = np.where(attached, _HIDDEN, score)
            hidden |= attached
    # A pixel is hidden only where the other views' first look saw something stand in front of its
    # table point: on an empty table, or with a shadow alone, nothing is hidden. An object of the
    # table's colour may be all hidden and hardly differ where the others see it; but a region of
    # hidden pixels alone (table behind another view's object or its shadow) says nothing stands there,
    # and is no candidate, however near the aim or large it is beside the object's pieces.
    region = _component_near(_regions_holding(cv2.bitwise_or(differs, np.where(hidden, 255, 0).astype(np.uint8)),
                                              differs), centre, reach=0.25 * np.hypot(cw, ch))
    if region is None or cv2.countNonZero(region) < _SPECK:
        raise SilhouetteError(_NOTHING, view=view.index)
    if view.background is not None:
        # Against the empty workspace what differs is the object, but in pieces where its print or its
        # colour matches the table here and there: every piece near the aim joins, within their convex
        # outline, for the graph cut to seed from (one piece alone loses an object of the table's colour).
        near = _components_near(cv2.morphologyEx(differs, cv2.MORPH_CLOSE, _CLOSING), centre,
                                reach=0.25 * np.hypot(cw, ch))
        region = _joined_within_outline(near)
    else:
        region = _with_pieces_beside(region, differs)
        # The plane's parallax outlines an object the colour of the table where other views see the table
        # beside it, and leaves its inside (table-coloured against table-coloured) out: a silhouette has
        # no holes, so what the evidence encloses is the object's too.
        region = _holes_filled(cv2.morphologyEx(region, cv2.MORPH_CLOSE, _CLOSING))
    if view.background is None:
        # What this cut sees of the shadow in the open, for the views that see none of their own
        # (auto_silhouettes); a later look keeps what an earlier one saw.
        shadow_seen = _open_shadow_seen(view, region, score)
        if shadow_seen is not None:
            view.shadow_seen = shadow_seen
    try:
        # Only this cut, of the view's own evidence, asks the shadow hidden from the other views: a view cut
        # again within their hull, or into its bays, is to drop or add only what the hull says, and a face
        # of the table's colour that this cut kept there is not to be asked again.
        cut = _graph_cut(view, region, score, hidden_shadows=True)
    except SilhouetteError:
        cut = np.zeros_like(region)  # the colour models gave it all to the table: the evidence decides below
    standing_out = cv2.bitwise_and(region, differs)
    if cv2.countNonZero(cv2.bitwise_and(cut, standing_out)) < _KEPT_BY_CUT * cv2.countNonZero(standing_out):
        # The colour models could not tell object from table (an object of the table's own colour and
        # grain): the evidence alone draws the silhouette.
        cut = _filled_region(cv2.morphologyEx(region, cv2.MORPH_CLOSE, _CLOSING), view)
    if texture_score is not None:
        cut = _with_faces_of_grain(view, cut, region, score, np.nan_to_num(texture_score))
    return cut, score


def _with_faces_of_grain(view: _View, cut: np.ndarray, region: np.ndarray, score: np.ndarray,
                         texture_score: np.ndarray) -> np.ndarray:
    """``cut`` with the faces beside it that stand out by their grain alone and that the graph cut left out.

    A face of the table's colour and grain (a box cut from the table's own wood) stands out through the
    plane by its grain only: its colour is the table's, so the colour models give it to the table whatever
    the evidence says. Where the grain alone carries the evidence (the texture's score is the pixel's) over
    a piece of the region that touches the silhouette, the piece is such a face, if it is wider than the
    band that the grain's window leaves beside any edge: the table just beyond an object's outline maps, in
    the other views, to windows that hold the object's edge too, and so stands out as a thin band along
    the outline; a face is wider than the band everywhere, and a 5-pixel disc fits in it."""
    grain: np.ndarray = np.where((texture_score >= score) & (score > 2.5) & (region > 0) & (cut == 0),
                                 255, 0).astype(np.uint8)
    grain = cv2.morphologyEx(grain, cv2.MORPH_OPEN, _SMALL)
    count, labels = cv2.connectedComponents(grain, connectivity=8)
    if count <= 1:
        return cut
    wide = cv2.morphologyEx(grain, cv2.MORPH_OPEN, _CLOSING)
    touching = cv2.dilate(cut, _SMALL) > 0
    faces = np.zeros(count, bool)
    faces[np.unique(labels[(wide > 0)])] = True
    beside = np.zeros(count, bool)
    beside[np.unique(labels[touching & (grain > 0)])] = True
    faces &= beside
    faces[0] = False
    if not faces.any():
        return cut
    # The face's pixels near its wide core (its fringe along the outline is the band's).
    core = cv2.dilate(np.where(faces[labels] & (wide > 0), 255, 0).astype(np.uint8), _SMALL)
    return _filled_region(cv2.bitwise_or(cut, cv2.bitwise_and(core, grain)), view)


#: The tint's difference on the table is taken to be at least this many grey levels (over the three
#: channels): on an even grey table most of it is exactly 0, and the pixels' rounding to whole grey
#: levels leaves about one.
_TINT_NOISE_FLOOR = 1.0
#: The side of JPEG's colour blocks, full-resolution px (8 samples of colour at half the resolution).
_JPEG_COLOUR_BLOCK = 16


def _tint_parallax(view: _View, others: Sequence[_View], plane: np.ndarray,
                   hiding: Sequence[np.ndarray | None]) -> np.ndarray:
    """How far each coarse pixel's tint differs from the other views' at its table point through the plane
    (:func:`_parallax_evidence`, their silhouettes ``hiding`` the table behind them), in units of its noise,
    where it stands out over a JPEG colour block (:func:`_over_a_block`), 0 elsewhere and where no other view
    sees the table point."""
    tint = _parallax_evidence(view, others, plane, hiding, _chroma_difference)
    return _over_a_block(view, tint / max(_noise_level(tint), _TINT_NOISE_FLOOR))


def _half_a_colour_block(view: _View) -> int:
    """Half a JPEG colour block, in the view's coarse pixels (rounded up): how far a colour runs in JPEG."""
    return int(np.ceil(0.5 * _JPEG_COLOUR_BLOCK / view.scale))


def _over_a_block(view: _View, tint_score: np.ndarray) -> np.ndarray:
    """A tint's score (in units of its noise) where it stands out over a JPEG colour block at least, 0
    elsewhere. JPEG keeps the colour in blocks, at half the resolution: a coloured object's tint runs onto
    the table beside it, and a block's tint goes astray here and there. A tint that stands out over less
    than a block is JPEG's, not a face's."""
    block = 2 * _half_a_colour_block(view) + 1
    wide = cv2.morphologyEx(np.where(tint_score > 2.5, 255, 0).astype(np.uint8), cv2.MORPH_OPEN,
                            cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (block, block)))
    return np.where(wide > 0, tint_score, 0.0).astype(np.float32)


def _tint_change(view: _View) -> np.ndarray:
    """How far each coarse pixel's tint has moved from the empty workspace's (in units of its noise),
    where the pixel is no darker than the empty workspace: a shadow only takes light away, and under a
    coloured lamp it takes the lamp's tint away too, so a tint that changed where no light was lost is
    no shadow's. A face as bright as the table differs from it in its tint only."""
    assert view.background is not None
    tint = _chroma_difference(view.coarse, view.background)
    score = tint / max(_noise_level(tint), _TINT_NOISE_FLOOR)
    brightness, ground = _brightness(view.coarse), _brightness(view.background)
    return _over_a_block(view, np.where(brightness < _SHADOW_DARKENING * ground, 0.0, score))


#: A pixel darker than the empty workspace by this factor or more may be in a shadow.
_SHADOW_DARKENING = 0.95


#: A graph cut that keeps less than this share of what stands out near the aim failed to model it.
_KEPT_BY_CUT = 0.5


def _with_pieces_beside(region: np.ndarray, differs: np.ndarray) -> np.ndarray:
    """``region`` and the pieces of ``differs`` beside it (within a third of its size): a print's
    band of the table's own colour splits an object's evidence in two, and the piece at the aim alone
    loses the rest."""
    _, _, w, h = cv2.boundingRect(region)
    grown = _dilated(region, max(2, int(round(_BESIDE * max(w, h)))))
    count, labels = cv2.connectedComponents(cv2.bitwise_or(differs, region), connectivity=8)
    touching = np.zeros(count, bool)
    touching[labels[grown > 0]] = True
    touching[0] = False
    return np.where(touching[labels], 255, 0).astype(np.uint8)


#: Pieces that stand out within this share of the region's size from it are of the same object.
_BESIDE = 0.3


def _dilated(binary: np.ndarray, reach: int) -> np.ndarray:
    """``binary`` (uint8) dilated by the ellipse of ``reach`` px either way (2 reach + 1 across), as cv2.dilate
    does it over the whole image: worked out over its pieces' box grown by ``reach`` alone, beyond which the
    dilation reaches nothing (and the image's edge counts for nothing in a dilation)."""
    x, y, w, h = cv2.boundingRect(binary)
    dilated = np.zeros_like(binary)
    if not w:
        return dilated
    box = (slice(max(0, y - reach), y + h + reach), slice(max(0, x - reach), x + w + reach))
    dilated[box] = cv2.dilate(binary[box], cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1)))
    return dilated


_CLOSING = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))


_SMALL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))


def _graph_cut(view: _View, region: np.ndarray, score: np.ndarray, outside: np.ndarray | None = None,
               iterations: int | None = None, hidden_shadows: bool = False) -> np.ndarray:
    """GrabCut on a box around ``region`` (the pixels that stand out near the aim), seeded by the
    evidence ``score`` (in units of its noise); ``outside`` (0/255), where given, is sure table.
    ``hidden_shadows``: the pixels hidden from the other views that look like the shadow they confirm
    (:func:`_hidden_shadow`; with a background, :func:`_hidden_table`) are seeded as table, not as object,
    and those darker than the table but of another colour than its shadow as object for sure."""
    cw, ch = view.coarse_size
    x0, y0, x1, y1 = _cut_box(view, region)
    mask = np.full((y1 - y0, x1 - x0), cv2.GC_PR_BGD, np.uint8)
    crop = (slice(y0, y1), slice(x0, x1))
    inside = region[crop] > 0
    mask[inside] = cv2.GC_PR_FGD
    sure = cv2.erode(region, _SMALL)[crop] > 0
    mask[sure & (score[crop] > _SURE)] = cv2.GC_FGD
    low = score[crop] < 1.0
    if view.background is not None:
        # Against the empty workspace what shows no change is table for sure, but not within the region that
        # stands out: a face there that changed alike in another view (a dark face beside the shadow seen
        # through it) is left to the colour models.
        mask[low & ~sure & ~inside] = cv2.GC_BGD
        if hidden_shadows:
            # A hidden pixel darker than the empty workspace, but far from its colour darkened, is the object's
            # own side in shade (as without it, below), where the table's shadow is seen to keep its colour.
            image, empty = view.coarse[crop], view.background[crop]
            hidden = score[crop] == _HIDDEN
            darker = _brightness(image) < _SHADOW_DIMMER * _brightness(empty)
            off = _off_colours(image, empty, darker & (hidden | low))
            if _shadow_keeps_colour(off, low & darker):
                mask[hidden & sure & darker & (off > _NO_SHADOW)] = cv2.GC_FGD
            # The converse: hidden pixels of the empty workspace's colour, darkened as the open shadow, are
            # the table in the object's shadow (_hidden_table). The open shadow in sight is the one the other
            # views confirm here, or where the object hides all of it (a lamp behind a lying can), every
            # view's (_open_shadow).
            shadow = _open_shadow_in(image, empty, low)
            darkenings = (_darkening_of(image, empty)[shadow] if np.any(shadow)
                          else None if view.open_shadow is None else view.open_shadow())
            if darkenings is not None and len(darkenings):
                probable, certain = _hidden_table(image, empty, hidden & (off < 1.0), darkenings,
                                                  sure & (score[crop] > _SURE) & ~hidden)
                mask[probable] = cv2.GC_PR_BGD
                mask[certain] = cv2.GC_BGD
    else:
        # A shadow maps through the plane like the rest of the table, but its dark colour may suit the
        # object's model: a dark pixel that the other views confirm is table for sure.
        if hidden_shadows:
            shadow, seen = _shadow_in_box(view, crop, score)
        else:
            shadow = low & _shadow_like(view.coarse[crop], low)
        mask[shadow & ~sure] = cv2.GC_BGD
        if hidden_shadows:
            image = view.coarse[crop]
            hidden = score[crop] == _HIDDEN
            if seen is None and view.open_shadow is not None:
                seen = _shadow_seen_elsewhere(image, low, hidden, view.open_shadow())
            if seen is not None:
                shadow, _, darker, off_table, table_colour = seen
                hidden_shadow = _hidden_shadow(seen, hidden)
                mask[hidden_shadow] = cv2.GC_PR_BGD
                # Darker than any shadow in the open, such a pixel is the table under the object's overhang (the
                # strip under a lying can's belly), unless it is a face of the object as dark and of the table's
                # colour. An object that, where the view surely sees it, has none of the table's colour, lit or
                # in shade, has no such face: the strip is table for sure, which the colour models, holding the
                # can's shaded side, would otherwise keep. A dark can of its mat's colour is left to the colour
                # models, and after them to the other views (_shadows_under_object_dropped).
                if _none_of_the_table_s_colour(image, table_colour, sure & (score[crop] > _SURE) & ~hidden):
                    mask[hidden_shadow & _under_the_object(seen)] = cv2.GC_BGD
                # The converse: a hidden pixel darker than the table, but far from the colour of the table and
                # of the shadow on it alike, is no shadow. It is the object's own side in shade (a tin's dark
                # band, an ellipsoid's underside), whose dark colour the table's model, holding the shadow,
                # would take. Only where the table's shadow is seen to keep the table's colour: where most of
                # the dark table that the other views confirm is of another colour (a coloured lamp, a bluish
                # sky), a shadow's colour is not known, and a dark pixel of any colour may be one.
                if _shadow_keeps_colour(off_table, low & darker):
                    faces = hidden & sure & darker & (off_table > _NO_SHADOW)
                    faces[faces] = _off_colour(image[faces], _median_colour(image, shadow)) > _NO_SHADOW
                    mask[faces] = cv2.GC_FGD
    # The box's rim is outside the object (it was grown around it), unless it is the image's own edge.
    rim = np.zeros(mask.shape, bool)
    rim[[0, -1], :] = True
    rim[:, [0, -1]] = True
    if x0 == 0:
        rim[:, 0] = False
    if y0 == 0:
        rim[0, :] = False
    if x1 == cw:
        rim[:, -1] = False
    if y1 == ch:
        rim[-1, :] = False
    mask[rim & (mask != cv2.GC_FGD)] = cv2.GC_BGD
    if outside is not None:
        mask[outside[crop] > 0] = cv2.GC_BGD
    return _run_grabcut(view, mask, (x0, y0, x1, y1), iterations)


def _cut_box(view: _View, region: np.ndarray) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) the graph cut's box around ``region`` (0/255), within the coarse image."""
    cw, ch = view.coarse_size
    x, y, w, h = cv2.boundingRect(region)
    margin = max(8, int(_CUT_MARGIN * max(w, h)))
    return max(0, x - margin), max(0, y - margin), min(cw, x + w + margin), min(ch, y + h + margin)


#: The graph cut's box reaches this share of the region's size beyond it: table enough for its colour model.
_CUT_MARGIN = 0.5
#: Evidence over this many units of its noise, well within what stands out, seeds the object for sure.
_SURE = 5.0


class _ShadowSeen(NamedTuple):
    """The shadow a view sees within the graph cut's box (:func:`_shadow_seen`)."""
    shadow: np.ndarray  # bool, the shadow as a region
    brightness: np.ndarray  # each pixel's channels summed (:func:`_brightness`)
    darker: np.ndarray  # bool, darker than the table (:data:`_SHADOW_DIMMER`)
    off_table: np.ndarray  # the dark pixels' :func:`_off_colours` from the table's colour
    table_colour: np.ndarray  # (3,) the median colour of the table the other views confirm


def _shadow_seen(image: np.ndarray, low: np.ndarray, shadow: np.ndarray, hidden: np.ndarray) -> _ShadowSeen | None:
    """Within the graph cut's box: the ``shadow`` (:func:`_shadow_like` of the table the other views confirm,
    ``low``) as a region, each pixel's brightness, whether it is darker than the table, the dark pixels'
    :func:`_off_colours` from the table's colour (the ``hidden`` ones and the confirmed table's), and that
    colour; None where no shadow region is seen."""
    # A shadow is a region; the table's own darker grain (a mat's speckle, wood's late rings) passes for
    # a shadow pixel by pixel, but not over a few pixels together.
    shadow = cv2.morphologyEx(shadow.astype(np.uint8), cv2.MORPH_OPEN, _SMALL) > 0
    if not np.any(shadow):
        return None
    table_colour = _median_colour(image, low)
    brightness = _brightness(image)
    darker = brightness < _SHADOW_DIMMER * float(table_colour.sum())
    # Only the dark pixels' colours are asked about: the hidden ones, and the table the others see.
    return _ShadowSeen(shadow, brightness, darker, _off_colours(image, table_colour, darker & (hidden | low)),
                       table_colour)


def _open_shadow_seen(view: _View, region: np.ndarray, score: np.ndarray) -> np.ndarray | None:
    """Without an empty workspace: the brightness over the table's of the shadow that the view sees in the
    open (:func:`_shadow_seen`, within the graph cut's box round ``region``, of the table the other views
    confirm: ``score`` under 1), None where it sees none."""
    x0, y0, x1, y1 = _cut_box(view, region)
    crop = (slice(y0, y1), slice(x0, x1))
    _, seen = _shadow_in_box(view, crop, score)
    if seen is None:
        return None
    return seen.brightness[seen.shadow] / max(float(seen.table_colour.sum()), 1.0)


def _shadow_in_box(view: _View, crop: tuple[slice, slice], score: np.ndarray) -> tuple[np.ndarray, _ShadowSeen | None]:
    """Within the graph cut's box ``crop``: the table the other views confirm (``score`` under 1 where some
    other view's picture holds the table point; not the view's ``unconfirmable`` pixels) that looks like a
    shadow (:func:`_shadow_like`), and :func:`_shadow_seen` of it, the pixels hidden from them
    (``score`` :data:`_HIDDEN`) asked: the one way to ask it, for the first cut's graph cut and the shadow it
    sees in the open, the open shadow round a silhouette, the table under the object's overhang, and the table
    in shadow in a bay (:func:`_table_in_shadow`). A first cut asks it twice of one box and one evidence: the
    view keeps its last one. Read only."""
    rows, columns = crop
    key = (rows.start, rows.stop, columns.start, columns.stop, score[crop].tobytes())
    if view.box_shadow is None or view.box_shadow[0] is not view.coarse or view.box_shadow[1] != key:
        image, low = view.coarse[crop], score[crop] < 1.0
        if view.unconfirmable is not None:
            # Evidence there is 0 for want of any (:func:`_parallax_evidence`), not the table confirmed: a dark
            # face there (a box's top seen from low views, near, whose table point lies far behind it, out of
            # the others' pictures) would pass for the confirmed shadow, table for sure in the graph cut.
            low &= ~view.unconfirmable[crop]
        shadow = low & _shadow_like(image, low)
        view.box_shadow = (view.coarse, key, shadow, _shadow_seen(image, low, shadow, score[crop] == _HIDDEN))
    return view.box_shadow[2], view.box_shadow[3]


def _table_in_shadow(view: _View, mask: np.ndarray, region: np.ndarray, score: np.ndarray) -> np.ndarray:
    """(h, w) bool, coarse: within the graph cut's box round ``region`` (0/255), the shadow the other views
    confirm and the pixels hidden from them that look like it (:func:`_hidden_shadow`), where the object (``mask``
    where the view surely sees it) has none of the table's colour; none elsewhere."""
    x0, y0, x1, y1 = _cut_box(view, region)
    crop = (slice(y0, y1), slice(x0, x1))
    shadow, seen = _shadow_in_box(view, crop, score)
    found = np.zeros(score.shape, bool)
    if seen is None:
        return found
    hidden = score[crop] == _HIDDEN
    standing = (cv2.erode(mask, _SMALL)[crop] > 0) & (score[crop] > _SURE) & ~hidden
    if _none_of_the_table_s_colour(view.coarse[crop], seen.table_colour, standing):
        found[crop] = shadow | _hidden_shadow(seen, hidden)
    return found


def _shadow_seen_elsewhere(image: np.ndarray, low: np.ndarray, hidden: np.ndarray,
                           darkenings: np.ndarray) -> _ShadowSeen | None:
    """As :func:`_shadow_seen`, for a view that sees no shadow in the open: the shadow is where the ``hidden``
    pixels have the colour of the table (the table the other views confirm, ``low``), darkened to no more
    than the other views see their open shadow darkened to (``darkenings``, its brightness over its table's,
    the :data:`_SHADOW_BRIGHTEST` quantile), a few together; None where this view sees none so."""
    if not np.any(low):
        return None
    table_colour = _median_colour(image, low)
    brightness = _brightness(image)
    darker = brightness < _SHADOW_DIMMER * float(table_colour.sum())
    off_table = _off_colours(image, table_colour, darker & (hidden | low))
    ceiling = float(np.quantile(darkenings, _SHADOW_BRIGHTEST)) * float(table_colour.sum())
    shadow = cv2.morphologyEx((hidden & darker & (off_table < 1.0) & (brightness <= ceiling)).astype(np.uint8),
                              cv2.MORPH_OPEN, _SMALL) > 0
    return _ShadowSeen(shadow, brightness, darker, off_table, table_colour) if np.any(shadow) else None


def _shadow_look(view: _View, crop: tuple[slice, slice], table: np.ndarray, region: np.ndarray) -> np.ndarray:
    """(h, w) bool: the pixels of ``region`` (bool, coarse) within the graph cut's box ``crop`` that have a
    shadow's look (:func:`_shadow_like`) against ``table`` (bool, the box's: the table the view's evidence
    confirms), the region counted in with it."""
    looks = np.zeros(region.shape, bool)
    looks[crop] = _shadow_like(view.coarse[crop], table | region[crop]) & region[crop]
    return looks


def _shadow_like(image: np.ndarray, table: np.ndarray) -> np.ndarray:
    """The ``table`` pixels of the same chromaticity as their median and darker than it: a shadow. Only
    they are asked about (the graph cut marks a shadow among the pixels the other views confirm), so the
    rest of the image is not looked at. The same chromaticity is as near the median as most of the lit
    table's (nine in ten), or a plain table's, up to a limit an object's other colour lies beyond: a textured
    table (a cutting mat's grid) has many colours, and its shadow keeps each of them."""
    found = np.zeros(table.shape, bool)
    shadow_like_pixels(image, table.view(np.uint8), _SHADOW_DIMMER, found.view(np.uint8))
    return found


def _hidden_shadow(seen: _ShadowSeen, hidden: np.ndarray) -> np.ndarray:
    """The ``hidden`` pixels (no other view sees their table point) that look like a shadow on the table
    (darker than it, its colour kept: ``seen``'s ``off_table`` under 1), and no brighter than the shadow the
    other views confirm (``seen``'s ``shadow``, a region, not empty).

    The strip of table under a lying can, and the part of a can's shadow behind it, are hidden from the
    other views by the object itself, so nothing but their look tells them from the object; seeded as
    object, the graph cut keeps them wherever the object's colour model holds a dark colour, as it does
    for a dark can, or for any object's own shaded side. A face of the table's colour, or a white box's on
    white laminate, turned from the lamp looks like the table in shadow too, but the lamp's light reaches
    it in part, or more of the sky's: it is brighter than the shadow on the table beside it."""
    return hidden & (seen.off_table < 1.0) & (seen.brightness <= np.quantile(seen.brightness[seen.shadow],
                                                                               _SHADOW_BRIGHTEST))


def _hidden_table(image: np.ndarray, empty: np.ndarray, kept: np.ndarray, shadow: np.ndarray,
                  faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which of the hidden pixels that keep the empty workspace's colour (``kept``, darkened or not) are
    probably, and which surely, the table in the object's shadow: as dark as the open shadow (``shadow``,
    its darkenings, :func:`_open_shadow`), and darker than its darkest. ``faces``, where the object surely
    stands and the other views see it. (h, w) bool each, none if the object's faces look like the table.

    The strip of table under a lying can or an ellipsoid's belly is hidden from the other views by the
    object itself; seeded as object, the graph cut keeps it wherever the object's colour model holds a
    dark colour. Against its own empty workspace such a pixel is the table darkened with its colour
    kept. A face of the object's turned from the lamp may look so too where the object has the table's
    colour (a white box on white laminate, a box of the table's wood): where most of its faces do,
    nothing is said. Darker than the darkest of the open shadow is only the table that the object hides
    from the sky as well as from the lamp, or a face darker still: only where none of the object's faces
    of the table's colour is that dark is it the table for sure.

    And only where something tells it from a face in shade. Its colour does where the pixel is bright
    enough (:func:`_told_from_table_above`): in the dark, the few grey levels that set a face's colour
    apart from the table's are within the noise, and a near-black can's lower body keeps "the table's
    colour" as well as the table does. Failing that, its darkness does where no face of the object in
    shade is that dark: a face turned from the lamp is still lit by the sky, as the open shadow is, so it
    is at least as bright as the object's darkest face in sight dimmed by the open shadow's depth."""
    like_table = _off_colours(image, empty, faces) < 1.0
    if np.count_nonzero(like_table) >= _TABLE_LIKE_FACES * np.count_nonzero(faces):
        return np.zeros_like(kept), np.zeros_like(kept)
    darkening = _darkening_of(image, empty)
    probable = kept & (darkening <= np.quantile(shadow, _SHADOW_BRIGHTEST))
    deepest = np.quantile(shadow, _DEEPEST)
    if np.any(like_table):
        deepest = min(deepest, np.quantile(darkening[like_table], _DEEPEST))
    shaded_face = np.quantile(darkening[faces], _DEEPEST) * np.quantile(shadow, _DEEPEST)
    told = (_brightness(image) >= _told_from_table_above(image[faces], empty[faces])) | (darkening < shaded_face)
    return probable, kept & (darkening < deepest) & told


def _told_from_table_above(faces: np.ndarray, empty: np.ndarray) -> float:
    """The brightness (summed over the channels) above which most of the object's ``faces`` ((N, 3), not
    empty; ``empty``, the empty workspace's colours there), darkened to it, are told from the table's
    colour by :func:`_off_colour`. A face keeps its colour in shade, but the grey levels that set it
    apart from the table's shrink with the light, while the test's floor (:data:`_SHADOW_TINT_FLOOR`,
    the noise) does not: a face whose colour lies a share u of its brightness from the table's is told
    only above _SHADOW_TINT_FLOOR / u, and never where u is within :data:`_SHADOW_TINT`."""
    brightness = faces.sum(axis=1)
    scaled = empty * (brightness / np.maximum(empty.sum(axis=1), 1.0))[:, None]
    unlike = np.abs(faces - scaled).sum(axis=1) / np.maximum(brightness, 1.0)
    told_above = np.full(len(faces), np.inf)
    apart = unlike > _SHADOW_TINT
    told_above[apart] = _SHADOW_TINT_FLOOR / unlike[apart]
    return float(np.quantile(told_above, _TABLE_LIKE_FACES, method="higher"))  # no interpolation to infinity


def _darkening_of(image: np.ndarray, empty: np.ndarray) -> np.ndarray:
    """(h, w) each pixel's brightness over the empty workspace's."""
    return cv2.transform(image, _CHANNEL_SUM) / np.maximum(cv2.transform(empty, _CHANNEL_SUM), 1.0)


def _open_shadow(views: Sequence[_View], scores: dict[int, np.ndarray]) -> np.ndarray:
    """(N,) the darkenings (:func:`_darkening_of`) of the open shadow (:func:`_open_shadow_in`, where the
    evidence ``scores`` is under 1), every view's pooled. The shadow's depth is the light's, the same on any
    table point and from any view: a view whose own shadow is all hidden behind the object (a lamp behind
    a lying can) knows it from the others."""
    found = []
    for view in views:
        assert view.background is not None
        shadow = _open_shadow_in(view.coarse, view.background, scores[view.index] < 1.0)
        found.append(_darkening_of(view.coarse, view.background)[shadow])
    return np.concatenate(found)


def _open_shadow_in(image: np.ndarray, empty: np.ndarray, confirmed: np.ndarray) -> np.ndarray:
    """(h, w) bool: the ``confirmed`` pixels (another view sees their change alike at the same table
    point) darker than the empty workspace and of its colour, a few together: the shadow in the open."""
    candidates = confirmed & (_brightness(image) < _SHADOW_DIMMER * _brightness(empty))
    shadow = candidates & (_off_colours(image, empty, candidates) < 1.0)
    return cv2.morphologyEx(shadow.astype(np.uint8), cv2.MORPH_OPEN, _SMALL) > 0


#: An object whose faces have the table's colour in this share of what is surely seen of them looks like
#: the table, and its shaded faces like the table's shadow.
_TABLE_LIKE_FACES = 0.5
#: The darkest of a region is taken at this quantile of its pixels: a few are darker by the noise.
_DEEPEST = 0.05


def _median_colour(image: np.ndarray, where: np.ndarray) -> np.ndarray:
    """(3,) float32 the median of each channel of ``image`` over ``where`` (not empty)."""
    return np.array([median(np.ascontiguousarray(image[..., k][where])) for k in range(3)], np.float32)


def _off_colours(image: np.ndarray, colour: np.ndarray, asked: np.ndarray) -> np.ndarray:
    """(H, W) :func:`_off_colour` of the ``asked`` pixels of ``image`` from ``colour`` ((3,), or (H, W, 3):
    each pixel's own, the empty workspace's), infinite elsewhere."""
    off = np.full(asked.shape, np.inf, np.float32)
    off[asked] = _off_colour(image[asked], colour if colour.ndim == 1 else colour[asked])
    return off


def _shadow_keeps_colour(off: np.ndarray, dark_table: np.ndarray) -> bool:
    """Whether the table's shadow is seen to keep the table's colour: :data:`_SHADOW_KNOWN` of the
    ``dark_table`` the other views confirm lies within a shadow's colour of it (``off`` under 1)."""
    return bool(np.count_nonzero(dark_table & (off < 1.0)) >= _SHADOW_KNOWN * np.count_nonzero(dark_table))


def _off_colour(pixels: np.ndarray, colour: np.ndarray) -> np.ndarray:
    """(N,) how far each of the (N, 3) ``pixels``' colour lies from ``colour`` brought to the pixel's
    brightness, in units of what a shadow's may (under 1: ``colour`` darkened or lit). A deep shadow's
    colour is a few grey levels, mostly noise: the colour is compared in grey levels, within a share of
    the brightness or :data:`_SHADOW_TINT_FLOOR`, whichever is more."""
    brightness = pixels.sum(axis=1)
    scaled = colour * (brightness / np.maximum(colour.sum(axis=-1), 1.0))[:, None]
    return np.abs(pixels - scaled).sum(axis=1) / np.maximum(_SHADOW_TINT * brightness, _SHADOW_TINT_FLOOR)


#: A shadow's colour lies within this share of its brightness (summed over the channels) of the table's
#: colour darkened alike, or within :data:`_SHADOW_TINT_FLOOR` grey levels: the sensor's noise and JPEG's.
_SHADOW_TINT = 0.04
_SHADOW_TINT_FLOOR = 6.0
#: The confirmed shadow's brightness is taken at this quantile of its pixels: its soft edge is brighter.
_SHADOW_BRIGHTEST = 0.9
#: A shadow is darker than the table by this factor at least.
_SHADOW_DIMMER = 0.92
#: A pixel whose colour lies this many times what a shadow's may from the table's colour and its shadow's
#: is no shadow: the lamp's tint gone from a shadow and JPEG's colour blocks stay well within it. (A coloured object's glow
#: on the table beside it is of another colour too, but no darker than the table: no shadow's darkness.)
_NO_SHADOW = 4.0
#: The table's shadow is taken to keep the table's colour where this share of the dark table that the
#: other views confirm does.
_SHADOW_KNOWN = 0.5


def _run_grabcut(view: _View, mask: np.ndarray, box: tuple[int, int, int, int],
                 iterations: int | None = None) -> np.ndarray:
    cw, ch = view.coarse_size
    x0, y0, x1, y1 = box
    result = np.zeros((ch, cw), np.uint8)
    # GrabCut's labels are 0 to 3, the object's the odd ones (GC_FGD 1, GC_PR_FGD 3), the table's the even.
    odd = mask & 1
    has_object = cv2.countNonZero(odd) > 0
    has_table = cv2.countNonZero(odd) < odd.size
    if not has_object:
        raise SilhouetteError(_NOTHING, view=view.index)
    if has_table:
        image = np.ascontiguousarray(np.clip(view.coarse[y0:y1, x0:x1], 0, 255).astype(np.uint8))
        background_model, object_model = np.zeros((1, 65)), np.zeros((1, 65))
        cv2.setRNGSeed(0)  # GrabCut's k-means starts from OpenCV's global generator
        cv2.grabCut(image, mask, (0, 0, 0, 0), background_model, object_model,
                    _GC_ITERATIONS if iterations is None else iterations,
                    cv2.GC_INIT_WITH_MASK)  # the box is unused: the mask seeds it
    result[y0:y1, x0:x1] = (mask & 1) * np.uint8(255)
    return _filled_region(result, view)


def _filled_region(binary: np.ndarray, view: _View) -> np.ndarray:
    """The largest region of a coarse binary image, holes filled."""
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        raise SilhouetteError(_NOTHING, view=view.index)
    filled = np.zeros_like(binary)
    cv2.drawContours(filled, [max(contours, key=cv2.contourArea)], -1, 255, thickness=cv2.FILLED)
    return filled


def _cut_again_around_aim(views: Sequence[_View], masks: Sequence[np.ndarray], index: int, hull: np.ndarray,
                          aim: np.ndarray) -> np.ndarray:
    """View ``index``, seeded by the aim alone, cut again within the other views' ``hull``, where only the
    colours their silhouettes hold (:func:`_object_colours`) seed the object."""
    view = views[index]
    return _cut_around_aim(view, _coarse_aim(view, aim), hull, _object_colours(views, masks, index))


def _object_colours(views: Sequence[_View], masks: Sequence[np.ndarray], index: int) -> np.ndarray:
    """(h, w) bool: the pixels of view ``index`` whose colour the other views' silhouettes hold more often
    than the rest of their pictures. An object looks much alike from every view; a stretch of table that
    the hull holds (a hull of views all from one side reaches far down to the table) does not look like
    what the other views found."""
    counts = np.ones((2, _COLOUR_BINS ** 3))
    for j, (other, mask) in enumerate(zip(views, masks)):
        if j != index:
            bins = _colour_bins(other.coarse)
            inside = mask > 0
            counts[0] += np.bincount(bins[inside], minlength=_COLOUR_BINS ** 3)
            counts[1] += np.bincount(bins[~inside], minlength=_COLOUR_BINS ** 3)
    likelihood = counts / counts.sum(axis=1, keepdims=True)
    return (likelihood[0] > likelihood[1])[_colour_bins(views[index].coarse)]


#: Bins per channel of the colour histograms that compare views (:func:`_object_colours`).
_COLOUR_BINS = 16


def _colour_bins(image: np.ndarray) -> np.ndarray:
    q = np.clip(image, 0, 255).astype(np.int64) * _COLOUR_BINS // 256
    return (q[..., 0] * _COLOUR_BINS + q[..., 1]) * _COLOUR_BINS + q[..., 2]


def _cut_around_aim(view: _View, centre: np.ndarray, hull: np.ndarray | None = None,
                    object_colours: np.ndarray | None = None) -> np.ndarray:
    """Without a plane or a background: the region around the aim is taken for the object, the rest
    of the image for the background, and the graph cut draws the line between them by colour. With
    the other views' ``hull`` (0/255), the object is looked for within it, and outside it is sure
    background."""
    cw, ch = view.coarse_size
    mask = np.full((ch, cw), cv2.GC_PR_BGD, np.uint8)
    cx, cy = int(round(centre[0])), int(round(centre[1]))
    if hull is None:
        axes = (max(2, int(0.12 * cw)), max(2, int(0.15 * ch)))
        cv2.ellipse(mask, (cx, cy), axes, 0, 0, 360, cv2.GC_PR_FGD, thickness=-1)
    else:
        mask[hull > 0] = cv2.GC_PR_FGD
        if object_colours is not None:
            mask[(hull > 0) & ~object_colours] = cv2.GC_PR_BGD
        mask[_clear_of(hull)] = cv2.GC_BGD
    cv2.circle(mask, (cx, cy), max(2, cw // 40), cv2.GC_FGD, thickness=-1)
    return _run_grabcut(view, mask, (0, 0, cw, ch))


#: Added to every channel before a ratio of image to empty workspace is taken: a dark pixel's noise must
#: not pass for a change of brightness.
_RATIO_OFFSET = 8.0


def _log_ratio(view: _View) -> np.ndarray:
    """(h, w, 3) float32: the log of each channel of the image over the empty workspace. The table's own
    texture divides out; a shadow is a smooth darkening, the same seen from any view.

    Of both pictures before their rounding to whole grey levels: a coarse pixel averages many of the lens's,
    so its value is known to a fraction of a grey level, and the rounding's half a grey level is a large step
    in the log of a dark pixel. On a dark mat, a can's lower body in shade and the shadow beside it (a dozen
    grey levels a channel) then changed alike within that step, and the other views' view of the shadow at
    the body's table points took the body for the table (seed 17's rubber mat: a view 0.78 before, 0.85).
    The noise of the change that first tells what changed at all is :func:`_change_noise`'s."""
    return _log_ratio_of(*view.unrounded)


def _log_ratio_of(image: np.ndarray, empty: np.ndarray) -> np.ndarray:
    """:func:`_log_ratio` of two images of the same size."""
    return np.log((image + _RATIO_OFFSET) / (empty + _RATIO_OFFSET)).astype(np.float32)


def _change_noise(view: _View, unrounded: float) -> float:
    """The noise of the view's change against the empty workspace (:func:`_log_ratio`'s magnitudes summed
    over the channels) on the table, as the coarse pictures rounded to whole grey levels give it, unless their
    rounding made that estimate too high; then ``unrounded``, as the pictures before their rounding give it.

    Rounding moves each channel of either image by half a grey level at most, so the rounded change lies
    within a grey level's step of the unrounded one, and so would its noise. On a dark, flat table it does
    not: there the coarse change is 0 or one grey level in most pixels, and the median and spread of so few
    values read the steps, not the noise (on a near-black mat, twice the noise or more). A dark can a
    little darker than its mat (0.85 of it, four grey levels) then fell within that false noise and was
    left out. An estimate that rounding made too low (over half the pixels unchanged: none at all) lets
    more pass as changed, and the look through the plane that follows still tells the table; it is kept
    (read before the rounding there too, two dark cans' views lost 0.12 and 0.18, and a third its top). Which
    of the pieces so found may join the object is judged against the noise before the rounding
    (:func:`_clearly_changed`)."""
    assert view.background is not None
    rounded = _noise_level(np.abs(_log_ratio_of(view.coarse, view.background)).sum(axis=2))
    # The empty workspace's grey levels are whole (unless the light was evened): the kernel's median counts them.
    table = np.array([median(np.ascontiguousarray(view.background[..., k]).ravel()) for k in range(3)],
                     view.background.dtype)
    step = float(np.log((table + 1.0 + _RATIO_OFFSET) / (table + _RATIO_OFFSET)).sum())
    return unrounded if rounded > unrounded + step else rounded


def _ratio_parallax(view: _View, others: Sequence[_View], plane: np.ndarray, ratios: dict[int, np.ndarray],
                    occluders: dict[int, np.ndarray] | None) -> np.ndarray:
    """How little any other view, seeing the same table point through the support plane, agrees with each
    coarse pixel's change against the empty workspace (:func:`_log_ratio`): the table and a shadow on it
    change alike from every view, what stands above the plane does not. NaN where every other view that
    would see the table point has it behind ``occluders`` (0/255 per view: what surely stands there)."""
    cw, ch = view.coarse_size
    own = ratios[view.index]
    best = np.full((ch, cw), np.inf, np.float32)
    seen = np.zeros((ch, cw), bool)
    occluded = np.zeros((ch, cw), bool)
    for other in others:
        maps, inside, behind = view.sees(other, plane, None if occluders is None else occluders[other.index])
        occluded |= behind
        key = (*_pair(other, plane), _ratio_parallax)
        if key not in view.differences:
            # A pixel's worth of misregistration: the other view's range of values around the point.
            low, high = cv2.erode(ratios[other.index], _SMALL), cv2.dilate(ratios[other.index], _SMALL)
            warped_low = _remapped(low, maps, cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_REPLICATE)
            warped_high = _remapped(high, maps, cv2.INTER_LINEAR,
                                    borderMode=cv2.BORDER_REPLICATE)
            disagreement = np.empty(own.shape[:2], np.float32)
            ratio_disagreement(own, warped_low, warped_high, disagreement)
            view.differences[key] = disagreement
        disagreement = view.differences[key]
        np.minimum(best, disagreement, out=best, where=inside)
        seen |= inside
    # Hidden behind what stands there in the other views that would see it: NaN; out of every other view's
    # picture: -1 (nothing is known).
    best[~seen] = np.where(occluded[~seen], np.nan, -1.0)
    return best


def _background_cuts(views: Sequence[_View], plane: np.ndarray,
                     aim: np.ndarray) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """Every view's coarse silhouette and its evidence (in units of its noise), when every view has a picture
    of the empty workspace and there is a support plane: what changed against the empty workspace, less what
    changed alike in another view at the same table point (a shadow)."""
    ratios = {view.index: _log_ratio(view) for view in views}
    changed, textures, tables, shades, clearly, clear_change = {}, {}, {}, {}, {}, {}
    for view in views:
        change = np.abs(ratios[view.index]).sum(axis=2)
        texture, grain_kept, view.grain_sums = _texture_change(view, _coarse_aim(view, aim))
        # Darker than the empty workspace, of its chromaticity, its grain kept: a shadow on the table.
        shade = view.shadow_look = _shadow_of_table(view)
        tables[view.index] = shade & (np.nan_to_num(grain_kept) > _GRAIN_SEEN)
        # Where the grain is too faint for a pixel's own window, it may still be told over a piece whole.
        shades[view.index] = shade & ~tables[view.index]
        # A face of the table's colour changes the grain, not the colour; a shadow keeps it.
        textures[view.index] = np.nan_to_num(texture / max(_noise_level(texture), _GRAIN_NOISE_FLOOR))
        # Lost whole, the grain says a face for sure, though on a table whose grain the noise blurs that reads
        # under _SURE of its noise: the graph cut's colour models would give a face of the table's colour
        # (a box of its table's wood) to the table, and are not to be asked there.
        textures[view.index][np.nan_to_num(texture) >= _GRAIN_LOST_WHOLE] = _GRAIN_LOST_WHOLE_SCORE
        # A face as bright as the table changed its tint only (the other views judge whether the table
        # itself took that tint: the glow of a coloured object beside it).
        beside_the_change = np.maximum(textures[view.index], _tint_change(view))
        unrounded = _noise_level(change)
        clear_change[view.index] = change / max(unrounded, _BACKGROUND_NOISE_FLOOR)
        score = np.maximum(change / max(_change_noise(view, unrounded), _BACKGROUND_NOISE_FLOOR), beside_the_change)
        changed[view.index] = cv2.morphologyEx(np.where(score > 2.5, 255, 0).astype(np.uint8), cv2.MORPH_OPEN, _SMALL)
        clearly[view.index] = _clearly_changed(clear_change[view.index], beside_the_change)
    # First with nothing taken to stand anywhere, then with what stood out hiding the table points behind it
    # (a view that sees the object there cannot confirm a shadow); then, twice, with the silhouettes cut
    # from it hiding them too (a face that looked like a shadow in every view is found by its neighbours).
    scores, standing = _stands_out(views, plane, ratios, textures, tables, shades, changed, None, None)
    # From the second look on, what another view confirms must look like a shadow to be one (_unlike_a_shadow):
    # the first look's confirmed shadow says how a shadow looks in each view.
    unlike = {view.index: _unlike_a_shadow(view, scores[view.index], clear_change[view.index]) for view in views}
    occluders = {i: cv2.dilate(mask, _SMALL, iterations=_OCCLUSION_MARGIN) for i, mask in standing.items()}
    scores, standing = _stands_out(views, plane, ratios, textures, tables, shades, changed, unlike, occluders)
    # The last evidence, with the silhouettes cut hiding the most of the table behind them, counts the
    # colour's parallax too (_stands_out), for the last cut only: fed back as what hides the table in the
    # next look, the colour found at one view's foot makes the table beside the others' feet stand out.
    for round_ in range(1, _OCCLUSION_ROUNDS + 1):
        cuts = _background_cut(views, aim, scores, standing, clearly, _OCCLUDER_ITERATIONS)
        occluders = {view.index: cv2.bitwise_or(cv2.dilate(standing[view.index], _SMALL, iterations=_OCCLUSION_MARGIN),
                                                cv2.erode(cut, _SMALL))
                     for view, (cut, _) in zip(views, cuts)}
        scores, standing = _stands_out(views, plane, ratios, textures, tables, shades, changed, unlike, occluders,
                                       colour=round_ == _OCCLUSION_ROUNDS)
    return _background_cut(views, aim, scores, standing, clearly)


def _hue_shift(view: _View) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each coarse pixel's brightness and the empty workspace's (the channels summed, :data:`_CHROMA_OFFSET`
    added to each), and how far its chromaticity moved from the empty workspace's (the channels' shares'
    differences summed): a shadow darkens the table and keeps about its chromaticity."""
    assert view.background is not None
    image, empty = view.coarse + _CHROMA_OFFSET, view.background + _CHROMA_OFFSET
    brightness, ground = _brightness(image), _brightness(empty)
    return brightness, ground, np.abs(image / brightness[..., None] - empty / ground[..., None]).sum(axis=2)


def _unlike_a_shadow(view: _View, score: np.ndarray, change: np.ndarray) -> np.ndarray:
    """``change`` (the view's against the empty workspace, in units of its noise before the rounding) where it
    clearly changed (2.5 noises), darker than the empty workspace but unlike a shadow; 0 elsewhere.

    A shadow darkens the table (as :func:`_shadow_of_table` reads it, to no less than a tenth) and keeps about
    its chromaticity: within :data:`_LAMP_HUE_SHIFT` (a warm lamp's tint leaves it), or moved no more than
    :data:`_SHADOW_HUE_SPREAD` times the median move of the shadow the view confirms (``score``, its evidence
    on the first look: darker pixels that changed alike in another view at the same table point). On a green
    cutting mat under a tinted lamp that median is 0.04 to 0.1, and a shadow's pixels move up to 0.2; on the
    other tables the median is 0.01 to 0.03. A face that two views confirm for each other is the smaller part
    of what they confirm and leaves the median to the shadow: a dark teal top on a blue mat moves by 0.15 to
    0.19, its views' confirmed medians are 0.02 to 0.03. What is brighter than the table (a coloured object's
    glow on it, which every view sees alike) is left to the other views' likeness. The noise is the one before
    the rounding (:func:`_clearly_changed`): on a flat dark mat the rounded one reads nothing, and the mat's
    noise would stand out."""
    brightness, ground, hue = _hue_shift(view)
    darker = brightness < 0.97 * ground
    dimmed = darker & (brightness > 0.1 * ground)
    confirmed = dimmed & (score > 0) & (score < 1.0)
    tolerance = _LAMP_HUE_SHIFT
    if np.count_nonzero(confirmed) >= _SPECK:
        tolerance = max(tolerance, _SHADOW_HUE_SPREAD * float(np.median(hue[confirmed])))
    return np.where(darker & ~(dimmed & (hue < tolerance)) & (change > 2.5), change, 0.0).astype(np.float32)


#: A shadow's chromaticity moves at most this many times the median move of the shadow a view confirms.
_SHADOW_HUE_SPREAD = 3.0


def _clearly_changed(change: np.ndarray, beside_the_change: np.ndarray) -> np.ndarray:
    """(h, w) 0/255: where a view changed against the empty workspace beyond its noise as the pictures before
    their rounding give it (``change``, :func:`_background_cuts`', in units of that noise, :func:`_noise_level`),
    or where its grain or tint did (``beside_the_change``, in units of their noise).

    What changed at all is judged against :func:`_change_noise`, which on a flat, dark table reads the rounded
    pictures' steps and comes out 0 (over half the pixels unchanged): the floor then lies well under the
    table's noise, so that a dark can a little darker than its mat is found, and a fifth to a half of the
    table far from the object passes for changed too (so in 146 of the 480 rubber-mat views of seeds 0-39). Its
    clumps mostly fall apart or are told by the look through the plane, but where they pass it near the aim they
    joined the object within its convex outline and grew it over the table (34/rubber-mat-tin-tin: 0.490,
    0.289, 0.896). Read before the rounding, the noise does not collapse (0.13 there, over the far table's
    99th percentile, 0.11); a piece the table's noise could have made holds no pixel beyond it."""
    clear = np.maximum(change, beside_the_change) > 2.5
    return np.where(clear, 255, 0).astype(np.uint8)


#: The grain lost in this share or more is lost whole (JPEG and the sensor's noise take less on the table), and
#: counts as this evidence: the object's for sure (:data:`_SURE`).
_GRAIN_LOST_WHOLE = 0.9
_GRAIN_LOST_WHOLE_SCORE = 2 * _SURE
#: How many times the silhouettes cut from the evidence hide the table behind them for the next evidence.
_OCCLUSION_ROUNDS = 2
#: The graph cut's iterations in those rounds: their silhouettes, shrunk by a pixel, only say where the
#: table is hidden for the next evidence, which the last cut, with all its iterations, then draws from.
_OCCLUDER_ITERATIONS = 1


def _stands_out(views: Sequence[_View], plane: np.ndarray, ratios: dict[int, np.ndarray],
                textures: dict[int, np.ndarray], tables: dict[int, np.ndarray],
                shades: dict[int, np.ndarray], changed: dict[int, np.ndarray], unlike: dict[int, np.ndarray] | None,
                occluders: dict[int, np.ndarray] | None,
                colour: bool = False) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """Per view, the evidence that a changed pixel stands above the plane (in units of its noise) and
    where it does (0/255), the table behind ``occluders`` hidden. ``textures``, per view, how much of its
    grain is lost against the empty workspace's (in units of its noise): a grain lost stands out too;
    ``tables``, per view, where the table is seen in a shadow by the view itself (its grain kept);
    ``shades``, per view, where it has a shadow's look but its grain is too faint for a pixel's window to
    tell (such a shadow is told over a piece whole by the view's ``grain_sums``, :func:`_texture_change`);
    ``unlike``, per view, its change where it is unlike a shadow's (:func:`_unlike_a_shadow`), which no other
    view's likeness makes a shadow, or None;
    ``colour``, whether the colour against the other views' through the plane counts too where it clearly
    stands (:func:`_background_cuts` says when)."""
    scores, standing = {}, {}
    for view in views:
        others = [v for v in views if v is not view]
        evidence = _ratio_parallax(view, others, plane, ratios, occluders)
        unseen = (evidence < 0) & (changed[view.index] > 0)
        score = evidence / max(_noise_level(np.where(evidence < 0, np.nan, evidence)), _BACKGROUND_NOISE_FLOOR)
        # Where every other view has the table point behind the object, the pixel changed and nothing
        # says it is a shadow (the object's foot, or a face whose table points it covers).
        # But a shadow that keeps the empty workspace's grain is the table: the strip under a lying can,
        # which the can hides from every other view.
        # A grain too faint for a pixel's own window is told over each piece of such a shadow whole.
        hidden = np.isnan(score)
        assert view.grain_sums is not None
        table = tables[view.index] | _keeps_the_grain(hidden & shades[view.index], view.grain_sums,
                                                      _fine_per_coarse(view))
        score = np.where(hidden, np.where(table, 0.0, _HIDDEN), score)
        score = np.maximum(score, textures[view.index])
        if unlike is not None:
            # Two views that both lost a face in front of the same table points (a dark teal box's top, seen from
            # high up over a blue mat) see it change alike there, as a shadow would; but its colour changed,
            # which a shadow's does not. Only where another view sees the table point: a pixel hidden from
            # them all is asked by its grain and look above.
            score = np.where(hidden, score, np.maximum(score, unlike[view.index]))
        if occluders is not None:
            # The tint against the other views' through the plane, as without a background (_first_cut):
            # the table's glow beside a coloured object, and a shadow under a coloured lamp, are the same
            # from every view; a face as bright as the table is not. Once the objects in the other views
            # are known: before, the table beside this object's foot takes their object's tint.
            score = np.maximum(score, _tint_parallax(view, others, plane, [occluders[v.index] for v in others]))
        if colour:
            assert occluders is not None
            # A dark face (a box's side turned from the lamp, a can's lower body) changes against the empty
            # workspace as the shadow beside it does, and where another view sees that shadow at the face's
            # table point, the two change alike: a shadow, by the change. Its colour is still not the colour
            # of that table point, which is the plane's parallax the view has without a background. Only
            # where it stands out clearly: at an object's foot a pixel's misregistration of the other view's
            # silhouette shows its object's colour against the shadow there, a little above the noise.
            parallax = np.nan_to_num(_colour_parallax(view, others, plane, [occluders[v.index] for v in others]))
            score = np.maximum(score, np.where(parallax > _SURE, parallax, 0.0))
        score = np.where(changed[view.index] > 0, score, 0.0).astype(np.float32)
        stands = cv2.morphologyEx(np.where(score > 2.5, 255, 0).astype(np.uint8), cv2.MORPH_OPEN, _SMALL)
        # A table point no other view sees (the top of a tall object maps far behind it, out of their
        # pictures): what changed there stands out only as part of what stands out beside it.
        count, labels = cv2.connectedComponents(cv2.bitwise_or(stands, np.where(unseen, 255, 0).astype(np.uint8)),
                                                connectivity=8)
        joined = np.zeros(count, bool)
        joined[np.unique(labels[stands > 0])] = True
        joined[0] = False
        attached = unseen & joined[labels]
        scores[view.index] = np.where(unseen, np.where(attached, _HIDDEN, 0.0), score).astype(np.float32)
        standing[view.index] = cv2.bitwise_or(stands, np.where(attached, 255, 0).astype(np.uint8))
    return scores, standing


def _background_cut(views: Sequence[_View], aim: np.ndarray, scores: dict[int, np.ndarray],
                    standing: dict[int, np.ndarray], clearly: dict[int, np.ndarray],
                    iterations: int | None = None) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """Per view, the coarse silhouette cut around what stands out near the aim, and its evidence;
    ``clearly``, per view, where it changed beyond the table's noise (:func:`_clearly_changed`);
    ``iterations``, the graph cut's (default :data:`_GC_ITERATIONS`)."""
    cuts: list[tuple[np.ndarray, np.ndarray | None]] = []
    # Asked of a view only where its own is all hidden: once for all of them.
    open_shadow = functools.cache(functools.partial(_open_shadow, views, scores))
    for view in views:
        view.open_shadow = open_shadow
    for view in views:
        cw, ch = view.coarse_size
        centre = _coarse_aim(view, aim)
        differs, score = standing[view.index], scores[view.index]
        near = _components_near(cv2.morphologyEx(differs, cv2.MORPH_CLOSE, _CLOSING), centre,
                                reach=0.25 * np.hypot(cw, ch))
        # A piece joins only if the table's noise could not have made it; unless no piece is clear of it.
        clear_pieces = _regions_holding(near, clearly[view.index])
        if cv2.countNonZero(clear_pieces) >= _SPECK:
            near = clear_pieces
        if cv2.countNonZero(near) < _SPECK:
            raise SilhouetteError(_NOTHING, view=view.index)
        # A silhouette has no holes: a hole in what stands out is a face that looked like a shadow there.
        region = _holes_filled(_joined_within_outline(near))
        cut = _graph_cut(view, region, score, iterations=iterations, hidden_shadows=True)
        if cv2.countNonZero(cv2.bitwise_and(cut, near)) < _KEPT_BY_CUT * cv2.countNonZero(near):
            cut = _filled_region(cv2.morphologyEx(region, cv2.MORPH_CLOSE, _CLOSING), view)
        cuts.append((cut, score))
    return cuts


def _joined_within_outline(pieces: np.ndarray) -> np.ndarray:
    """The pieces (0/255) joined within their convex outline, each closed: the region a graph cut
    seeds from when what differs from the empty workspace comes in pieces (where an object's print or
    colour matches the table here and there)."""
    hull = cv2.convexHull(cv2.findNonZero(pieces))
    return cv2.bitwise_and(cv2.fillConvexPoly(np.zeros_like(pieces), hull, 255),
                           cv2.morphologyEx(pieces, cv2.MORPH_CLOSE, _CLOSING, iterations=3))


def _holes_filled(binary: np.ndarray) -> np.ndarray:
    """A 0/255 image with every hole (background not connected to the image's border) filled."""
    padded = cv2.copyMakeBorder(binary, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    outside = padded.copy()
    cv2.floodFill(outside, None, (0, 0), 255)
    return cv2.bitwise_or(binary, cv2.bitwise_not(outside)[1:-1, 1:-1])
