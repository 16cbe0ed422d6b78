"""Render what a wrist camera sees: red objects on a textured table.

The object is drawn by a small vectorised z-buffer rasteriser at twice the
image resolution (2x2 samples per pixel), which gives exact visibility and
anti-aliased edges; the background is ray-traced per pixel against the table
plane z = 0 and a floor below it, so the table's texture is fixed in the world
and consistent between views.

The projection here is the simulator's own (not core_cy's) on purpose: a
convention bug on one side then shows up in tests instead of cancelling out.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .objects import SimObject, vertex_normals

__all__ = ["TableScene", "project", "render"]

#: Object base colour, BGR, before shading: red for the HSV segmentation.
OBJECT_BGR = np.array([30.0, 30.0, 200.0])
#: Unit vector towards the (fixed, distant) light, world frame.
LIGHT_DIR = np.array([0.35, -0.45, 1.0]) / np.linalg.norm([0.35, -0.45, 1.0])
AMBIENT = 0.38  # keeps the darkest shaded red well above V = 40
_SS = 2  # samples per pixel along each axis
_NEAR = 1e-3  # metres; triangles closer to the camera are dropped
_CHUNK = 2_000_000  # candidate samples per rasterisation pass


def _pose(T_world_cam: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    T = np.asarray(T_world_cam, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"T_world_cam must be 4x4, got shape {T.shape}")
    return T[:3, :3], T[:3, 3]


def project(
    points_world: ArrayLike, T_world_cam: ArrayLike, K: ArrayLike, dist: ArrayLike | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Project world points into the image.

    Parameters
    ----------
    points_world : (N, 3) array_like of float
    T_world_cam : (4, 4) array_like, camera-to-world, OpenCV camera axes.
    K : (3, 3) array_like, pinhole matrix.
    dist : (k,) array_like or None, OpenCV distortion coefficients.

    Returns
    -------
    uv : (N, 2) ndarray of float64, pixel coordinates (pixel centres are integers).
    z : (N,) ndarray of float64, depth along the optical axis.

    Examples
    --------
    >>> K = [[600, 0, 319.5], [0, 600, 239.5], [0, 0, 1]]
    >>> project([[0.0, 0.0, 2.0]], np.eye(4), K)[0].tolist()
    [[319.5, 239.5]]
    """
    R, t = _pose(T_world_cam)
    Xc = (np.asarray(points_world, dtype=np.float64).reshape(-1, 3) - t) @ R  # R^T (X - t)
    z = Xc[:, 2]
    K = np.asarray(K, dtype=np.float64)
    if dist is None or len(Xc) == 0:
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = Xc[:, :2] / z[:, None]
        uv = xy @ K[:2, :2].T + K[:2, 2]
    else:
        uv, _ = cv2.projectPoints(Xc.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, np.asarray(dist, float))
        uv = uv.reshape(-1, 2)
    return uv, z


