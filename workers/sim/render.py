"""Render what a wrist camera sees: objects on a textured table, under a lamp.

The object is drawn by a small vectorised z-buffer rasteriser at four times
the image resolution (4x4 samples per pixel, in the object's box only): its
coverage of a pixel is area-true to a sixteenth, and the true mask is that
coverage thresholded at one half. The background is ray-traced per pixel
against the table plane z = 0 and a floor below it, so the table's texture is
fixed in the world and consistent between views.

Without a :class:`Light` the scene is lit as it always was: red objects
(:data:`OBJECT_BGR`) shaded by :data:`LIGHT_DIR`, an unlit table, no shadow.
With one, every object's colour is its albedo (a
:class:`~workers.sim.textures.PrintedObject`'s print, else red), lit by one
directional light with an ambient share and a specular highlight, and the
objects cast a shadow on the table and on each other: a shadow map from the
light's view, drawn by the same rasteriser, answers for each table point and
each object sample whether the way to the light is blocked, with a soft edge
as wide as the lamp's angular size makes it.

The projection here is the simulator's own (not core_cy's) on purpose: a
convention bug on one side then shows up in tests instead of cancelling out.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Sequence

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .objects import SimObject, vertex_normals
from .textures import TABLE_KINDS, PrintedObject, table_pattern

__all__ = ["Layers", "Light", "TableScene", "project", "remembered", "render", "render_layers"]

#: Object base colour, BGR, before shading: red for the HSV segmentation.
OBJECT_BGR = np.array([30.0, 30.0, 200.0])
#: Unit vector towards the (fixed, distant) light, world frame.
LIGHT_DIR = np.array([0.35, -0.45, 1.0]) / np.linalg.norm([0.35, -0.45, 1.0])
AMBIENT = 0.38  # keeps the darkest shaded red well above V = 40
_SS = 4  # samples per pixel along each axis
_NEAR = 1e-3  # metres; triangles closer to the camera are dropped
_CHUNK = 2_000_000  # candidate samples per rasterisation pass
_SHADOW_TEXEL = 0.0005  # metres: the shadow map's resolution
_SHADOW_MAX_TEXELS = 2048  # along each side; a larger scene gets coarser texels
_SOFT_REACH = 30  # texels a soft shadow lookup reaches: blocker search (12) + widest penumbra (16) + bilinear


@dataclass(frozen=True)
class Light:
    """One distant lamp: ``direction`` towards it (world, normalised here), its ``strength``,
    the ``ambient`` light every surface gets, and its angular radius (the soft shadow edge).

    A surface turned by angle ``a`` from the lamp, not in shadow, receives
    ``ambient + strength * cos(a) * colour``; in shadow, ``ambient``.
    """

    direction: tuple[float, float, float] = (0.35, -0.45, 1.0)
    strength: float = 0.7
    ambient: float = 0.3
    angular_radius_deg: float = 1.5
    colour: tuple[float, float, float] = (1.0, 1.0, 1.0)  # BGR tint of the lamp (the ambient light is white)

    def __post_init__(self) -> None:
        d = np.asarray(self.direction, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(d)) or d[2] <= 0.05 * np.linalg.norm(d):
            raise ValueError(f"the light must shine from above the table, got direction {list(self.direction)}")
        object.__setattr__(self, "direction", tuple(float(x) for x in d / np.linalg.norm(d)))
        if self.strength < 0 or not 0 <= self.ambient <= 1:
            raise ValueError(f"need strength >= 0 and 0 <= ambient <= 1, got {self.strength}, {self.ambient}")

    @classmethod
    def from_angles(cls, azimuth_deg: float, elevation_deg: float, strength: float = 0.7,
                    ambient: float = 0.3, colour: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> Light:
        """A lamp at ``azimuth_deg`` (from +x towards +y) and ``elevation_deg`` above the table."""
        az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
        return cls((float(np.cos(el) * np.cos(az)), float(np.cos(el) * np.sin(az)), float(np.sin(el))),
                   strength, ambient, colour=colour)

    @property
    def L(self) -> NDArray[np.float64]:
        return np.asarray(self.direction, dtype=np.float64)


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

    ``wood`` and ``fabric`` (:meth:`from_seed`) keep out of the red HSV range: the
    wood is pale (low saturation), the fabric is blue-green, so only a red object is
    red. The kinds of :data:`workers.sim.textures.TABLE_KINDS` (:meth:`of_kind`) look
    like real tables and care for no segmentation: a light oak of boards with growth
    rings and seams, a dark rubber mat, white laminate, a green cutting mat with its grid.
    """

    kind: str = "wood"  # "wood", "fabric" or one of TABLE_KINDS
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

    @classmethod
    def of_kind(cls, kind: str, seed: int) -> TableScene:
        """A table of ``kind`` (wood, fabric or one of TABLE_KINDS) whose look varies with ``seed``.

        Raises
        ------
        ValueError
            If the kind is unknown.
        """
        rng = np.random.default_rng([seed, 7921])
        common = dict(grain_angle=float(rng.uniform(0, np.pi)), phase=float(rng.uniform(0, 100)))
        hsv = {  # OpenCV hue 0-179, saturation and value 0-1
            "wood": (rng.uniform(16, 26), rng.uniform(0.12, 0.25), rng.uniform(0.65, 0.85)),
            "fabric": (rng.uniform(85, 125), rng.uniform(0.2, 0.45), rng.uniform(0.45, 0.7)),
            "oak": (rng.uniform(13, 19), rng.uniform(0.35, 0.5), rng.uniform(0.72, 0.85)),
            "rubber-mat": (rng.uniform(90, 120), rng.uniform(0.03, 0.1), rng.uniform(0.12, 0.2)),
            "laminate": (rng.uniform(10, 30), rng.uniform(0.02, 0.05), rng.uniform(0.9, 0.96)),
            "cutting-mat": (rng.uniform(55, 75), rng.uniform(0.55, 0.75), rng.uniform(0.4, 0.55)),
        }
        if kind not in hsv:
            raise ValueError(f"unknown table kind {kind!r}; known: {', '.join(hsv)}")
        h, s, v = hsv[kind]
        return cls(kind, float(h), float(s), float(v), **common)

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
        if self.kind in TABLE_KINDS:
            fp = np.full(len(xy), 1e-4, np.float32) if footprint is None else footprint.astype(np.float32)
            colour = table_pattern(self.kind, self._base_bgr(), xy, fp, self.grain_angle, self.phase)
            fall = 1.0 - 0.15 * np.minimum(np.hypot(xy[:, 0] - 0.5, xy[:, 1] + 0.3), 1.5)
            return (colour * fall[:, None]).astype(np.float32)
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
        """(H, W, 3) float32 BGR image of the surroundings alone, unlit, ray-traced per pixel."""
        w, h = image_size
        return self.trace(T_world_cam, K, dist, image_size)[0].reshape(h, w, 3)

    def trace(
        self, T_world_cam: ArrayLike, K: ArrayLike, dist: ArrayLike | None, image_size: tuple[int, int]
    ) -> tuple[NDArray[np.float32], NDArray[np.bool_], NDArray[np.float32]]:
        """Every pixel's ray against the table and the floor.

        Returns the colours (H*W, 3) float32, which pixels see the table (H*W,) bool,
        and where their rays meet it, (n_table, 2) float32 world x, y.
        """
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
        table_xy = np.column_stack([px[on_table], py[on_table]])
        out[on_table] = self.table_colour(table_xy, footprint)
        floor = down & ~on_table
        s_floor = np.float32(self.floor_z - t[2]) / dz[floor]
        tiles = (np.floor((t[0] + s_floor * dx[floor]) / 0.3) + np.floor((t[1] + s_floor * dy[floor]) / 0.3)) % 2
        out[floor] = np.array([70.0, 72.0, 75.0], dtype=np.float32) * (0.85 + 0.1 * tiles)[:, None]
        return out, on_table, table_xy


