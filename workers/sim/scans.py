"""Simulated scan bundles: camera planning, writing, and the benchmark set.

A bundle is the directory of DESIGN.md §3 (``scan.json`` and ``view{i}.jpg``)
plus ``truth.json``, the ground truth to score a reconstruction against.
"""
from __future__ import annotations

import dataclasses
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import cv2
import numpy as np

from robocell.core_cy.plan import look_at  # the one look_at: camera-to-world, OpenCV axes
from numpy.typing import ArrayLike, NDArray

from .objects import CupStack, LumpyFigure, SimObject, SuperquadricObject
from .render import AMBIENT, Light, TableScene, remembered, render
from .textures import PRODUCT_LOOKS, TABLE_KINDS, PrintedObject, product_look, table_look

__all__ = [
    "HSV_SEGMENTATION",
    "BROAD_FAMILIES",
    "PRINTED_SCENES",
    "PRODUCT_SET_LOOKS",
    "PRODUCT_TABLES",
    "ScanSpec",
    "OneSidedScan",
    "broad_set",
    "compound_set",
    "fourth_view_candidates",
    "one_sided_set",
    "one_sided_views",
    "default_K",
    "fitting_distance",
    "look_at",
    "make_spec",
    "object_target",
    "plan_views",
    "printed_products_set",
    "printed_set",
    "standard_set",
    "write_scan",
    "write_standard_set",
    "ycb_like_set",
]

#: The segmentation written into every simulated scan.json: red, hue wrapping round 0.
HSV_SEGMENTATION: dict[str, Any] = {"method": "hsv", "lower": [170, 90, 20], "upper": [10, 255, 255]}


def default_K(image_size: tuple[int, int] = (640, 480), f: float = 600.0) -> NDArray[np.float64]:
    """(3, 3) pinhole matrix, focal length ``f`` px, principal point at the image centre."""
    w, h = image_size
    return np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])


def _rot(axis: int, angle: float) -> NDArray[np.float64]:
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def plan_views(
    target: ArrayLike,
    n_views: int = 3,
    distance: tuple[float, float] = (0.4, 0.7),
    elevation_deg: tuple[float, float] = (35.0, 55.0),
    azimuth_start_deg: float = 0.0,
    rng: np.random.Generator | None = None,
    jitter_deg: float = 2.0,
) -> list[NDArray[np.float64]]:
    """Poses (4, 4 each) of ``n_views`` cameras around ``target``, 360/n degrees apart.

    With ``rng`` each view's distance and elevation are drawn uniformly from
    the ranges, its azimuth is moved by up to ``jitter_deg`` and its optical
    axis tilted off the target by up to ``jitter_deg`` about the camera's x and
    y axes (an arm does not point perfectly). Without ``rng`` every view sits
    at the middle of the ranges and looks exactly at the target.
    """
    if n_views < 1:
        raise ValueError(f"n_views must be >= 1, got {n_views}")
    target = np.asarray(target, dtype=np.float64).reshape(3)
    poses = []
    for i in range(n_views):
        if rng is None:
            d, el, jitter = np.mean(distance), np.mean(elevation_deg), np.zeros(3)
        else:
            d, el = rng.uniform(*distance), rng.uniform(*elevation_deg)
            jitter = rng.uniform(-jitter_deg, jitter_deg, 3)
        az = np.radians(azimuth_start_deg + i * 360.0 / n_views + jitter[0])
        el = np.radians(el)
        offset = d * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        T = look_at(target + offset, target)
        # Turning about the camera's own axes keeps its position (distance, elevation).
        T[:3, :3] = T[:3, :3] @ _rot(0, np.radians(jitter[1])) @ _rot(1, np.radians(jitter[2]))
        poses.append(T)
    return poses


def _json_bytes(obj: Any) -> bytes:
    """Indented JSON with every innermost list of numbers on one line (matrix rows)."""
    text = json.dumps(obj, indent=2)
    flat = re.compile(r"\[\s+([-+.\deE,\s]+?)\s+\]")  # a list holding only numbers
    text = flat.sub(lambda m: "[" + ", ".join(x.strip() for x in m.group(1).split(",")) + "]", text)
    return (text + "\n").encode()


