"""Benchmark of the grasp planner: does its best grasp hold the true object?

    .venv/bin/python bench/bench_grasp.py [--per-family N] [--seed S] [--views 3 6] [--show-failures]

For every scene of `workers.sim.grasp_set` (graspable superquadrics, standing
plates, lying cylinders, compound objects, and objects too big for the
gripper) at each view count: render the scan bundle, reconstruct it with the
real pipeline, plan grasps on the reconstruction, and judge the best one
against the true object with workers/sim/judge.py (the DESIGN.md §3 "holds"
test, written apart from the planner). An object too big for the gripper is
handled correctly when the list is empty.

Beside it, the ceiling: the same planner on the true model (its error taken as
nil). For a compound object, whose truth is several superquadrics and no
single one, the true model is the superquadric fitted (plain Jaklic cost) to
points on the true object's surface, and those points stand in for the hull:
the best the planner could be given.

Planning time runs on one core (this process is pinned to CPU 0); since the
machine may be busy, it is also given as a fraction of the reconstruction's
own time in the same run. Prints tables; asserts nothing.
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from robocell.workers.sim.judge import JudgeGripper, judge, parts_from_truth  # noqa: E402

from robocell.wire.bundle import load_bundle  # noqa: E402
from robocell.workers.sim.grasp_set import GRASPABLE, TOO_BIG, grasp_set  # noqa: E402
from robocell.workers.sim.objects import COMPOUNDS  # noqa: E402
from robocell.core_cy.grasp import DEFAULT_GRIPPER, plan_grasps  # noqa: E402
from robocell.core_cy.reconstruct import reconstruct  # noqa: E402
from robocell.core_cy.superquadric import Superquadric, fit_superquadric  # noqa: E402

GROUPS = {
    "superquadrics": ("box", "cylinder", "ellipsoid", "rounded-box", "plate", "lying-cylinder"),
    "compounds": tuple(COMPOUNDS),
}


def true_model(obj, plane) -> tuple[Superquadric, np.ndarray | None]:
    """The superquadric to plan on as the ceiling, and the true surface's points standing in
    for the hull (see the module docstring)."""
    truth = obj.truth()
    if "parts" not in truth:
        return Superquadric.from_dict(truth), None
    vertices = np.concatenate([part.mesh()[0] for part in obj.parts])
    # Keep the union's surface: a part's vertex inside another part is not on it.
    outside = np.ones(len(vertices), bool)
    start = 0
    for k, part in enumerate(obj.parts):
        count = len(part.mesh()[0])
        for other_index, other in enumerate(obj.parts):
            if other_index != k:
                outside[start:start + count] &= ~other.inside(vertices[start:start + count] * 1.0)
        start += count
    surface = vertices[outside][:: max(1, outside.sum() // 2000)]
    fit = fit_superquadric(surface, inside_weight=1.0, outside_loss="squared", support_plane=plane)
    return fit.superquadric, surface


def best_verdict(grasps, parts, plane, contacts="patch"):
    if not grasps:
        return None
    return judge(grasps[0].T_world_grasp, parts, JudgeGripper.from_dict(DEFAULT_GRIPPER.to_dict()), plane,
                 mu=DEFAULT_GRIPPER.friction, contacts=contacts)


READINGS = ("patch", "centre-line")


def _held(family: str, grasps, parts, plane) -> dict[str, bool]:
    """Per reading of the contacts: is the scene handled? (too-big: an empty list)."""
    if family == TOO_BIG:
        return {reading: not grasps for reading in READINGS}
    verdicts = {reading: best_verdict(grasps, parts, plane, reading) for reading in READINGS}
    return {reading: v is not None and v.holds for reading, v in verdicts.items()}


def _table(held, families, columns, reading: str) -> None:
    print(f"{'family':<16}" + "".join(f"{f'{c} views' if c != 'ceiling' else 'ceiling':>12}" for c in columns))
    for family in families:
        print(f"{family:<16}" + "".join(f"{100 * np.mean(held[reading, family, c]):>11.1f}%" for c in columns))
    for group, members in GROUPS.items():
        row = f"{'all ' + group:<16}"
        for c in columns:
            row += f"{100 * np.mean(sum((held[reading, f, c] for f in members), [])):>11.1f}%"
        print(row)
    print("(worst family: " + ", ".join(
        f"{c}: {min(GRASPABLE, key=lambda f: np.mean(held[reading, f, c]))} "
        f"{100 * min(np.mean(held[reading, f, c]) for f in GRASPABLE):.0f}%" for c in columns) + ")")


def run(seed: int, per_family: int, views: list[int], out: Path, show_failures: bool, min_score: float | None,
        record: str | None) -> None:
    cv2.setNumThreads(1)
    families = (*GRASPABLE, TOO_BIG)
    held = defaultdict(list)  # (reading, family, views or "ceiling") -> [bool]
    plan_ms, part_ms, ratio = [], [], []
    failures, records = [], []
    for n_views in views:
        for spec in grasp_set(seed, per_family, n_views, families):
            family = spec.name.rsplit("-", 1)[0]
            obj = spec.objects[0]
            parts = parts_from_truth(obj.truth())
            bundle = load_bundle(spec.write(out / f"v{n_views}"))
            plane = bundle.support_plane
            result = reconstruct(bundle.views, segmentation=bundle.segmentation, support_plane=plane)
            start = time.perf_counter()
            options = {} if min_score is None else {"min_score": min_score}
            # On the model's parts (DESIGN.md §1.11): one for an object that is one superquadric.
            grasps = plan_grasps(result.parts, plane, residual=result.residual,
                                 silhouette_iou=result.silhouette_iou, points=result.points, **options)
            ms = (time.perf_counter() - start) * 1e3
            plan_ms.append(ms)
            part_ms.append(ms / len(result.parts))
            ratio.append(ms / result.timings_ms["total"])
            ok = _held(family, grasps, parts, plane)
            for reading in READINGS:
                held[reading, family, n_views].append(ok[reading])
            verdict = best_verdict(grasps, parts, plane)
            records.append({"family": family, "name": spec.name, "views": n_views, "grasps": len(grasps),
                            "score": grasps[0].score if grasps else None, **ok,
                            "reason": None if verdict is None else verdict.reason,
                            "residual": result.residual, "iou": float(np.mean(result.silhouette_iou))})
            if not ok["patch"]:
                why = ("empty list" if verdict is None else
                       f"{'holds' if verdict.holds else verdict.reason} (score {grasps[0].score:.2f})")
                failures.append((n_views, spec.name, why, result))
            if n_views == views[0]:
                model, surface = true_model(obj, plane)
                ceiling = _held(family, plan_grasps(model, plane, points=surface), parts, plane)
                for reading in READINGS:
                    held[reading, family, "ceiling"].append(ceiling[reading])
    if record:
        Path(record).write_text(json.dumps(records))

    columns = [*views, "ceiling"]
    print(f"\nBest grasp judged against the true object, {per_family} scenes per family, seed {seed} "
          "(too-big: % with an empty list)")
    print("\ncontacts where the pads first touch (workers/sim/judge.py, the default):")
    _table(held, families, columns, "patch")
    print("\ncontacts where the pads' centre line meets the object (the Dex-Net reading):")
    _table(held, families, columns, "centre-line")
    print(f"\nplanning time, one core (CPU 0), {len(plan_ms)} scans: median {np.median(plan_ms):.2f} ms, "
          f"p90 {np.percentile(plan_ms, 90):.2f} ms, worst {np.max(plan_ms):.2f} ms; as a fraction of the "
          f"same scan's reconstruction: median {np.median(ratio):.2f}, worst {np.max(ratio):.2f}; per part of the "
          f"model: median {np.median(part_ms):.2f} ms, worst {np.max(part_ms):.2f} ms")
    if show_failures:
        print("\nfailures (first-touch contacts):")
        for n_views, name, why, result in failures:
            sq = result.superquadric
            print(f"  {n_views} views {name:<20} {why}; model size {np.round(sq.size * 100, 1).tolist()} cm, "
                  f"shape {np.round(sq.shape, 2).tolist()}, residual {result.residual * 1000:.1f} mm, "
                  f"IoU {np.mean(result.silhouette_iou):.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--per-family", type=int, default=20, help="scenes per family (default 20)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the scene set (default 0)")
    parser.add_argument("--views", type=int, nargs="+", default=[3, 6], help="view counts (default 3 6)")
    parser.add_argument("--keep", help="write the bundles here instead of a temporary directory")
    parser.add_argument("--min-score", type=float, help="the planner's min_score (default: the planner's own)")
    parser.add_argument("--record", metavar="FILE", help="write each scene's result here, as JSON")
    parser.add_argument("--show-failures", action="store_true", help="list every scene whose best grasp fails")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {0})
    print(f"robocell grasp benchmark: gripper {DEFAULT_GRIPPER.to_dict()}")
    with tempfile.TemporaryDirectory() as scratch:
        run(args.seed, args.per_family, args.views, Path(args.keep or scratch), args.show_failures, args.min_score,
            args.record)


if __name__ == "__main__":
    main()