@dataclass(frozen=True)
class _RememberedTable(TableScene):
    """The table, whose trace from each of the last few camera poses is kept (read-only): poses repeat
    (a view and its background, a cell's planned views and its snapshots tried again), and the table's
    texture is much of a printed scene's cost."""

    def trace(self, T_world_cam: ArrayLike, K: ArrayLike, dist: ArrayLike | None,
              image_size: tuple[int, int]) -> tuple[NDArray[np.float32], NDArray[np.bool_], NDArray[np.float32]]:
        T = np.ascontiguousarray(T_world_cam, dtype=np.float64)
        K = np.ascontiguousarray(K, dtype=np.float64)
        coefficients = None if dist is None else np.ascontiguousarray(dist, dtype=np.float64).tobytes()
        return _traced(self, T.tobytes(), K.tobytes(), coefficients, (int(image_size[0]), int(image_size[1])))


@lru_cache(maxsize=6)   # about 6 MB each at 640x480
def _traced(table: _RememberedTable, T: bytes, K: bytes, dist: bytes | None,
            image_size: tuple[int, int]) -> tuple[NDArray[np.float32], NDArray[np.bool_], NDArray[np.float32]]:
    traced = TableScene.trace(table, np.frombuffer(T).reshape(4, 4), np.frombuffer(K).reshape(3, 3),
                              None if dist is None else np.frombuffer(dist), image_size)
    for array in traced:
        array.flags.writeable = False
    return traced


