"""Small scenes for the segmentation tests: a box or an upright cylinder on a table, ray-traced.

Written apart from the segmentation it judges: every pixel is 3x3 rays, each
traced against the object (analytically) and the table plane z = 0, and
averaged down, so that edges are area-true and the true silhouette is the
pixels at least half covered by the object. One directional light; a table
point whose way to the light is blocked by the object gets the ambient light
only (the cast shadow). Then lens blur, sensor noise and JPEG.

Textures are functions of the surface point: flat colours, wood grain, a
cutting mat's grid, and a printed label (bands and text-like blocks).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from robocell.workers.sim.scans import default_K, plan_views

__all__ = ["Scene", "render_view", "render_scan"]

_SS = 3
_RAYS_AT_ONCE = 8192


@dataclass(frozen=True)
class Scene:
    shape: str = "box"                     # "box" or "cylinder"
    size: tuple[float, float, float] = (0.04, 0.03, 0.05)   # half-sizes (box); cylinder: (r, r, half-height)
    position: tuple[float, float] = (0.0, 0.0)
    yaw: float = 0.3
    object_bgr: tuple[float, float, float] = (40.0, 60.0, 200.0)
    object_print: str = "flat"             # "flat", "label" or "wood"
    table_bgr: tuple[float, float, float] = (150.0, 170.0, 190.0)
    table_texture: str = "flat"            # "flat", "wood" or "grid"
    light: tuple[float, float, float] = (0.5, -0.3, 0.8)
    ambient: float = 0.35
    with_object: bool = True
    noise: float = 2.0
    shadow_only: bool = False              # the object casts its shadow but is not seen (held out of view)
    extra: dict = field(default_factory=dict)

    @property
    def centre(self) -> np.ndarray:
        return np.array([self.position[0], self.position[1], self.size[2]])


def _object_hit(scene: Scene, origin: np.ndarray, rays: np.ndarray):
    """Ray parameter of the first hit with the object (inf where none), the hit's normal and local point.

    Only rays that pass the object's bounding sphere are traced."""
    origin = np.broadcast_to(origin, rays.shape)
    to_centre = scene.centre - origin
    along = np.einsum("ij,ij->i", to_centre, rays)
    miss = np.einsum("ij,ij->i", to_centre, to_centre) - along ** 2
    near = np.flatnonzero(miss <= float(np.dot(scene.size, scene.size)) * 1.0001)
    t = np.full(len(rays), np.inf)
    normal = np.zeros((len(rays), 3))
    local = np.zeros((len(rays), 3))
    if len(near):
        t[near], normal[near], local[near] = _traced(scene, origin[near], rays[near])
    return t, normal, local


def _traced(scene: Scene, origin: np.ndarray, rays: np.ndarray):
    c, s = np.cos(scene.yaw), np.sin(scene.yaw)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    o = (origin - scene.centre) @ R
    d = rays @ R
    a = np.asarray(scene.size)
    n = len(d)
    if scene.shape == "box":
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-a - o) / d
            t2 = (a - o) / d
        t_near = np.nanmax(np.minimum(t1, t2), axis=1)
        t_far = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (t_near <= t_far) & (t_far > 0)
        t = np.where(hit, t_near, np.inf)
        p = o + t[:, None] * d
        axis = np.argmax(np.abs(p) / a, axis=1)
        normal = np.zeros((n, 3))
        normal[np.arange(n), axis] = np.sign(p[np.arange(n), axis])
    else:
        r, h = a[0], a[2]
        A = d[:, 0] ** 2 + d[:, 1] ** 2
        B = 2 * (o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1])
        C = o[:, 0] ** 2 + o[:, 1] ** 2 - r * r
        disc = B * B - 4 * A * C
        with np.errstate(divide="ignore", invalid="ignore"):
            t_side = (-B - np.sqrt(np.maximum(disc, 0))) / (2 * A)
            t_top = (h - o[:, 2]) / d[:, 2]
        z_side = o[:, 2] + t_side * d[:, 2]
        side = (disc > 0) & (np.abs(z_side) <= h) & (t_side > 0)
        p_top = o + t_top[:, None] * d
        top = (np.hypot(p_top[:, 0], p_top[:, 1]) <= r) & (t_top > 0) & (d[:, 2] < 0)
        t = np.full(n, np.inf)
        t[side] = t_side[side]
        t = np.where(top & (t_top < t), t_top, t)
        p = o + np.where(np.isfinite(t), t, 0)[:, None] * d
        normal = np.column_stack([p[:, 0], p[:, 1], np.zeros(n)]) / r
        is_top = top & (t == t_top)
        normal[is_top] = (0, 0, 1)
    return t, normal @ R.T, p


def _table_colour(scene: Scene, xy: np.ndarray) -> np.ndarray:
    base = np.asarray(scene.table_bgr, dtype=np.float64)
    x, y = xy[:, 0], xy[:, 1]
    if scene.table_texture == "wood":
        across = y * 0.9 + x * 0.3
        warp = 0.004 * np.sin(x / 0.05)
        g = np.sin((across + warp) * 2 * np.pi / 0.006)
        shade = 1.0 - 0.18 * g ** 4 - 0.08 * np.sin(across / 0.03)
    elif scene.table_texture == "grid":
        line = (np.abs(((x + 0.5) % 0.01) - 0.005) < 0.0006) | (np.abs(((y + 0.5) % 0.01) - 0.005) < 0.0006)
        shade = np.where(line, 1.35, 1.0)
    else:
        shade = np.ones(len(x))
    return base * shade[:, None]


