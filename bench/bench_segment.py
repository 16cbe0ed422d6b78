"""Benchmark of finding the object without being told its colour: printed objects on real-looking tables.

    .venv/bin/python bench/bench_segment.py [--seeds 0 1] [--keep DIR] [--no-timing] [--ways ...] [--record FILE]

Over `robocell sim scans --set printed` (workers.sim.scans.printed_set, for each seed: 16 grocery-like
printed objects on oak, a rubber mat, white laminate, a cutting mat, and the classic wood and fabric, lit
by one lamp that casts their shadow, 3 to 6 views, lens blur, sensor noise, JPEG; the bundles name no
segmentation, so the reconstruction uses its default), three ways:

- "default": the bundle as a user would give it, images, poses and the support plane only;
- "+ background": the same, each view also naming a picture of the empty workspace (same pose, same lamp);
- "true masks": the true silhouettes supplied as masks (the ceiling: what the fit makes of perfect eyes).

(a) silhouette IoU of each view's silhouette (the one the reconstruction carved from) against the true
    silhouette (the renderer's area-true coverage at one half), per table kind, mean and worst;
(b) volumetric IoU of the model (its union of parts, as `robocell reconstruct` gives it) against the true
    object (workers/sim/judge.py's Monte Carlo union_iou, written apart from the fit) per table kind and
    per object kind, mean and worst, beside the ceiling, and whether the best grasp, planned on the union
    as the cell and `robocell reconstruct --grasps` plan it, holds the true object (the same judge); also
    counted over the objects the gripper's opening spans (some true part narrower than it by a millimetre
    across the table: a grasp closing across the table holds no tuna can 85 mm across in an 85 mm gripper,
    whatever its model);
(c) speed: `robocell reconstruct` on the 3-view 640x480 JPEG bundles, from outside, one core
    (taskset -c 0), as a ratio to OpenCV's decode of the same three JPEGs on the same core, measured
    in the same run, over the bundles that reconstruct; beside it the same bundles with their true
    silhouettes given as masks (the fit's own cost, no segmentation) and the classic red HSV bundles of
    the standard set, for reference.

(d) the same tables (a) and (b) over `robocell sim scans --set printed-products`
    (workers.sim.scans.printed_products_set): the YCB-like products in parts (a mug and its handle, a
    drill, a hammer, a banana, bottles, boxes, cans) wearing the printed looks on the same tables under
    such a lamp, three views; grouped by table and by product. The printed set's objects are each one
    superquadric; a robot's shelf holds these too.

A reconstruction that fails scores 0 and is counted. Prints tables; asserts nothing. Rendering takes a few
minutes: --keep DIR keeps the bundles (and reuses them when DIR already holds them). --record FILE writes
each scan's scores (per way: volumetric IoU, silhouette IoU per view, grasp verdict, error) as JSON, so
that two runs can be compared scan by scan and view by view (bench/compare_segment.py).
"""

from __future__ import annotations

import os

# One core: the numbers must not depend on how many threads BLAS or OpenCV would take.
for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_core import model_parts  # noqa: E402

from robocell.core_cy.grasp import DEFAULT_GRIPPER, plan_grasps  # noqa: E402
from robocell.core_cy.reconstruct import View, reconstruct  # noqa: E402
from robocell.wire.bundle import load_bundle  # noqa: E402
from robocell.workers.sim.judge import (  # noqa: E402
    JudgeGripper, judge, parts_from_truth, surface_points, union_iou)
from robocell.workers.sim.scans import printed_products_set, printed_set, standard_set  # noqa: E402

WAYS = ("default", "+ background", "true masks")
SEEING = WAYS[:2]  # the ways that segment the images
#: An object the gripper spans is narrower than its opening by this much at least (m): fingers that come down
#: grazing its sides push it away.
CLEARANCE = 0.001


def write_bundles(specs, out: Path) -> list[tuple]:
    """Each spec as two bundles: ``out/background/NAME`` (views name their backgrounds) and
    ``out/plain/NAME`` (the same files, scan.json without them). Rendered unless already there."""
    pairs = []
    for spec in specs:
        with_bg, plain = out / "background" / spec.name, out / "plain" / spec.name
        if not (with_bg / "truth.json").exists():
            spec.write(out / "background", backgrounds=True)
        if not (plain / "truth.json").exists():
            plain.mkdir(parents=True, exist_ok=True)
            for item in with_bg.iterdir():
                if item.name != "scan.json" and not item.name.startswith("background"):
                    shutil.copy2(item, plain / item.name)
            scan = json.loads((with_bg / "scan.json").read_text())
            for view in scan["views"]:
                view.pop("background", None)
            (plain / "scan.json").write_text(json.dumps(scan, indent=1))
        pairs.append((spec, plain, with_bg))
    return pairs