def remembered(table: TableScene) -> TableScene:
    """``table`` as it is, its trace from each of the last few camera poses kept: the same pictures."""
    return _RememberedTable(**{f.name: getattr(table, f.name) for f in fields(table)})


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
) -> tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.float64], NDArray[np.int64]]:
    """All objects' meshes as one: vertices (V, 3), faces (F, 3), vertex normals (V, 3), and the
    index of the object each face belongs to (F,)."""
    meshes = [o.mesh() for o in objs] or [(np.zeros((0, 3)), np.zeros((0, 3), np.int32))]
    offsets = np.cumsum([0] + [len(v) for v, _ in meshes])
    verts = np.vstack([v for v, _ in meshes])
    faces = np.vstack([f + o for (_, f), o in zip(meshes, offsets)]).astype(np.int32)
    normals = np.vstack([vertex_normals(v, f) for v, f in meshes])
    owner = np.concatenate([np.full(len(f), k, np.int64) for k, (_, f) in enumerate(meshes)])
    return verts, faces, normals, owner


class _ShadowMap:
    """What the light sees: the nearness to the light (``p . L``) of the first surface along each
    light ray, on a grid across the light's direction, drawn with the renderer's own rasteriser."""

    def __init__(self, verts: NDArray[np.float64], faces: NDArray[np.int32], light: Light,
                 texel: float = _SHADOW_TEXEL) -> None:
        L = light.L
        e1 = np.cross(L, [0.0, 0.0, 1.0] if abs(L[2]) < 0.9 else [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        self.basis = np.stack([e1, np.cross(L, e1)])  # (2, 3) across the light
        self.L = L
        self.tan_radius = float(np.tan(np.radians(light.angular_radius_deg)))
        self.empty = len(faces) == 0
        if self.empty:
            return
        s = verts @ self.basis.T
        extent = float((s.max(0) - s.min(0)).max())
        self.texel = max(texel, extent / (_SHADOW_MAX_TEXELS - 16))
        self.origin = s.min(0) - 8 * self.texel
        cols, rows = (np.ceil((s.max(0) - self.origin) / self.texel) + 8).astype(int)
        near = verts @ L
        self.near_min = float(near.min())
        # The rasteriser keeps the largest interpolated 1/z: give it the nearness (plus one, to stay
        # positive) as 1/z, which an orthographic view interpolates linearly.
        face_id, l1, l2 = _rasterise((s - self.origin) / self.texel, 1.0 / (near - self.near_min + 1.0), faces,
                                     (rows, cols))
        hit = face_id >= 0
        f = faces[face_id[hit]]
        depth = np.full(rows * cols, -np.inf)
        depth[hit] = (1 - l1[hit] - l2[hit]) * near[f[:, 0]] + l1[hit] * near[f[:, 1]] + l2[hit] * near[f[:, 2]]
        self.depth = depth.reshape(rows, cols)
        # The nearest blocker anywhere a soft lookup reaches (the blocker search, the widest penumbra):
        # a point farther from the light than that is lit, and is not looked up tap by tap.
        finite = np.where(np.isfinite(self.depth), self.depth, -1e9).astype(np.float32)
        self.reach = cv2.dilate(finite, np.ones((2 * _SOFT_REACH + 1, 2 * _SOFT_REACH + 1), np.uint8))

    def _lookup(self, c: NDArray[np.float64], near: NDArray[np.float64], bias: NDArray[np.float64],
                ) -> NDArray[np.float64]:
        """Bilinear share of the light blocked at grid coordinates c (N, 2) for points of nearness ``near``."""
        rows, cols = self.depth.shape
        c0 = np.floor(c).astype(np.int64)
        f = c - c0
        blocked = np.zeros(len(c))
        for du, dv in ((0, 0), (1, 0), (0, 1), (1, 1)):
            u, v = c0[:, 0] + du, c0[:, 1] + dv
            ok = (u >= 0) & (u < cols) & (v >= 0) & (v < rows)
            d = np.full(len(c), -np.inf)
            d[ok] = self.depth[v[ok], u[ok]]
            wgt = (f[:, 0] if du else 1 - f[:, 0]) * (f[:, 1] if dv else 1 - f[:, 1])
            blocked += wgt * (d > near + bias)
        return blocked

    def shadow(self, points: NDArray[np.float64], bias: NDArray[np.float64] | float,
               soft: bool = True) -> NDArray[np.float64]:
        """Share of the lamp hidden from each world point (N, 3), in [0, 1] (0: fully lit).

        ``bias`` (metres of nearness) keeps a surface from shadowing itself. With ``soft`` the edge
        is as soft as the lamp's angular radius times the distance to the blocker makes it, sampled on
        a ring of eight taps; without, one bilinear lookup.
        """
        out = np.zeros(len(points))
        if self.empty or len(points) == 0:
            return out
        c = (points @ self.basis.T - self.origin) / self.texel
        rows, cols = self.depth.shape
        near = points @ self.L
        bias = np.broadcast_to(np.asarray(bias, dtype=np.float64), near.shape)
        inside = (c[:, 0] > -24) & (c[:, 0] < cols + 24) & (c[:, 1] > -24) & (c[:, 1] < rows + 24)
        idx = np.flatnonzero(inside)
        u = np.clip(np.rint(c[idx, 0]).astype(np.int64), 0, cols - 1)
        v = np.clip(np.rint(c[idx, 1]).astype(np.int64), 0, rows - 1)
        idx = idx[self.reach[v, u] > near[idx] + bias[idx]]  # the others are surely lit
        c, near, bias = c[idx], near[idx], bias[idx]
        if not soft:
            out[idx] = self._lookup(c, near, bias)
            return out
        ring = [(np.cos(a), np.sin(a)) for a in np.linspace(0, 2 * np.pi, 8, endpoint=False)]
        # The nearest blocker round the point sets how wide the penumbra is.
        blocker = np.full(len(c), -np.inf)
        for cu, cv in [(0.0, 0.0), *ring]:
            u = np.clip(np.rint(c[:, 0] + 12 * cu).astype(np.int64), 0, cols - 1)
            v = np.clip(np.rint(c[:, 1] + 12 * cv).astype(np.int64), 0, rows - 1)
            blocker = np.maximum(blocker, self.depth[v, u])
        gap = np.where(np.isfinite(blocker), np.maximum(blocker - near, 0.0), 0.0)
        radius = np.clip(gap * self.tan_radius / self.texel, 0.5, 16.0)
        total = self._lookup(c, near, bias)
        for cu, cv in ring:
            total += self._lookup(c + radius[:, None] * [cu, cv], near, bias)
        out[idx] = total / 9.0
        return out


class _Footprint:
    """How far each table point is from the objects' footprint (seen from straight above), for the
    dimmer ambient light round their feet: the objects hide part of the sky from the table there."""

    def __init__(self, verts: NDArray[np.float64], faces: NDArray[np.int32]) -> None:
        self.above = _ShadowMap(verts, faces, Light((0.0, 0.0, 1.0), angular_radius_deg=0.0), texel=0.001)
        if not self.above.empty:
            low = self.above.depth > -np.inf
            # Distances (texels) from every texel to the nearest one under an object.
            self.distance = cv2.distanceTransform((~low).astype(np.uint8), cv2.DIST_L2, 5)

    def occlusion(self, points: NDArray[np.float64], reach: float = 0.006) -> NDArray[np.float32]:
        """Share of the ambient light reaching table points (N, 3): a dark rim fading within ``reach`` metres."""
        out = np.ones(len(points), dtype=np.float32)
        if self.above.empty or len(points) == 0:
            return out
        above = self.above
        c = np.rint((points @ above.basis.T - above.origin) / above.texel).astype(np.int64)
        rows, cols = self.distance.shape
        inside = (c[:, 0] >= 0) & (c[:, 0] < cols) & (c[:, 1] >= 0) & (c[:, 1] < rows)
        d = self.distance[c[inside, 1], c[inside, 0]] * above.texel
        out[inside] = np.where(d < 6 * reach, 1.0 - 0.6 * np.exp(-d / reach), 1.0)
        return out


@lru_cache(maxsize=4)
def _light_maps_cached(key: tuple, light: Light) -> tuple[_ShadowMap, _Footprint]:
    verts, faces = _MESHES.pop(key)
    return _ShadowMap(verts, faces, light), _Footprint(verts, faces)


_MESHES: dict[tuple, tuple[NDArray[np.float64], NDArray[np.int32]]] = {}


def _light_maps(verts: NDArray[np.float64], faces: NDArray[np.int32], light: Light) -> tuple[_ShadowMap, _Footprint]:
    """The shadow map and the footprint of a scene under a light. They depend on neither the camera nor
    the pixels, so the views of one scene share them: kept for the last few scenes, by their meshes' bytes."""
    key = (verts.tobytes(), faces.tobytes())
    _MESHES[key] = (verts, faces)
    try:
        return _light_maps_cached(key, light)
    finally:
        _MESHES.pop(key, None)


@dataclass(frozen=True)
class Layers:
    """What :func:`render_layers` draws, before the optics and the sensor.

    ``image`` (H, W, 3) float32 BGR, 0-255 scale; ``coverage`` (H, W) float32, the share of each
    pixel the objects cover (area-true to 1/16); ``shadow`` (H, W) float32, the share of the light
    the objects take from the table point a pixel sees: their cast shadow, and the dimmer ambient
    light round their feet (0 without a light, and off the table); ``albedo``
    (H, W, 3) float32 in [0, 1], the mean albedo of the objects' part of each pixel (0 where none).
    """

    image: NDArray[np.float32]
    coverage: NDArray[np.float32]
    shadow: NDArray[np.float32]
    albedo: NDArray[np.float32]


def render_layers(
    objects: SimObject | Sequence[SimObject],
    T_world_cam: ArrayLike,
    K: ArrayLike,
    dist: ArrayLike | None = None,
    image_size: tuple[int, int] = (640, 480),
    *,
    table: TableScene | None = None,
    ambient: float = AMBIENT,
    light: Light | None = None,
) -> Layers:
    """The scene's picture and its layers, before blur and noise (see :func:`render`)."""
    objs = [objects] if isinstance(objects, SimObject) else list(objects)
    w, h = image_size
    table = TableScene() if table is None else table
    R, t = _pose(T_world_cam)
    background, on_table, table_xy = table.trace(T_world_cam, K, dist, image_size)

    verts, faces, normals, owner = _merge_meshes(objs)
    shadow_map, footprint = (None, None) if light is None else _light_maps(verts, faces, light)
    table_shadow = np.zeros(h * w, dtype=np.float32)
    if light is not None and shadow_map is not None and footprint is not None:
        L = light.L
        tint = np.asarray(light.colour, dtype=np.float32)
        # Only table points near the objects or their shadows can be darkened: the box of the
        # objects' feet and of their outline cast along the light onto the table, with a margin
        # for the soft edge and the dark rim.
        hidden, occlusion = np.zeros(h * w, dtype=np.float32), np.ones(h * w, dtype=np.float32)
        table_index = np.flatnonzero(on_table)
        if len(verts) and len(table_xy):
            cast_xy = verts[:, :2] - verts[:, 2:3] * (L[:2] / L[2])
            reach = np.vstack([verts[:, :2], cast_xy])
            lo, hi = reach.min(axis=0) - 0.04, reach.max(axis=0) + 0.04
            near = np.flatnonzero((table_xy[:, 0] >= lo[0]) & (table_xy[:, 0] <= hi[0])
                                  & (table_xy[:, 1] >= lo[1]) & (table_xy[:, 1] <= hi[1]))
            points = np.column_stack([table_xy[near].astype(np.float64), np.zeros(len(near))])
            grazing = np.sqrt(max(1 - L[2] ** 2, 0.0)) / L[2]
            hidden[table_index[near]] = shadow_map.shadow(points, 1.5 * _SHADOW_TEXEL * (1 + grazing))
            occlusion[table_index[near]] = footprint.occlusion(points)
        full = light.ambient + light.strength * L[2] * float(tint.mean())
        received = light.ambient * occlusion + light.strength * L[2] * (1 - hidden) * float(tint.mean())
        # The shadow layer: the share of the light the objects take from the table point.
        table_shadow = np.where((hidden > 0) | (occlusion < 1), 1 - received / full, 0.0).astype(np.float32)
        background = background * (light.ambient * occlusion[:, None]
                                   + (light.strength * L[2] * (1 - hidden))[:, None] * tint)

    tv = verts[faces]
    face_n = np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0])
    front = np.einsum("ij,ij->i", face_n, tv[:, 0] - t) < 0  # back faces never show on closed meshes
    uv, z = project(verts, T_world_cam, K, dist)
    front &= (z[faces] > _NEAR).all(axis=1)
    faces, owner = faces[front], owner[front]

    # Sample (i, j) of the fine grid sits at pixel coordinate (i + 0.5) / SS - 0.5. Only the box of
    # the objects' projection is rasterised.
    fine = uv * _SS + (_SS - 1) / 2
    coverage = np.zeros(h * w, dtype=np.float32)
    albedo_img = np.zeros((h * w, 3), dtype=np.float32)
    obj_sum = np.zeros((h * w, 3))
    if len(faces):
        used = fine[np.unique(faces)]
        c0 = max(int(np.floor(used[:, 0].min())), 0) // _SS * _SS
        r0 = max(int(np.floor(used[:, 1].min())), 0) // _SS * _SS
        c1 = min(int(np.ceil(used[:, 0].max())) + 1, w * _SS)
        r1 = min(int(np.ceil(used[:, 1].max())) + 1, h * _SS)
    if len(faces) and c1 > c0 and r1 > r0:
        cols = c1 - c0
        face_id, l1, l2 = _rasterise(fine - [c0, r0], z, faces, (r1 - r0, cols))
        hit = np.flatnonzero(face_id >= 0)
        fv = faces[face_id[hit]]
        # Perspective-correct weights: screen-space barycentrics divided by depth.
        wts = np.column_stack([1 - l1[hit] - l2[hit], l1[hit], l2[hit]]) / z[fv]
        wts /= wts.sum(axis=1, keepdims=True)
        n = sum(wts[:, k, None] * normals[fv[:, k]] for k in range(3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        p = sum(wts[:, k, None] * verts[fv[:, k]] for k in range(3))
        r_, c_ = np.divmod(hit, cols)
        pix = ((r_ + r0) // _SS) * w + (c_ + c0) // _SS
        if light is None:
            lambert = ambient + (1 - ambient) * np.clip(n @ LIGHT_DIR, 0, 1)
            # A faint mottle so the object is not a flat plastic colour.
            mottle = 1.0 + 0.03 * np.sin(p @ [157.0, 91.0, 211.0]) * np.sin(p @ [-83.0, 139.0, 67.0])
            colour = OBJECT_BGR * (lambert * mottle)[:, None]
            albedo = np.broadcast_to(OBJECT_BGR / 255, colour.shape)
        else:
            albedo, gloss = _albedo(objs, owner[face_id[hit]], p, n)
            L = light.L
            cos = n @ L
            lit = cos > 0
            hidden = np.ones(len(p))
            sin = np.sqrt(np.clip(1 - cos[lit] ** 2, 0, 1))
            # Hard-edged on the objects (their own shadows are rare and small): one lookup a sample.
            hidden[lit] = shadow_map.shadow(p[lit], _SHADOW_TEXEL * (2 + 3 * sin / np.maximum(cos[lit], 0.2)),
                                            soft=False)
            direct = light.strength * np.clip(cos, 0, 1) * (1 - hidden)
            view = t - p
            view /= np.linalg.norm(view, axis=1, keepdims=True)
            half = view + L
            half /= np.linalg.norm(half, axis=1, keepdims=True)
            specular = gloss * direct * np.clip(np.einsum("ij,ij->i", n, half), 0, 1) ** 40
            tint = np.asarray(light.colour)
            colour = 255.0 * (albedo * (light.ambient + direct[:, None] * tint) + specular[:, None] * tint)
        # Box-filter the samples down to pixels: sums per pixel by bincount.
        obj_sum = np.column_stack([np.bincount(pix, colour[:, k], h * w) for k in range(3)]) / _SS**2
        count = np.bincount(pix, minlength=h * w)
        coverage = (count / _SS**2).astype(np.float32)
        albedo_img = np.column_stack([np.bincount(pix, albedo[:, k], h * w) for k in range(3)])
        albedo_img = (albedo_img / np.maximum(count, 1)[:, None]).astype(np.float32)
    image = (obj_sum.astype(np.float32) + (1 - coverage)[:, None] * background).reshape(h, w, 3)
    return Layers(image, coverage.reshape(h, w), table_shadow.reshape(h, w), albedo_img.reshape(h, w, 3))


def _albedo(objs: Sequence[SimObject], owner: NDArray[np.int64], p: NDArray[np.float64], n: NDArray[np.float64],
            ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Albedo (N, 3) in [0, 1] and gloss (N,) of samples at points p with normals n, by their object."""
    albedo = np.empty((len(p), 3))
    gloss = np.zeros(len(p))
    for k, obj in enumerate(objs):
        mine = owner == k
        if not mine.any():
            continue
        if isinstance(obj, PrintedObject):
            albedo[mine] = obj.albedo(p[mine], n[mine])
            gloss[mine] = obj.look.gloss
        else:
            albedo[mine] = OBJECT_BGR / 255
            gloss[mine] = 0.1
    return albedo, gloss


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
    light: Light | None = None,
    blur_sigma: float = 0.5,
) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """Render ``objects`` on a table as seen from ``T_world_cam``.

    Parameters
    ----------
    objects : SimObject or sequence of SimObject (a PrintedObject wears its print); may be empty,
        for a picture of the empty workspace.
    T_world_cam : (4, 4) array_like, camera-to-world, OpenCV camera axes.
    K : (3, 3) array_like; dist : OpenCV distortion coefficients or None.
    image_size : (width, height) in pixels.
    rng : generator for the sensor noise; None means ``default_rng(0)``.
    noise_sigma : standard deviation of the Gaussian sensor noise (grey levels).
    table : the surroundings; None means ``TableScene()``.
    ambient : without a light: the share of the light a face turned away from the lamp still gets,
        in [0, 1]: the lower, the darker the shaded side (0.15 puts red at V = 30).
    light : None for the classic red scene (unlit table, no shadow); a :class:`Light` for albedo,
        a lit table and cast shadows.
    blur_sigma : the lens's blur, a Gaussian's standard deviation in pixels.

    Returns
    -------
    bgr : (H, W, 3) ndarray of uint8
    mask : (H, W) ndarray of uint8, 255 where at least half the pixel is object.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    layers = render_layers(objects, T_world_cam, K, dist, image_size, table=table, ambient=ambient, light=light)
    w, h = image_size
    # Optics and sensor: blur, vignetting, noise.
    image = cv2.GaussianBlur(layers.image, (0, 0), blur_sigma) if blur_sigma > 0 else layers.image.copy()
    yy, xx = np.mgrid[0:h, 0:w]
    r2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    image *= (1.0 - 0.15 * r2).astype(np.float32)[..., None]
    noise = noise_sigma * rng.standard_normal(image.shape, dtype=np.float32)
    if light is not None:
        # A real sensor's noise grows with the light it counts (shot noise): as given at mid-grey.
        noise *= np.sqrt(0.3 + 0.7 * np.clip(image, 0, 255) / 128)
    image += noise
    bgr = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    mask = np.where(layers.coverage >= 0.5, 255, 0).astype(np.uint8)
    return bgr, mask