@lru_cache(maxsize=8)
def _normalised_grid(
    K: tuple[float, ...], dist: tuple[float, ...] | None, w: int, h: int
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Normalised camera coordinates x, y (H*W,) of every pixel centre, undistorted.

    Cached: undistorting 300k points costs more than the rest of the background.
    """
    Km = np.array(K).reshape(3, 3)
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    uv = np.stack([u.ravel(), v.ravel()], 1)
    if dist is None:
        xy = (uv - Km[:2, 2]) / [Km[0, 0], Km[1, 1]]
    else:
        xy = cv2.undistortPoints(uv.reshape(-1, 1, 2), Km, np.array(dist)).reshape(-1, 2)
    x, y = (np.ascontiguousarray(c, dtype=np.float32) for c in xy.T)
    x.flags.writeable = y.flags.writeable = False
    return x, y


@dataclass(frozen=True)
class TableScene:
    """The procedural surroundings: a table top at z = 0 over a floor.

    Colours are kept out of the red HSV range: the wood is pale (low
    saturation), the fabric is blue-green, so only the object is red.
    """

    kind: str = "wood"  # "wood" or "fabric"
    hue: float = 20.0  # OpenCV hue, 0-179
    saturation: float = 0.2
    value: float = 0.75
    grain_angle: float = 0.3  # radians, direction of the wood grain / weave
    phase: float = 0.0
    extent: tuple[float, float, float, float] = (-0.2, 1.4, -0.8, 0.8)  # x0, x1, y0, y1
    floor_z: float = -0.75

    @classmethod
    def from_seed(cls, seed: int) -> TableScene:
        """A table whose look varies with ``seed``."""
        rng = np.random.default_rng([seed, 7919])
        common = dict(grain_angle=rng.uniform(0, np.pi), phase=rng.uniform(0, 100))
        if rng.random() < 0.5:
            return cls("wood", rng.uniform(16, 26), rng.uniform(0.12, 0.25), rng.uniform(0.65, 0.85), **common)
        return cls("fabric", rng.uniform(85, 125), rng.uniform(0.2, 0.45), rng.uniform(0.45, 0.7), **common)

    def _base_bgr(self) -> NDArray[np.float64]:
        hsv = np.uint8([[[round(self.hue), round(self.saturation * 255), round(self.value * 255)]]])
        return cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0].astype(np.float64)

    def table_colour(
        self, xy: NDArray[np.float64], footprint: NDArray[np.float64] | None = None
    ) -> NDArray[np.float32]:
        """BGR float32 colours (N, 3) of table points (N, 2).

        ``footprint`` (N,), the size of a pixel on the table in metres, fades
        out the fine pattern where it would alias into moire (a poor man's mipmap).
        """
        # float32: sin() of large arguments is an order of magnitude faster.
        xy = xy.astype(np.float32)
        fade = 1.0 if footprint is None else 1.0 / (1.0 + (footprint.astype(np.float32) / 0.002) ** 2)
        c, s = np.float32(np.cos(self.grain_angle)), np.float32(np.sin(self.grain_angle))
        along, across = xy[:, 0] * c + xy[:, 1] * s, xy[:, 1] * c - xy[:, 0] * s
        if self.kind == "wood":
            # Grain lines 8 mm apart, warped, over broad darker bands.
            warp = 0.006 * np.sin(along / 0.09 + self.phase) + 0.003 * np.sin(along / 0.023 + 2 * self.phase)
            g = np.sin((across + warp) * (2 * np.pi / 0.008) + self.phase)
            g2 = g * g  # not g**4: float32 pow is slow
            shade = 1.0 - 0.10 * fade * g2 * g2 - 0.05 * np.sin(across / 0.05 + self.phase)
        else:
            # A coarse weave (1.2 cm) with a soft mottle.
            w = np.sin(along * (2 * np.pi / 0.012)) * np.sin(across * (2 * np.pi / 0.012))
            shade = 1.0 + 0.06 * fade * w + 0.05 * np.sin(along / 0.04 + self.phase) * np.cos(across / 0.05)
        # A gentle light fall-off across the table.
        shade = shade * (1.0 - 0.15 * np.minimum(np.hypot(xy[:, 0] - 0.5, xy[:, 1] + 0.3), 1.5))
        return self._base_bgr().astype(np.float32) * shade[:, None]

    def background(
        self, T_world_cam: ArrayLike, K: ArrayLike, dist: ArrayLike | None, image_size: tuple[int, int]
    ) -> NDArray[np.float32]:
        """(H, W, 3) float32 BGR image of the surroundings alone, ray-traced per pixel."""
        w, h = image_size
        R, t = _pose(T_world_cam)
        K = np.asarray(K, dtype=np.float64)
        key = None if dist is None else tuple(np.asarray(dist, dtype=np.float64).ravel())
        x, y = _normalised_grid(tuple(K.ravel()), key, w, h)
        # World ray directions, one float32 array per axis (cheaper than (N, 3) slices).
        dx, dy, dz = (np.float32(r[0]) * x + np.float32(r[1]) * y + np.float32(r[2]) for r in R)
        out = np.empty((len(x), 3), dtype=np.float32)
        out[:] = [40.0, 42.0, 45.0]  # above the horizon: a dim wall
        down = dz < -1e-6
        s_table = np.float32(-t[2]) / np.where(down, dz, np.float32(-1.0))
        px, py = np.float32(t[0]) + s_table * dx, np.float32(t[1]) + s_table * dy
        x0, x1, y0, y1 = self.extent
        on_table = down & (t[2] > 0) & (px >= x0) & (px <= x1) & (py >= y0) & (py <= y1)
        # A pixel's footprint on the plane: range / f / cos(incidence).
        dxt, dyt, dzt = dx[on_table], dy[on_table], dz[on_table]
        footprint = s_table[on_table] * (dxt * dxt + dyt * dyt + dzt * dzt) / (np.float32(K[0, 0]) * -dzt)
        out[on_table] = self.table_colour(np.column_stack([px[on_table], py[on_table]]), footprint)
        floor = down & ~on_table
        s_floor = np.float32(self.floor_z - t[2]) / dz[floor]
        tiles = (np.floor((t[0] + s_floor * dx[floor]) / 0.3) + np.floor((t[1] + s_floor * dy[floor]) / 0.3)) % 2
        out[floor] = np.array([70.0, 72.0, 75.0], dtype=np.float32) * (0.85 + 0.1 * tiles)[:, None]
        return out.reshape(h, w, 3)


def _rasterise(
    uv: NDArray[np.float64], z: NDArray[np.float64], faces: NDArray[np.int32], shape: tuple[int, int]
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Z-buffer: nearest face per sample and its screen-space barycentrics.

    ``uv`` (V, 2) are in sample units (sample centres on integers), ``z`` (V,)
    depths, ``faces`` (F, 3), ``shape`` (rows, cols). Returns the face index per
    sample (rows*cols,) with -1 for none, and barycentrics l1, l2 per sample.
    """
    rows, cols = shape
    face_id = np.full(rows * cols, -1, dtype=np.int64)
    l1_buf, l2_buf = np.zeros(rows * cols), np.zeros(rows * cols)
    zbuf = np.full(rows * cols, -np.inf)  # holds 1/z: the larger, the nearer
    p = uv[faces]  # (F, 3, 2)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    lo = np.maximum(np.ceil(p.min(axis=1)), 0).astype(np.int64)
    hi = np.minimum(np.floor(p.max(axis=1)), [cols - 1, rows - 1]).astype(np.int64)
    nx, ny = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
    keep = np.flatnonzero((nx > 0) & (ny > 0) & (np.abs(det) > 1e-12))
    inv_z = 1.0 / z[faces]
    count = nx[keep] * ny[keep]
    cum = np.cumsum(count)
    start = 0
    while start < len(keep):  # chunks of faces bound the candidate arrays' memory
        done = cum[start - 1] if start else 0
        stop = max(start + 1, int(np.searchsorted(cum, done + _CHUNK, side="right")))
        f, n = keep[start:stop], count[start:stop]
        start = stop
        fi = np.repeat(f, n)
        k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        x = lo[fi, 0] + k % nx[fi]
        y = lo[fi, 1] + k // nx[fi]
        dx, dy = x - p[fi, 0, 0], y - p[fi, 0, 1]
        l1 = (e2[fi, 1] * dx - e2[fi, 0] * dy) / det[fi]
        l2 = (e1[fi, 0] * dy - e1[fi, 1] * dx) / det[fi]
        ok = (l1 >= -1e-9) & (l2 >= -1e-9) & (l1 + l2 <= 1 + 1e-9)
        fi, l1, l2 = fi[ok], l1[ok], l2[ok]
        pix = y[ok] * cols + x[ok]
        iz = (1 - l1 - l2) * inv_z[fi, 0] + l1 * inv_z[fi, 1] + l2 * inv_z[fi, 2]
        np.maximum.at(zbuf, pix, iz)
        win = iz >= zbuf[pix]
        face_id[pix[win]], l1_buf[pix[win]], l2_buf[pix[win]] = fi[win], l1[win], l2[win]
    return face_id, l1_buf, l2_buf


def _merge_meshes(
    objs: Sequence[SimObject],
) -> tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.float64]]:
    """All objects' meshes as one: vertices (V, 3), faces (F, 3), vertex normals (V, 3)."""
    meshes = [o.mesh() for o in objs] or [(np.zeros((0, 3)), np.zeros((0, 3), np.int32))]
    offsets = np.cumsum([0] + [len(v) for v, _ in meshes])
    verts = np.vstack([v for v, _ in meshes])
    faces = np.vstack([f + o for (_, f), o in zip(meshes, offsets)]).astype(np.int32)
    normals = np.vstack([vertex_normals(v, f) for v, f in meshes])
    return verts, faces, normals