def write_scan(
    out_dir: str | Path,
    objects: SimObject | Sequence[SimObject],
    cameras: Sequence[ArrayLike],
    K: ArrayLike,
    dist: ArrayLike | None = None,
    *,
    seed: int,
    image_size: tuple[int, int] = (640, 480),
    jpeg_quality: int = 90,
    write_masks: bool = False,
    name_masks: bool = False,
    noise_sigma: float = 2.0,
    ambient: float = AMBIENT,
    table: TableScene | None = None,
    light: Light | None = None,
    blur_sigma: float = 0.5,
    segmentation: dict[str, Any] | None = HSV_SEGMENTATION,
    truth_masks: bool = False,
    backgrounds: bool = False,
) -> Path:
    """Render and write one scan bundle; return its directory.

    Writes ``view{i}.jpg`` per camera, ``scan.json`` (DESIGN.md §3, with
    :data:`HSV_SEGMENTATION` and the table plane as support plane) and
    ``truth.json``: the object's ``truth()``, or ``{"kind": "scene",
    "objects": [...]}`` for several objects. ``write_masks`` adds
    ``mask{i}.png`` (255 = object) for inspection; scan.json does not name them,
    so a reconstruction still has to segment the images, unless ``name_masks``
    (which implies ``write_masks``) supplies them as each view's ``mask``.
    ``noise_sigma`` (grey levels) and ``ambient`` (see :func:`render`) set the
    sensor noise and how dark the shaded side is. The table's look (unless
    ``table`` is given) and the sensor noise follow ``seed``: the same arguments
    give the same bytes.

    ``light`` (see :func:`render`) lights the scene and casts the shadows;
    ``blur_sigma`` is the lens blur; ``segmentation`` goes into scan.json as it
    is, None leaving the key out (the reader's default). ``truth_masks`` writes
    the true silhouettes as ``truth_mask{i}.png``, never named in scan.json;
    ``backgrounds`` also writes ``background{i}.jpg``, the empty workspace from
    the same pose under the same light (no object, no shadow, its own sensor
    noise), named as each view's ``background``.
    """
    objs = [objects] if isinstance(objects, SimObject) else list(objects)
    if not objs:
        raise ValueError("no objects to scan")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    K = np.asarray(K, dtype=np.float64)
    # Each view's background sees the table from the view's own pose: it is traced once for both.
    table = remembered(TableScene.from_seed(seed) if table is None else table)
    look = dict(noise_sigma=noise_sigma, table=table, ambient=ambient, light=light, blur_sigma=blur_sigma)

    def write_jpeg(name: str, bgr: NDArray[np.uint8]) -> None:
        ok, jpg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        if not ok:
            raise RuntimeError(f"JPEG encoding failed for {name}")
        (out / name).write_bytes(jpg.tobytes())

    views = []
    for i, T in enumerate(cameras):
        bgr, mask = render(objs, T, K, dist, image_size, rng=np.random.default_rng([seed, i]), **look)
        write_jpeg(f"view{i}.jpg", bgr)
        if write_masks or name_masks:
            cv2.imwrite(str(out / f"mask{i}.png"), mask)
        if truth_masks:
            cv2.imwrite(str(out / f"truth_mask{i}.png"), mask)
        view: dict[str, Any] = {"image": f"view{i}.jpg", "K": K.tolist()}
        if name_masks:
            view["mask"] = f"mask{i}.png"
        if backgrounds:
            empty, _ = render([], T, K, dist, image_size, rng=np.random.default_rng([seed, i, 1]), **look)
            write_jpeg(f"background{i}.jpg", empty)
            view["background"] = f"background{i}.jpg"
        if dist is not None:
            view["dist"] = np.asarray(dist, dtype=np.float64).ravel().tolist()
        view["T_world_cam"] = np.asarray(T, dtype=np.float64).tolist()
        views.append(view)
    scan: dict[str, Any] = {"views": views, "segmentation": segmentation, "support_plane": [0, 0, 1, 0]}
    if segmentation is None:
        del scan["segmentation"]
    (out / "scan.json").write_bytes(_json_bytes(scan))
    truth = objs[0].truth() if len(objs) == 1 else {"kind": "scene", "objects": [o.truth() for o in objs]}
    (out / "truth.json").write_bytes(_json_bytes(truth))
    return out