def best_grasp_holds(result, obj, plane) -> bool:
    grasps = plan_grasps(result.parts, plane, residual=result.residual,
                         silhouette_iou=result.silhouette_iou, points=result.points)
    if not grasps:
        return False
    verdict = judge(grasps[0].T_world_grasp, parts_from_truth(obj.truth()),
                    JudgeGripper.from_dict(DEFAULT_GRIPPER.to_dict()), plane, mu=DEFAULT_GRIPPER.friction)
    return bool(verdict.holds)


def narrowest_width(parts, plane) -> float:
    """How far a parallel gripper closing across the table must open to hold the object by its narrowest true
    part (m): the least width of that part's outline on the table, over directions a degree apart (its surface
    by its signed-power parametrisation, on a grid that holds the ends of its own axes, projected on the
    plane). An object wider than the gripper's opening every way across the table is not held by a grasp closing
    across it, however good its model: only by one tilted over an edge, if at all."""
    normal = np.asarray(plane[:3], float) / np.linalg.norm(plane[:3])
    across = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    along = np.cross(normal, across)
    angles = np.radians(np.arange(180.0))
    directions = np.outer(np.cos(angles), across) + np.outer(np.sin(angles), along)
    widths = []
    for part in parts:
        # The judge's own sampling of a part's surface; 33 x 128 holds the ends of the part's axes.
        projected = surface_points(part, n_eta=33, n_omega=128) @ directions.T
        widths.append(float(np.min(projected.max(axis=0) - projected.min(axis=0))))
    return min(widths)


def score(spec, plain: Path, with_bg: Path, ways=WAYS) -> dict:
    """{way: {"iou", "views" (silhouette IoU per view), "holds", "error", "spanned"}} for one scan, each of
    ``ways``; "spanned", the same for every way: whether the gripper's opening spans the object's narrowest
    true part across the table (:func:`narrowest_width`)."""
    obj = spec.objects[0]
    truths = [cv2.imread(str(plain / f"truth_mask{i}.png"), cv2.IMREAD_GRAYSCALE) > 0
              for i in range(len(spec.cameras))]
    spanned = (narrowest_width(parts_from_truth(obj.truth()), load_bundle(plain).support_plane)
               <= DEFAULT_GRIPPER.max_opening - CLEARANCE)
    out = {}
    for way in ways:
        entry: dict = {"iou": 0.0, "views": [0.0] * len(truths), "holds": False, "error": None, "spanned": spanned}
        try:
            bundle = load_bundle(with_bg if way == "+ background" else plain)
            views = bundle.views
            if way == "true masks":
                views = [View(v.camera, mask=(plain / f"truth_mask{i}.png").read_bytes())
                         for i, v in enumerate(bundle.views)]
            result = reconstruct(views, segmentation=bundle.segmentation, support_plane=bundle.support_plane)
        except Exception as exc:  # a failed reconstruction scores 0; its message is shown
            entry["error"] = f"{type(exc).__name__}: {exc}"
        else:
            entry["iou"] = union_iou(model_parts(result), parts_from_truth(obj.truth()))
            entry["views"] = [float((s > 0)[t].sum() / max(1, ((s > 0) | t).sum()))
                              for s, t in zip(result.silhouettes, truths)]
            entry["holds"] = best_grasp_holds(result, obj, bundle.support_plane)
        out[way] = entry
    return out


def _cells(values) -> str:
    return f"{np.mean(values):>9.3f}{np.min(values):>8.3f}" if len(values) else f"{'-':>9}{'-':>8}"