def _object_colour(scene: Scene, local: np.ndarray) -> np.ndarray:
    base = np.asarray(scene.object_bgr, dtype=np.float64)
    if scene.object_print == "flat":
        return np.broadcast_to(base, (len(local), 3)).copy()
    if scene.object_print == "wood":  # a grain of its own, running up its sides and across its top
        along = local[:, 2] * 0.8 + local[:, 0] * 0.5 + local[:, 1] * 0.3
        shade = 1.0 - 0.3 * np.sin(along * 2 * np.pi / 0.008) ** 2
        return base * shade[:, None]
    z = local[:, 2] / scene.size[2]
    angle = np.arctan2(local[:, 1], local[:, 0])
    colour = np.broadcast_to(base, (len(local), 3)).copy()
    band = np.abs(z) < 0.45
    colour[band] = (235, 235, 235)
    text = band & (np.abs(z) < 0.3) & (np.sin(angle * 40) > 0.2) & (np.sin(z * 25) > -0.3)
    colour[text] = (30, 30, 30)
    stripe = (z > 0.6) & (z < 0.75)
    colour[stripe] = (200, 120, 30)
    return colour


def render_view(scene: Scene, T_world_cam: np.ndarray, K: np.ndarray, size: tuple[int, int], seed: int):
    """(BGR uint8 image after JPEG, true mask uint8 0/255) of one view."""
    w, h = size
    # Sub-pixel ray k of pixel i sits at i - 0.5 + (k + 0.5) / SS: pixel centres on integers.
    u = (np.arange(w * _SS) + 0.5) / _SS - 0.5
    v = (np.arange(h * _SS) + 0.5) / _SS - 0.5
    u, v = np.meshgrid(u, v)
    pix = np.column_stack([u.ravel(), v.ravel(), np.ones(u.size)])
    colour = np.zeros((len(pix), 3))
    on_object = np.zeros(len(pix), dtype=bool)
    # Each ray is traced on its own, so a few thousand at a time give the same pixels, and their
    # arrays stay in the processor's cache.
    for start in range(0, len(pix), _RAYS_AT_ONCE):
        rows = slice(start, start + _RAYS_AT_ONCE)
        rays = np.linalg.solve(K, pix[rows].T).T @ T_world_cam[:3, :3].T
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        colour[rows], on_object[rows] = _shaded(scene, T_world_cam[:3, 3], rays)
    image = colour.reshape(h, _SS, w, _SS, 3).mean(axis=(1, 3))
    coverage = on_object.reshape(h, _SS, w, _SS).mean(axis=(1, 3))
    image = cv2.GaussianBlur(image.astype(np.float32), (0, 0), 0.6)
    image += np.random.default_rng(seed).normal(0, scene.noise, image.shape).astype(np.float32)
    bgr = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    jpeg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 90])[1]
    mask = np.where(coverage >= 0.5, 255, 0).astype(np.uint8)
    return cv2.imdecode(jpeg, cv2.IMREAD_COLOR), mask


def _shaded(scene: Scene, origin: np.ndarray, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The colour each ray from ``origin`` sees, and whether it meets the object."""
    light = np.asarray(scene.light) / np.linalg.norm(scene.light)
    colour = np.zeros((len(rays), 3))
    t_obj, normal, local = _object_hit(scene, origin, rays) if scene.with_object else (
        np.full(len(rays), np.inf), None, None)
    if scene.shadow_only:
        t_obj = np.full(len(rays), np.inf)
    with np.errstate(divide="ignore"):
        t_table = np.where(rays[:, 2] < 0, -origin[2] / rays[:, 2], np.inf)
    on_object = t_obj < t_table
    on_table = ~on_object & np.isfinite(t_table)
    if on_object.any():
        lambert = scene.ambient + (1 - scene.ambient) * np.clip(normal[on_object] @ light, 0, 1)
        colour[on_object] = _object_colour(scene, local[on_object]) * lambert[:, None]
    points = origin + t_table[on_table, None] * rays[on_table]
    lit = np.ones(len(points))
    if scene.with_object:
        t_block, _, _ = _object_hit(scene, points + 1e-6 * light, np.broadcast_to(light, points.shape).copy())
        lit = np.where(np.isfinite(t_block), 0.0, 1.0)
    table_light = scene.ambient + (1 - scene.ambient) * light[2] * lit
    colour[on_table] = _table_colour(scene, points[:, :2]) * table_light[:, None]
    colour[~on_object & ~on_table] = (60, 60, 60)
    return colour, on_object


def render_scan(scene: Scene, *, views: int = 3, size: tuple[int, int] = (320, 240), seed: int = 0,
                distance: float | None = None, elevations: tuple[float, float] = (35.0, 55.0)):
    """(images, true masks, cameras as (K, T_world_cam) pairs, jpeg bytes) of a scan around the object,
    its views ``elevations`` (degrees) above the table."""
    f = 600.0 * size[0] / 640
    K = default_K(size, f)
    radius = float(np.linalg.norm(scene.size))
    if distance is None:
        distance = max(0.3, radius / np.sin(np.arctan(0.8 * size[1] / 2 / f) - np.radians(2.0)))
    poses = plan_views(scene.centre, views, (distance, distance * 1.15), elevations,
                       float(np.random.default_rng(seed).uniform(0, 360)), np.random.default_rng([seed, 1]))
    images, masks = [], []
    for i, T in enumerate(poses):
        image, mask = render_view(scene, T, K, size, seed * 100 + i)
        images.append(image)
        masks.append(mask)
    return images, masks, [(K, T) for T in poses]