@dataclass(frozen=True, eq=False)
class ScanSpec:
    """Everything needed to write one simulated scan bundle."""

    name: str
    objects: tuple[SimObject, ...]
    cameras: tuple[NDArray[np.float64], ...]
    K: NDArray[np.float64]
    target: NDArray[np.float64]  # the point the cameras aim at (the object's centre)
    seed: int
    dist: NDArray[np.float64] | None = None
    image_size: tuple[int, int] = field(default=(640, 480))
    jpeg_quality: int = 90
    noise_sigma: float = 2.0
    ambient: float = AMBIENT
    # The look of the printed scenes (see write_scan); the defaults are the red scenes'.
    table: TableScene | None = None
    light: Light | None = None
    blur_sigma: float = 0.5
    segmentation: dict[str, Any] | None = field(default_factory=lambda: HSV_SEGMENTATION)
    truth_masks: bool = False
    table_kind: str = ""  # what a benchmark groups the scan by
    object_kind: str = ""

    def write(self, out_dir: str | Path, write_masks: bool = False, name_masks: bool = False,
              backgrounds: bool = False) -> Path:
        """Write the bundle to ``out_dir / name`` (see :func:`write_scan` for the masks and backgrounds)."""
        return write_scan(
            Path(out_dir) / self.name, self.objects, self.cameras, self.K, self.dist,
            seed=self.seed, image_size=self.image_size, jpeg_quality=self.jpeg_quality,
            write_masks=write_masks, name_masks=name_masks, noise_sigma=self.noise_sigma,
            ambient=self.ambient, table=self.table, light=self.light, blur_sigma=self.blur_sigma,
            segmentation=self.segmentation, truth_masks=self.truth_masks, backgrounds=backgrounds,
        )


def object_target(obj: SimObject) -> NDArray[np.float64]:
    """Where to aim the cameras: the centre of the mesh's bounding box."""
    v = obj.mesh()[0]
    return (v.min(axis=0) + v.max(axis=0)) / 2


def fitting_distance(obj: SimObject, K: ArrayLike, image_size: tuple[int, int], fill: float = 0.8) -> float:
    """Smallest camera distance at which the object's bounding sphere spans at most
    ``fill`` of the image's half-height (from the aimed-at centre, 2 degrees of
    pointing jitter allowed for)."""
    v = obj.mesh()[0]
    r = float(np.linalg.norm(v - object_target(obj), axis=1).max())
    half_angle = np.arctan(fill * min(image_size) / 2 / float(np.asarray(K)[1, 1])) - np.radians(2.0)
    return r / np.sin(half_angle)


def make_spec(
    name: str, obj: SimObject, seed: int, n_views: int = 3,
    distance: tuple[float, float] = (0.4, 0.7), elevation_deg: tuple[float, float] = (35.0, 55.0),
    image_size: tuple[int, int] = (640, 480), fit_distance: bool = True,
    jpeg_quality: int = 90, noise_sigma: float = 2.0, ambient: float = AMBIENT,
) -> ScanSpec:
    """A spec with cameras planned around ``obj``, seeded by ``seed``.

    With ``fit_distance`` the near end of ``distance`` moves out (at most to the
    far end) until the whole object fits in the image. ``jpeg_quality``,
    ``noise_sigma`` and ``ambient`` are passed on to :func:`write_scan`.
    """
    K = default_K(image_size)
    near = distance[0]
    if fit_distance:
        near = min(max(near, fitting_distance(obj, K, image_size)), distance[1])
    rng = np.random.default_rng([seed, 1])
    target = object_target(obj)
    cams = plan_views(target, n_views, (near, distance[1]), elevation_deg, rng.uniform(0, 360), rng)
    return ScanSpec(name, (obj,), tuple(cams), K, target, seed, image_size=image_size,
                    jpeg_quality=jpeg_quality, noise_sigma=noise_sigma, ambient=ambient)