def tables(records: list[tuple], ways=WAYS) -> None:
    """records: (spec, scores), the scores of each of ``ways``."""
    seeing = [way for way in ways if way in SEEING]
    by_table, by_object = defaultdict(list), defaultdict(list)
    for spec, s in records:
        by_table[spec.table_kind].append(s)
        by_object[spec.object_kind].append(s)
    n_views = sum(len(spec.cameras) for spec, _ in records)
    print(f"\n(a) silhouette IoU per view against the true silhouette, {n_views} views of {len(records)} scans")
    print(f"{'table':<16}" + "".join(f"{way:>17}" for way in seeing))
    print(f"{'':<16}" + "".join(f"{'mean':>9}{'worst':>8}" for _ in seeing))
    for group, scans in [*sorted(by_table.items()), ("all", [s for _, s in records])]:
        print(f"{group:<16}" + "".join(_cells([v for s in scans for v in s[way]["views"]]) for way in seeing))
    for title, groups in (("table", by_table), ("object", by_object)):
        print(f"\n(b) volumetric IoU against the true object, per {title} kind (failed reconstructions score 0)")
        print(f"{title:<16}{'scans':>6}" + "".join(f"{way:>17}" for way in ways))
        print(f"{'':<22}" + "".join(f"{'mean':>9}{'worst':>8}" for _ in ways))
        for group, scans in [*sorted(groups.items()), ("all", [s for _, s in records])]:
            print(f"{group:<16}{len(scans):>6}" + "".join(_cells([s[way]["iou"] for s in scans]) for way in ways))
    print(f"\n{'':<22}" + "".join(f"{way:>17}" for way in ways))
    print(f"{'failed':<22}" + "".join(f"{sum(s[way]['error'] is not None for _, s in records):>17}" for way in ways))
    held = [f"{sum(s[way]['holds'] for _, s in records)} of {len(records)}" for way in ways]
    print(f"{'best grasp holds':<22}" + "".join(f"{h:>17}" for h in held))
    spanned = [(spec, s) for spec, s in records if s[ways[0]]["spanned"]]
    if len(spanned) < len(records):
        held = [f"{sum(s[way]['holds'] for _, s in spanned)} of {len(spanned)}" for way in ways]
        print(f"{'  of those spanned':<22}" + "".join(f"{h:>17}" for h in held))
        wide = sorted({spec.object_kind for spec, s in records if not s[ways[0]]["spanned"]})
        print(f"  (not spanned: no part of {', '.join(wide)} is narrower than the gripper's opening of "
              f"{DEFAULT_GRIPPER.max_opening * 1e3:.0f} mm by {CLEARANCE * 1e3:.0f} mm)")
    errors = defaultdict(list)
    for spec, s in records:
        for way in ways:
            if s[way]["error"] is not None:
                errors[s[way]["error"][:100]].append(f"{spec.name} ({way})")
    if errors:
        print("\nfailures:")
        for message, where in sorted(errors.items(), key=lambda item: -len(item[1])):
            print(f"  {len(where):>3} x {message}\n        e.g. {', '.join(where[:3])}")


def _decode_ms(jpegs: list[list[bytes]], repeat: int = 5) -> float:
    """Median time (ms) OpenCV takes to decode one bundle's JPEGs, on this process's core."""
    times = []
    for _ in range(repeat):
        for bundle in jpegs:
            start = time.perf_counter()
            for data in bundle:
                cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
            times.append((time.perf_counter() - start) * 1e3)
    return float(np.median(times))