def render(
    objects: SimObject | Sequence[SimObject],
    T_world_cam: ArrayLike,
    K: ArrayLike,
    dist: ArrayLike | None = None,
    image_size: tuple[int, int] = (640, 480),
    rng: np.random.Generator | None = None,
    noise_sigma: float = 2.0,
    *,
    table: TableScene | None = None,
    ambient: float = AMBIENT,
) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """Render red ``objects`` on a table as seen from ``T_world_cam``.

    Parameters
    ----------
    objects : SimObject or sequence of SimObject
    T_world_cam : (4, 4) array_like, camera-to-world, OpenCV camera axes.
    K : (3, 3) array_like; dist : OpenCV distortion coefficients or None.
    image_size : (width, height) in pixels.
    rng : generator for the sensor noise; None means ``default_rng(0)``.
    noise_sigma : standard deviation of the Gaussian sensor noise (grey levels).
    table : the surroundings; None means ``TableScene()``.
    ambient : share of the light a face turned away from the lamp still gets, in [0, 1]:
        the lower, the darker the shaded side (0.15 puts it at V = 30).

    Returns
    -------
    bgr : (H, W, 3) ndarray of uint8
    mask : (H, W) ndarray of uint8, 255 where at least half the pixel is object.
    """
    objs = [objects] if isinstance(objects, SimObject) else list(objects)
    w, h = image_size
    rng = np.random.default_rng(0) if rng is None else rng
    table = TableScene() if table is None else table
    R, t = _pose(T_world_cam)
    image = table.background(T_world_cam, K, dist, image_size)

    verts, faces, normals = _merge_meshes(objs)
    tv = verts[faces]
    face_n = np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0])
    front = np.einsum("ij,ij->i", face_n, tv[:, 0] - t) < 0  # back faces never show on closed meshes
    uv, z = project(verts, T_world_cam, K, dist)
    front &= (z[faces] > _NEAR).all(axis=1)
    faces = faces[front]

    rows, cols = h * _SS, w * _SS
    # Sample (i, j) of the fine grid sits at pixel coordinate (i + 0.5) / SS - 0.5.
    face_id, l1, l2 = _rasterise(uv * _SS + (_SS - 1) / 2, z, faces, (rows, cols))
    hit = np.flatnonzero(face_id >= 0)
    fv = faces[face_id[hit]]
    # Perspective-correct weights: screen-space barycentrics divided by depth.
    wts = np.column_stack([1 - l1[hit] - l2[hit], l1[hit], l2[hit]]) / z[fv]
    wts /= wts.sum(axis=1, keepdims=True)
    n = sum(wts[:, k, None] * normals[fv[:, k]] for k in range(3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    p = sum(wts[:, k, None] * verts[fv[:, k]] for k in range(3))
    lambert = ambient + (1 - ambient) * np.clip(n @ LIGHT_DIR, 0, 1)
    # A faint mottle so the object is not a flat plastic colour.
    mottle = 1.0 + 0.03 * np.sin(p @ [157.0, 91.0, 211.0]) * np.sin(p @ [-83.0, 139.0, 67.0])
    # Box-filter the samples down to pixels: sums per pixel by bincount.
    r_, c_ = np.divmod(hit, cols)
    pix = (r_ // _SS) * w + c_ // _SS
    colour = OBJECT_BGR * (lambert * mottle)[:, None]
    obj_sum = np.column_stack([np.bincount(pix, colour[:, k], h * w) for k in range(3)]) / _SS**2
    coverage = (np.bincount(pix, minlength=h * w) / _SS**2).astype(np.float32)
    image = (obj_sum.astype(np.float32) + (1 - coverage)[:, None] * image.reshape(-1, 3)).reshape(h, w, 3)
    coverage = coverage.reshape(h, w)

    # Optics and sensor: slight blur, vignetting, noise.
    image = cv2.GaussianBlur(image, (0, 0), 0.5)
    yy, xx = np.mgrid[0:h, 0:w]
    r2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    image *= (1.0 - 0.15 * r2).astype(np.float32)[..., None]
    image += noise_sigma * rng.standard_normal(image.shape, dtype=np.float32)
    bgr = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    mask = np.where(coverage >= 0.5, 255, 0).astype(np.uint8)
    return bgr, mask