def standard_set(seed: int = 0) -> list[ScanSpec]:
    """The fixed benchmark: 6 scans per superquadric family, 2 cup stacks, 2 lumpy figures.

    Half-sizes are drawn from 1.5-7.5 cm (full dimensions 3-15 cm), at least
    one of them 3 cm or more so that no object is a speck at 0.7 m; cylinders
    are round (a1 = a2); scans 4 and 5 of each family lie on their side. Yaws
    are uniform, positions within 8 cm of (0.6, 0).
    """
    specs = []
    for fam_index, family in enumerate(["box", "cylinder", "ellipsoid", "rounded-box"]):
        for i in range(6):
            rng = np.random.default_rng([seed, fam_index, i])
            a = rng.uniform(0.015, 0.075, 3)
            a[rng.integers(3)] = rng.uniform(0.03, 0.075)
            if family == "cylinder":
                a[1] = a[0]
            rho, phi = 0.08 * np.sqrt(rng.random()), rng.uniform(0, 2 * np.pi)
            xy = (0.6 + rho * np.cos(phi), rho * np.sin(phi))
            obj = SuperquadricObject.on_table(family, a, xy, rng.uniform(0, 180), lying=i >= 4)
            specs.append(make_spec(f"{family}-{i:02d}", obj, seed=1000 * seed + 10 * fam_index + i))
    for i in range(2):
        rng = np.random.default_rng([seed, 10, i])
        xy = (0.6 + rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05))
        cups = CupStack(xy, rng.uniform(0.022, 0.03), rng.uniform(0.035, 0.045), rng.uniform(0.05, 0.07), i == 0)
        specs.append(make_spec(f"cup-stack-{i:02d}", cups, seed=1000 * seed + 100 + i))
        lumpy = LumpyFigure(xy, rng.uniform(0.03, 0.06, 3), seed=1000 * seed + i)
        specs.append(make_spec(f"lumpy-{i:02d}", lumpy, seed=1000 * seed + 200 + i))
    return specs


def write_standard_set(out_dir: str | Path, seed: int = 0, write_masks: bool = False) -> list[Path]:
    """Write every bundle of :func:`standard_set` under ``out_dir``; return their directories."""
    return [spec.write(out_dir, write_masks) for spec in standard_set(seed)]


def _flat_box(rng: np.random.Generator, xy, yaw: float) -> SuperquadricObject:
    """A box with one half-size of 8-12 mm: lying flat (thin along z) or standing on its narrow side."""
    a = rng.uniform(0.025, 0.075, 3)
    a[rng.choice([0, 2])] = rng.uniform(0.008, 0.012)
    return SuperquadricObject.on_table("box", a, xy, yaw)


def _plate(rng: np.random.Generator, xy, yaw: float) -> SuperquadricObject:
    """A disc standing on its rim: radius 3.5-7.5 cm, 0.8-2 cm thick."""
    radius = rng.uniform(0.035, 0.075)
    return SuperquadricObject.on_table("cylinder", [radius, radius, rng.uniform(0.004, 0.01)], xy, yaw,
                                       lying=True)


def _cylinder(lying: bool):
    def make(rng: np.random.Generator, xy, yaw: float) -> SuperquadricObject:
        radius = rng.uniform(0.01, 0.05)
        return SuperquadricObject.on_table("cylinder", [radius, radius, rng.uniform(0.015, 0.075)], xy, yaw,
                                           lying=lying)
    return make


def _family(name: str):
    def make(rng: np.random.Generator, xy, yaw: float) -> SuperquadricObject:
        return SuperquadricObject.on_table(name, rng.uniform(0.01, 0.075, 3), xy, yaw)
    return make


#: The broad benchmark's object families: each draws an object standing on the table at (x, y), turned by yaw.
BROAD_FAMILIES = {
    "box": _family("box"),
    "flat-box": _flat_box,
    "cylinder": _cylinder(lying=False),
    "lying-cylinder": _cylinder(lying=True),
    "plate": _plate,
    "ellipsoid": _family("ellipsoid"),
    "rounded-box": _family("rounded-box"),
}