def _outside_ms(dirs: list[Path], pin: list[str], lines: int = 30) -> tuple[np.ndarray, int]:
    """The wall times (ms) between `robocell reconstruct`'s output lines over ``lines`` bundles (each one
    bundle's reconstruction), and how many of the lines were errors."""
    robocell = Path(sys.executable).with_name("robocell")
    args = [str(d) for d in (dirs * (lines // len(dirs) + 1))[:lines]]
    process = subprocess.Popen([*pin, str(robocell), "reconstruct", *args], stdout=subprocess.PIPE,
                               stderr=subprocess.DEVNULL, text=True)
    stamps, errors = [], 0
    assert process.stdout is not None
    for line in process.stdout:
        stamps.append(time.perf_counter())
        errors += "error" in json.loads(line)
    process.wait()
    return np.diff(stamps) * 1e3, errors


def masks_bundle(plain: Path, out: Path) -> Path:
    """``plain``'s scan with its true silhouettes for masks in place of its images, at ``out``: what
    `robocell reconstruct` costs when the segmentation is given (made unless already there)."""
    if not (out / "scan.json").exists():
        out.mkdir(parents=True, exist_ok=True)
        scan = json.loads((plain / "scan.json").read_text())
        for i, view in enumerate(scan["views"]):
            del view["image"]
            view["mask"] = f"truth_mask{i}.png"
            shutil.copy2(plain / view["mask"], out / view["mask"])
        (out / "scan.json").write_text(json.dumps(scan, indent=1))
    return out


def timing(groups: dict[str, tuple[list[Path], list[Path]]]) -> None:
    """Per group, (the bundles reconstructed, the bundles whose JPEGs are decoded beside them)."""
    cv2.setNumThreads(1)
    pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {0})  # the decode runs on the same core as the reconstructions
    print(f"\n(c) `robocell reconstruct` from outside{', one core (taskset -c 0)' if pin else ''}, 3 views of "
          "640x480 JPEG a bundle: wall time between output lines (over 30: median, mean and worst), beside OpenCV "
          "decoding the same three JPEGs on the same core just before and after (median); the ratio is the "
          "median's")
    print(f"{'bundles':<34}{'reconstruct ms':>16}{'mean':>9}{'worst':>9}{'decode ms':>12}{'ratio':>8}{'errors':>8}")
    for name, (dirs, decoded) in groups.items():
        if not dirs:
            continue
        jpegs = []
        for d in decoded:
            scan = json.loads((d / "scan.json").read_text())
            jpegs.append([(d / v["image"]).read_bytes() for v in scan["views"]])
        before = _decode_ms(jpegs)
        times, errors = _outside_ms(dirs, pin)
        outside = float(np.median(times))
        decode = (before + _decode_ms(jpegs)) / 2
        print(f"{name:<34}{outside:>16.2f}{times.mean():>9.2f}{times.max():>9.2f}{decode:>12.2f}"
              f"{outside / decode:>8.2f}{errors:>8}")
    print("  (decode: the three views' JPEGs; a bundle with backgrounds has three more to read; the true masks'\n"
          "   bundles are the default's with the true silhouettes, PNG, in place of the images: the fit's own cost,\n"
          "   beside the decode of the images they stand for)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1],
                        help="printed_set and printed_products_set seeds (default 0 1)")
    parser.add_argument("--sets", nargs="+", choices=("printed", "products"), default=["printed", "products"],
                        help="which sets to score (default both)")
    parser.add_argument("--keep", type=Path, metavar="DIR", help="keep the bundles here (reused when present)")
    parser.add_argument("--no-timing", action="store_true", help="skip the speed table")
    parser.add_argument("--ways", nargs="+", choices=("default", "background", "masks"),
                        default=["default", "background", "masks"], help="which ways to score (default all three)")
    parser.add_argument("--record", type=Path, metavar="FILE", help="write each scan's scores here, as JSON")
    args = parser.parse_args()
    ways = [way for way, short in zip(WAYS, ("default", "background", "masks")) if short in args.ways]
    cv2.setNumThreads(1)
    work = args.keep or Path(tempfile.mkdtemp(prefix="bench_segment_"))
    try:
        recorded: dict[str, dict] = {}
        records, pairs = [], []
        for set_name, make, prefix in (("printed", printed_set, ""), ("products", printed_products_set, "products-")):
            if set_name not in args.sets:
                continue
            scored, written = [], []
            for seed in args.seeds:
                for spec, plain, with_bg in write_bundles(make(seed), work / f"{set_name}-{seed}"):
                    written.append((spec, plain, with_bg))
                    scored.append((spec, score(spec, plain, with_bg, ways)))
                    recorded[f"{prefix}{seed}/{spec.name}"] = scored[-1][1]
            default = load_bundle(written[0][1]).segmentation
            print(f"\n== {make.__name__} seeds {args.seeds}: {len(scored)} scans; the bundles' default segmentation "
                  f"here is {default.method!r}")
            tables(scored, ways)
            if set_name == "printed":
                records, pairs = scored, written
        if args.record:
            args.record.write_text(json.dumps(recorded, indent=1))
        if not args.no_timing and set(SEEING) <= set(ways) and records:
            # Bundles that reconstruct: a failing one stops early and would flatter the time.
            def timed(way: str, column: int) -> list[Path]:
                return [pair[column] for pair, (_, s) in zip(pairs, records)
                        if len(pair[0].cameras) == 3 and s[way]["error"] is None][:8]

            red = []
            for spec in standard_set(0)[:24:4]:
                path = work / "standard" / spec.name
                if not (path / "scan.json").exists():
                    spec.write(work / "standard")
                red.append(path)
            plain = timed("default", 1)
            given = [masks_bundle(d, work / "masks-timing" / f"{d.parents[1].name}-{d.name}") for d in plain]
            timing({"printed, default segmentation": (plain, plain),
                    "printed, + background": (timed("+ background", 2),) * 2,
                    "printed, true masks given": (given, plain),
                    "red standard set, hsv (reference)": (red, red)})
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
