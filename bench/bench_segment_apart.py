"""Benchmark of `auto` on scenes from a renderer written apart from the simulator it was tuned on.

    .venv/bin/python bench/bench_segment_apart.py [--scans 24] [--first 0] [--record FILE]

bench/bench_segment.py scores `auto` on `robocell sim`'s printed scenes, the ones its rules were measured
on. Here the scenes come from tests/seg_scenes.py, a ray tracer written apart from the simulator and from
the segmentation (area-true edges, one directional light and the cast shadow, lens blur, sensor noise,
JPEG), drawn at random per scan: a box or an upright cylinder of any size from 4 to 14 cm, flat, printed
with a label or grained like wood, of any colour (one in five the table's own); a table of any colour,
flat, wood-grained or a mat with a grid; the lamp anywhere from 35 to 80 degrees up; the ambient light; the
noise; three views at 640x480, about half of the scans near (at the distance at which the object fills
eight tenths of a picture's height, about 6 % to 14 % of each picture: a camera on the wrist comes that
near), the others far (1.5 to 2 times as far: about 1 % to 5 %); half of the scans' views 35-55 degrees
above the table (as the simulator's), a quarter low (15-30), a quarter high (60-80). Three ways, as bench_segment's:
"default" (the images, poses and support plane), "+ background" (each view also with a picture of the
empty workspace, rendered without the object) and "true masks" (the ceiling).

(a) silhouette IoU per view against the true silhouette, mean / worst / views under 0.85, per table, per
    print, per shape, for objects of the table's colour or not, near or far, and per band of elevation;
(b) volumetric IoU of the model against the true box or cylinder (workers/sim/judge.py's Monte Carlo
    union_iou; the truth as a superquadric of exponent 0.1, which the true masks' ceiling shares), the
    same groups.

A reconstruction that fails scores 0 and is counted; the scans whose backgrounds were set aside (reconstruct's
backgrounds_set_aside: the silhouettes cut against them failed) are listed. Prints tables; asserts nothing.
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import colorsys  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_core import model_parts  # noqa: E402

from robocell.core_cy.camera import Camera  # noqa: E402
from robocell.core_cy.reconstruct import View, reconstruct  # noqa: E402
from robocell.workers.sim.judge import Part, union_iou  # noqa: E402
from robocell.workers.sim.scans import default_K, plan_views  # noqa: E402
from tests.seg_scenes import Scene, render_view  # noqa: E402

WAYS = ("default", "+ background", "true masks")
#: The bands of elevation (degrees above the table) a scan's three views are taken from: the simulator's
#: scans are all in the middle one.
ELEVATIONS = {"low views": (15.0, 30.0), "middle views": (35.0, 55.0), "high views": (60.0, 80.0)}
SIZE = (640, 480)
FOCAL = 600.0


def _bgr(hue: float, saturation: float, value: float) -> tuple[float, float, float]:
    red, green, blue = colorsys.hsv_to_rgb(hue, saturation, value)
    return 255 * blue, 255 * green, 255 * red


def scene_of(number: int) -> tuple[Scene, float, bool, str]:
    """Scan ``number``'s scene, its camera distance (m), whether that is near, and the band of elevations its
    views are taken from (a key of :data:`ELEVATIONS`), drawn from its own generator."""
    rng = np.random.default_rng([number, 77])
    shape = "box" if rng.random() < 0.55 else "cylinder"
    if shape == "box":
        size = (rng.uniform(0.02, 0.06), rng.uniform(0.02, 0.05), rng.uniform(0.02, 0.07))
    else:
        radius = rng.uniform(0.02, 0.045)
        size = (radius, radius, rng.uniform(0.03, 0.07))
    table = _bgr(rng.random(), rng.uniform(0, 0.5), rng.uniform(0.25, 0.9))
    if rng.random() < 0.2:
        colour = tuple(channel * rng.uniform(0.9, 1.1) for channel in table)
    else:
        colour = _bgr(rng.random(), rng.uniform(0, 1), rng.uniform(0.15, 0.95))
    elevation, azimuth = np.radians(rng.uniform(35, 80)), rng.uniform(0, 2 * np.pi)
    light = (np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation))
    scene = Scene(shape=shape, size=size, position=(rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02)),
                  yaw=rng.uniform(0, np.pi), object_bgr=colour,
                  object_print=str(rng.choice(["flat", "label", "wood"], p=[0.3, 0.5, 0.2])),
                  table_bgr=table, table_texture=str(rng.choice(["flat", "wood", "grid"])),
                  light=light, ambient=rng.uniform(0.25, 0.5), noise=rng.uniform(1.5, 3.0))
    # Near: render_scan's own distance, at which the object fills eight tenths of a picture's height (a camera
    # on the wrist comes that close); or far, 1.5 to 2 times as far.
    radius = float(np.linalg.norm(size))
    fills = max(0.3, radius / np.sin(np.arctan(0.8 * SIZE[1] / 2 / FOCAL) - np.radians(2.0)))
    near = bool(rng.random() < 0.5)
    distance = fills * (1.0 if near else rng.uniform(1.5, 2.0))
    return scene, distance, near, str(rng.choice(list(ELEVATIONS), p=[0.25, 0.5, 0.25]))


def truth_of(scene: Scene) -> list[Part]:
    """The true box or cylinder as a superquadric (exponent 0.1 for its sharp edges)."""
    c, s = np.cos(scene.yaw), np.sin(scene.yaw)
    pose = np.eye(4)
    pose[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    pose[:3, 3] = scene.centre
    return [Part(np.asarray(scene.size, float), np.array([0.1, 0.1 if scene.shape == "box" else 1.0]), pose)]


def score(number: int) -> dict:
    """Scan ``number``: what it is, and per way its volumetric IoU, silhouette IoU per view and error."""
    scene, distance, near, band = scene_of(number)
    K = default_K(SIZE, FOCAL)
    poses = plan_views(scene.centre, 3, (distance, distance * 1.15), ELEVATIONS[band],
                       float(np.random.default_rng(number).uniform(0, 360)), np.random.default_rng([number, 1]))
    images, truths = zip(*(render_view(scene, T, K, SIZE, number * 100 + i) for i, T in enumerate(poses)))
    empty = Scene(**{**scene.__dict__, "with_object": False})
    backgrounds = [render_view(empty, T, K, SIZE, number * 100 + 50 + i)[0] for i, T in enumerate(poses)]
    cameras = [Camera(K, T, view=i) for i, T in enumerate(poses)]
    same_colour = float(np.abs(np.subtract(scene.object_bgr, scene.table_bgr)).max()) < 30
    record: dict = {"shape": scene.shape, "print": scene.object_print, "table": scene.table_texture,
                    "table's colour": same_colour, "near": near, "views from": band,
                    "share": float(np.mean([np.mean(t > 0) for t in truths]))}
    for way in WAYS:
        if way == "true masks":
            views = [View(camera, mask=truth) for camera, truth in zip(cameras, truths)]
        else:
            views = [View(camera, image=image, background=background if way == "+ background" else None)
                     for camera, image, background in zip(cameras, images, backgrounds)]
        entry: dict = {"iou": 0.0, "views": [0.0] * len(truths), "error": None, "set aside": None}
        try:
            result = reconstruct(views, support_plane=[0.0, 0.0, 1.0, 0.0])
        except Exception as exc:  # a failed reconstruction scores 0; its message is shown
            entry["error"] = f"{type(exc).__name__}: {exc}"
        else:
            entry["set aside"] = result.backgrounds_set_aside
            entry["iou"] = union_iou(model_parts(result), truth_of(scene))
            entry["views"] = [float(((s > 0) & (t > 0)).sum() / max(1, ((s > 0) | (t > 0)).sum()))
                              for s, t in zip(result.silhouettes, truths)]
        record[way] = entry
    return record


def _cells(values) -> str:
    if not len(values):
        return f"{'-':>9}{'-':>8}{'-':>7}"
    return f"{np.mean(values):>9.3f}{np.min(values):>8.3f}{sum(v < 0.85 for v in values):>7}"


def tables(records: list[dict]) -> None:
    groups: dict[str, list[dict]] = defaultdict(list)
    for record in records:
        groups[f"table {record['table']}"].append(record)
        groups[f"print {record['print']}"].append(record)
        groups[record["shape"]].append(record)
        groups["the table's colour" if record["table's colour"] else "another colour"].append(record)
        groups["near" if record["near"] else "far"].append(record)
        groups[record["views from"]].append(record)
    groups = {name: groups[name] for name in sorted(groups)}
    groups["all"] = records
    seeing = WAYS[:2]
    print(f"\n(a) silhouette IoU per view against the true silhouette, {3 * len(records)} views of "
          f"{len(records)} scans (under: views under 0.85)")
    print(f"{'':<22}{'scans':>6}" + "".join(f"{way:>24}" for way in seeing))
    print(f"{'':<28}" + "".join(f"{'mean':>9}{'worst':>8}{'under':>7}" for _ in seeing))
    for name, group in groups.items():
        print(f"{name:<22}{len(group):>6}" + "".join(_cells([v for r in group for v in r[way]["views"]])
                                                    for way in seeing))
    print("\n(b) volumetric IoU against the true object (failed reconstructions score 0; under: scans under 0.85)")
    print(f"{'':<22}{'scans':>6}" + "".join(f"{way:>24}" for way in WAYS))
    print(f"{'':<28}" + "".join(f"{'mean':>9}{'worst':>8}{'under':>7}" for _ in WAYS))
    for name, group in groups.items():
        print(f"{name:<22}{len(group):>6}" + "".join(_cells([r[way]["iou"] for r in group]) for way in WAYS))
    set_aside = [(r["number"], r["+ background"]["set aside"]) for r in records if r["+ background"].get("set aside")]
    if set_aside:
        print("\nbackgrounds set aside (the silhouettes cut against them failed; found from the images alone):")
        for number, message in set_aside:
            print(f"  scan {number}: {message[:110]}")
    errors = [(r["number"], way, r[way]["error"]) for r in records for way in WAYS if r[way]["error"]]
    if errors:
        print("\nfailures:")
        for number, way, message in errors:
            print(f"  scan {number} ({way}): {message[:110]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scans", type=int, default=24, help="how many scans (default 24)")
    parser.add_argument("--first", type=int, default=0, help="the first scan's number (default 0)")
    parser.add_argument("--record", type=Path, help="write each scan's scores as JSON")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    records = []
    for number in range(args.first, args.first + args.scans):
        records.append({"number": number, **score(number)})
        if args.record:
            args.record.write_text(json.dumps(records, indent=1))
    print(f"`auto` on {len(records)} scans from tests/seg_scenes.py (a renderer written apart), scans "
          f"{args.first}-{args.first + args.scans - 1}")
    tables(records)


if __name__ == "__main__":
    main()