def broad_set(seed: int = 0, per_family: int = 6, view_counts: Sequence[int] = (3, 4, 6)) -> list[ScanSpec]:
    """A benchmark broad enough that no single kind of scan can be tuned to.

    ``per_family`` objects of each of :data:`BROAD_FAMILIES`, full dimensions
    2-15 cm, turned at random within 8 cm of (0.6, 0); each is scanned once per
    number of views in ``view_counts``, every camera at its own elevation of
    20-60 degrees and distance of 0.4-0.7 m, all scans of one object sharing
    its table, JPEG quality (70-95), sensor noise (1-4 grey levels) and how
    dark its shaded side is (ambient light 0.15-0.4). Names are
    ``{family}-{i:02d}-{n}v``.
    """
    specs = []
    for fam_index, (family, make) in enumerate(BROAD_FAMILIES.items()):
        for i in range(per_family):
            rng = np.random.default_rng([seed, 100 + fam_index, i])
            rho, phi = 0.08 * np.sqrt(rng.random()), rng.uniform(0, 2 * np.pi)
            obj = make(rng, (0.6 + rho * np.cos(phi), rho * np.sin(phi)), rng.uniform(0, 180))
            look = dict(jpeg_quality=int(rng.integers(70, 96)), noise_sigma=float(rng.uniform(1.0, 4.0)),
                        ambient=float(rng.uniform(0.15, 0.4)))
            scene_seed = 1000 * seed + 50 * fam_index + i
            for n in view_counts:
                specs.append(make_spec(f"{family}-{i:02d}-{n}v", obj, scene_seed, n, elevation_deg=(20.0, 60.0),
                                       **look))
    return specs


# --- printed objects on real-looking tables ---------------------------------------------------

#: The printed set's scenes: (table kind, look, shape, views). Shapes: see :func:`_printed_shape`.
PRINTED_SCENES: tuple[tuple[str, str, str, int], ...] = (
    ("oak", "mustard", "bottle", 3),
    ("oak", "table-colour", "box", 3),
    ("oak", "soup-can", "lying-can", 4),
    ("rubber-mat", "dark", "can", 3),
    ("rubber-mat", "tin", "tin", 3),
    ("rubber-mat", "printed", "ellipsoid", 6),
    ("laminate", "white", "box", 3),
    ("laminate", "sugar-box", "tall-box", 3),
    ("laminate", "mustard", "bottle", 4),
    ("cutting-mat", "sugar-box", "lying-box", 3),
    ("cutting-mat", "soup-can", "can", 3),
    ("cutting-mat", "printed", "lying-can", 3),
    ("wood", "tin", "lying-can", 3),
    ("wood", "printed", "box", 4),
    ("fabric", "soup-can", "can", 3),
    ("fabric", "printed", "ellipsoid", 3),
)


def _printed_shape(shape: str, rng: np.random.Generator, xy: tuple[float, float], yaw: float) -> SuperquadricObject:
    """A grocery-sized superquadric: bottle (rounded shoulders, oval), can, tin (short, wide), lying can,
    box, tall box (a sugar box on its end), lying box, ellipsoid; sizes vary by about 15 %."""
    k = rng.uniform(0.85, 1.15, 3)
    family, size, lying = {
        "bottle": ((0.45, 1.0), [0.034, 0.024, 0.085], False),
        "can": ("cylinder", [0.034, 0.034, 0.05], False),
        "tin": ("cylinder", [0.045, 0.045, 0.022], False),
        "lying-can": ("cylinder", [0.033, 0.033, 0.055], True),
        "box": ("box", [0.04, 0.032, 0.035], False),
        "tall-box": ("box", [0.045, 0.025, 0.075], False),
        "lying-box": ("box", [0.045, 0.025, 0.075], True),
        "ellipsoid": ("ellipsoid", [0.05, 0.035, 0.03], False),
    }[shape]
    size = np.asarray(size) * k
    if family == "cylinder":
        size[1] = size[0]
    return SuperquadricObject.on_table(family, size, xy, yaw, lying=lying)  # type: ignore[arg-type]


def printed_set(seed: int = 0) -> list[ScanSpec]:
    """Printed objects on real-looking tables, lit by one lamp that casts their shadows.

    One scan per row of :data:`PRINTED_SCENES`: grocery-like objects (a yellow mustard
    bottle, a white-and-blue sugar box, a red-and-white soup can, a blue-and-yellow tin,
    an object the colour of its table, a white object on white laminate, a dark one on a
    dark mat, and randomly printed ones) on oak, a rubber mat, white laminate, a cutting
    mat and the classic wood and fabric. The lamp's direction (azimuth any, 35-70 degrees
    high), strength and warmth, the lens blur, sensor noise, JPEG quality, sizes, yaws and places
    (within 5 cm of (0.6, 0)) follow ``seed``. The bundles name no segmentation (the
    default finds the object) and carry their true masks as ``truth_mask{i}.png``; names
    are ``{table}-{look}-{shape}``, and ``table_kind``, ``object_kind`` say which.
    """
    specs = []
    for index, (kind, look_name, shape, n_views) in enumerate(PRINTED_SCENES):
        rng = np.random.default_rng([seed, 300, index])
        scene_seed = 1000 * seed + 300 + index
        rho, phi = 0.05 * np.sqrt(rng.random()), rng.uniform(0, 2 * np.pi)
        xy = (0.6 + rho * np.cos(phi), rho * np.sin(phi))
        obj = _printed_shape(shape, rng, xy, rng.uniform(0, 180))
        table = TableScene.of_kind(kind, scene_seed)
        if look_name == "table-colour":
            look = table_look(table, xy)
        else:
            look = product_look(look_name, rng, float(obj.size[2]))
        specs.append(_lit_on_table(f"{kind}-{look_name}-{shape}", PrintedObject(obj, look), table, rng, scene_seed,
                                   n_views, table_kind=kind, object_kind=look_name))
    return specs


def _lit_on_table(name: str, obj: PrintedObject, table: TableScene, rng: np.random.Generator, scene_seed: int,
                  n_views: int, **kinds: str) -> ScanSpec:
    """The spec of ``obj`` on ``table`` under one lamp drawn from ``rng`` (any azimuth, 35-70 degrees high,
    its strength, warmth and the ambient light), with the lens blur, sensor noise and JPEG quality drawn
    from it too; no segmentation named, the true masks written. ``kinds``: ``table_kind``, ``object_kind``."""
    ambient = float(rng.uniform(0.25, 0.45))
    elevation = float(rng.uniform(35, 70))
    # The lit table at 85-100 % of its albedo, as a camera's exposure would put it.
    strength = (float(rng.uniform(0.85, 1.0)) - ambient) / np.sin(np.radians(elevation))
    warmth = float(rng.uniform(0.0, 0.12))  # from a daylight-white lamp to a warm one
    light = Light.from_angles(float(rng.uniform(0, 360)), elevation, strength, ambient,
                              colour=(1.0 - warmth, 1.0 - warmth / 3, 1.0))
    spec = make_spec(name, obj, scene_seed, n_views, elevation_deg=(30.0, 60.0),
                     jpeg_quality=int(rng.integers(80, 96)), noise_sigma=float(rng.uniform(1.5, 3.0)))
    return dataclasses.replace(spec, table=table, light=light, blur_sigma=float(rng.uniform(0.5, 0.9)),
                               segmentation=None, truth_masks=True, **kinds)


#: The tables and looks :func:`printed_products_set` puts the products on and in, each in turn.
PRODUCT_TABLES = (*TABLE_KINDS, "wood", "fabric")
PRODUCT_SET_LOOKS = (*PRODUCT_LOOKS, "table-colour")


def printed_products_set(seed: int = 0) -> list[ScanSpec]:
    """The YCB-like products (:data:`workers.sim.objects.YCB_LIKE`, unions of superquadrics: a mug and its
    handle, a drill, a hammer, a banana, bottles, boxes and cans) wearing printed looks on the printed set's
    tables, lit as :func:`printed_set` lights them, three views each: what a robot meets on a shelf, where
    the printed set's objects are each one superquadric.

    Product ``i`` stands on table ``(i + seed) % 6`` of :data:`PRODUCT_TABLES` and wears look
    ``(i + 3 * seed) % 8`` of :data:`PRODUCT_SET_LOOKS` (``table-colour``: the grain and colour of its
    table), so that a few seeds put each product on most tables and in most looks. Its place (within 5 cm
    of (0.6, 0)), yaw, lamp, lens blur, noise and JPEG quality follow ``seed``. The bundles name no
    segmentation and carry their true masks as ``truth_mask{i}.png``; ``truth.json`` lists the parts.
    Names are ``{table}-{look}-{product}``; ``table_kind`` is the table, ``object_kind`` the product.
    """
    from .objects import YCB_LIKE, compound

    specs = []
    for index, product in enumerate(YCB_LIKE):
        rng = np.random.default_rng([seed, 900, index])
        scene_seed = 1000 * seed + 900 + index
        rho, phi = 0.05 * np.sqrt(rng.random()), rng.uniform(0, 2 * np.pi)
        xy = (0.6 + rho * np.cos(phi), rho * np.sin(phi))
        obj = compound(product, xy, rng.uniform(0, 360))
        kind = PRODUCT_TABLES[(index + seed) % len(PRODUCT_TABLES)]
        look_name = PRODUCT_SET_LOOKS[(index + 3 * seed) % len(PRODUCT_SET_LOOKS)]
        table = TableScene.of_kind(kind, scene_seed)
        if look_name == "table-colour":
            look = table_look(table, xy)
        else:
            look = product_look(look_name, rng, float(obj.mesh()[0][:, 2].max()) / 2)
        specs.append(_lit_on_table(f"{kind}-{look_name}-{product}", PrintedObject(obj, look), table, rng,
                                   scene_seed, 3, table_kind=kind, object_kind=product))
    return specs


# --- Compound objects and one-sided scans (issues 21 and 22) ---------------------------------------

def compound_set(seed: int = 0, per_kind: int = 2, n_views: int = 3) -> list[ScanSpec]:
    """``per_kind`` scans of each everyday compound object (:data:`workers.sim.objects.EVERYDAY`).

    Each object is drawn from ``seed``, turned at random within 8 cm of (0.6, 0), and
    scanned with ``n_views`` views all around it at 35-55 degrees of elevation (as
    :func:`standard_set`). ``truth.json`` lists its parts (DESIGN.md §3). Names are
    ``{kind}-{i:02d}``.
    """
    from .objects import EVERYDAY, compound

    specs = []
    for kind_index, kind in enumerate(EVERYDAY):
        for i in range(per_kind):
            rng = np.random.default_rng([seed, 300 + kind_index, i])
            rho, phi = 0.08 * np.sqrt(rng.random()), rng.uniform(0, 2 * np.pi)
            obj = compound(kind, (0.6 + rho * np.cos(phi), rho * np.sin(phi)), rng.uniform(0, 360),
                           seed=1000 * seed + 20 * kind_index + i)
            specs.append(make_spec(f"{kind}-{i:02d}", obj, seed=1000 * seed + 400 + 20 * kind_index + i,
                                   n_views=n_views))
    return specs


def ycb_like_set(seed: int = 0, per_kind: int = 1, n_views: int = 3) -> list[ScanSpec]:
    """``per_kind`` scans of each YCB-like product (:data:`workers.sim.objects.YCB_LIKE`), placed and
    scanned as :func:`compound_set` does. Names are ``{kind}-{i:02d}``."""
    from .objects import YCB_LIKE, compound

    specs = []
    for kind_index, kind in enumerate(YCB_LIKE):
        for i in range(per_kind):
            rng = np.random.default_rng([seed, 700 + kind_index, i])
            rho, phi = 0.08 * np.sqrt(rng.random()), rng.uniform(0, 2 * np.pi)
            obj = compound(kind, (0.6 + rho * np.cos(phi), rho * np.sin(phi)), rng.uniform(0, 360))
            specs.append(make_spec(f"{kind}-{i:02d}", obj, seed=1000 * seed + 700 + 20 * kind_index + i,
                                   n_views=n_views))
    return specs


def one_sided_views(
    target: ArrayLike, azimuth_deg: float, distance: float, elevation_deg: Sequence[float] = (45.0, 35.0, 50.0),
    span_deg: float = 60.0,
) -> list[NDArray[np.float64]]:
    """Camera poses of a robot reaching from one side: ``len(elevation_deg)`` views spread evenly
    over ``span_deg`` of azimuth centred on ``azimuth_deg``, each at its elevation, ``distance``
    from ``target`` and aimed at it.

    Examples
    --------
    >>> poses = one_sided_views([0.6, 0.0, 0.05], 180.0, 0.5)
    >>> [round(float(np.degrees(np.arctan2(T[1, 3], T[0, 3] - 0.6))) % 360) for T in poses]
    [150, 180, 210]
    """
    target = np.asarray(target, dtype=np.float64).reshape(3)
    n = len(elevation_deg)
    azimuths = azimuth_deg + (np.linspace(-span_deg / 2, span_deg / 2, n) if n > 1 else np.zeros(1))
    return [_around(target, az, el, distance) for az, el in zip(azimuths, elevation_deg)]


def fourth_view_candidates(
    target: ArrayLike, distance: float, elevation_deg: float = 40.0, azimuth_start_deg: float = 0.0, count: int = 12,
) -> list[NDArray[np.float64]]:
    """``count`` camera poses evenly around ``target`` (360/count degrees of azimuth apart, from
    ``azimuth_start_deg``), at ``elevation_deg`` and ``distance``, aimed at it: where a fourth
    view could be taken from."""
    target = np.asarray(target, dtype=np.float64).reshape(3)
    return [_around(target, azimuth_start_deg + k * 360.0 / count, elevation_deg, distance) for k in range(count)]


def _around(target: NDArray[np.float64], azimuth_deg: float, elevation_deg: float, distance: float):
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    offset = distance * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return look_at(target + offset, target)


@dataclass(frozen=True, eq=False)
class OneSidedScan:
    """An object seen from one side, and where a fourth view could come from.

    ``spec`` holds 3 + 12 cameras: views 0-2 are the one-sided scan (:func:`one_sided_views`),
    views 3-14 the candidate fourth views (:func:`fourth_view_candidates`), rendered together so
    that each 4-view scan is the first three views and one candidate.
    """

    family: str
    spec: ScanSpec
    n_seen: int = 3


def one_sided_set(seed: int = 0, per_family: int = 1, families: Sequence[str] | None = None,
                  compounds: Sequence[str] = ("mug", "hammer", "l-boxes", "spray-bottle", "t-bars"),
                  ) -> list[OneSidedScan]:
    """One-sided scans of single superquadrics (:data:`BROAD_FAMILIES`) and of compound objects
    turned so that their handle or second part (each kind's +x side) faces away from the cameras.

    The robot reaches from a random azimuth; the three views span 60 degrees of it; twelve
    candidates stand 30 degrees apart all around, at 40 degrees of elevation. Names are
    ``{family}-{i:02d}-one-sided``.
    """
    from .objects import compound

    chosen = list(BROAD_FAMILIES) if families is None else list(families)
    scans = []
    for index, family in enumerate([*chosen, *compounds]):
        for i in range(per_family):
            rng = np.random.default_rng([seed, 500 + index, i])
            rho, phi = 0.06 * np.sqrt(rng.random()), rng.uniform(0, 2 * np.pi)
            xy = (0.6 + rho * np.cos(phi), rho * np.sin(phi))
            side = rng.uniform(0, 360)
            if family in BROAD_FAMILIES:
                obj: SimObject = BROAD_FAMILIES[family](rng, xy, rng.uniform(0, 180))
            else:
                # The part on the object's +x side points away from the cameras' side, give or take 20 degrees.
                obj = compound(family, xy, side + 180.0 + rng.uniform(-20, 20), seed=1000 * seed + 30 * index + i)
            K = default_K()
            target = object_target(obj)
            distance = min(max(0.45, fitting_distance(obj, K, (640, 480))), 0.7)
            cameras = [*one_sided_views(target, side, distance), *fourth_view_candidates(target, distance,
                                                                                           azimuth_start_deg=side)]
            look = dict(jpeg_quality=int(rng.integers(80, 96)), noise_sigma=float(rng.uniform(1.0, 3.0)))
            spec = ScanSpec(f"{family}-{i:02d}-one-sided", (obj,), tuple(cameras), K, target,
                            1000 * seed + 600 + 30 * index + i, **look)
            scans.append(OneSidedScan(family, spec))
    return scans
