"""Benchmark of the model in parts (DESIGN.md §1.11) beside one superquadric, in the same run, on one core.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_parts.py [--keep DIR] [--per-kind N] [--views 3 4 6]

For every scan: the reconstruction with one superquadric (``Options(max_parts=1)``, as before parts
existed) and with parts (the default), each timed in process (best of ``--repeat``, interleaved, on
one core). Scored by the judge (workers/sim/judge.py, written apart from the fit): volumetric IoU of
the model's union against the true union. Sets: the everyday compound objects of
``workers.sim.scans.compound_set`` (and the older ``COMPOUNDS``: cups, mug, box and ball, L) per number
of views, and the superquadric scans of the standard set (how often one is split; its cup stacks and
lumpy figures have no superquadric truth to score a union against, and are left out). Prints, per kind:
IoU mean and worst (one superquadric / parts), parts used, and the time of parts over one
superquadric (median; for the scans that stayed one part, and for those of up to four parts), and the
silhouette fits' evaluations of their cost (each part of a union counted; deterministic, unlike the
times) with parts over those of one superquadric. Then the YCB-like products
(``workers.sim.scans.ycb_like_set``: the YCB set's sizes as unions of superquadrics) the same way.
With ``--today DIR`` (a built checkout of the code before parts, e.g. ``git worktree add DIR 4747abe^``), the same bundles
are also timed by that code in a child process on the same core, in the same run, and the time of
parts is given over that too. Asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from robocell.core_cy.reconstruct import Options, reconstruct
from robocell.wire.bundle import load_bundle
from robocell.workers.sim.judge import Part, parts_from_truth, union_iou
from robocell.workers.sim.objects import COMPOUNDS, compound
from robocell.workers.sim.scans import compound_set, make_spec, standard_set, ycb_like_set


def _written(spec, out: Path):
    path = out / spec.name
    if not (path / "truth.json").exists():
        spec.write(out, write_masks=True)
    return load_bundle(path)


def _timed(bundle, options: Options, repeat: int):
    best, result = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        result = reconstruct(bundle.views, segmentation=bundle.segmentation, support_plane=bundle.support_plane,
                             options=options)
        best = min(best, time.perf_counter() - start)
    return result, best * 1e3


# The code before parts kept core_cy and wire at the top of the tree, not under robocell (whose editable
# install would otherwise hand the child this tree's code under the other name).
_TODAY = """
import importlib, json, sys, time
from pathlib import Path
tree, prefix = Path(sys.argv[1]).resolve(), sys.argv[2]
module = importlib.import_module(prefix + "core_cy.reconstruct")
if tree not in Path(module.__file__).resolve().parents:
    sys.exit(f"{module.__file__} is not the code of {tree}")
reconstruct = module.reconstruct
load_bundle = importlib.import_module(prefix + "wire.bundle").load_bundle
out = {}
for path in sys.argv[4:]:
    bundle = load_bundle(path)
    best = float("inf")
    for _ in range(int(sys.argv[3])):
        start = time.perf_counter()
        try:
            reconstruct(bundle.views, segmentation=bundle.segmentation, support_plane=bundle.support_plane)
        except Exception as exc:  # that code's own limits (a hammer lying flat under its table check)
            print(f"{path}: {exc}", file=sys.stderr)
            break
        best = min(best, time.perf_counter() - start)
    out[path] = best * 1e3 if best < float("inf") else None
print(json.dumps(out))
"""


def time_today(tree: Path, paths, repeat: int) -> dict:
    """{bundle path: ms} of the default reconstruction of the code in ``tree``, in a child on this core."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    prefix = "robocell." if (tree / "robocell" / "core_cy").exists() else ""
    done = subprocess.run([sys.executable, "-c", _TODAY, str(tree), prefix, str(repeat), *map(str, paths)], env=env, cwd=tree,
                          capture_output=True, text=True, check=True, timeout=3600)
    return json.loads(done.stdout.strip().splitlines()[-1])


def _as_parts(model) -> list[Part]:
    return [Part.from_dict(part.to_dict()) for part in model]


def measure(specs, out: Path, repeat: int, today: Path | None = None):
    """{kind: [(iou one, iou parts, parts used, ms one, ms parts, ms today, evaluations one, with parts)]}"""
    rows = defaultdict(list)
    bundles = [_written(spec, out) for spec in specs]
    today_ms: dict = {}
    for spec, bundle in zip(specs, bundles):
        truth = parts_from_truth(spec.objects[0].truth())
        # Interleaved scan by scan, so that the machine's load falls on all three alike.
        if today:
            today_ms.update(time_today(today, [bundle.path], repeat))
        one, ms_one = _timed(bundle, Options(max_parts=1), repeat)
        many, ms_many = _timed(bundle, Options(), repeat)
        kind = spec.name.rsplit("-", 1)[0]
        rows[kind].append((union_iou(_as_parts([one.superquadric]), truth), union_iou(_as_parts(many.parts), truth),
                           len(many.parts), ms_one, ms_many, today_ms.get(str(bundle.path)) or np.nan,
                           one.evaluations["fit"], many.evaluations["fit"] + many.evaluations.get("parts", 0)))
    return rows


def table(title: str, rows) -> None:
    if not rows:
        return  # nothing measured (--per-kind 0: the standard set alone)
    print(f"\n{title}")
    print(f"{'kind':<16}{'one sq: mean':>13}{'worst':>7}{'parts: mean':>13}{'worst':>7}{'parts used':>12}"
          f"{'time x':>8}{'evals x':>9}")
    every = []
    for kind, values in rows.items():
        v = np.array(values)
        every.append(v)
        used = ",".join(str(int(n)) for n in v[:, 2])
        print(f"{kind:<16}{v[:, 0].mean():>13.3f}{v[:, 0].min():>7.3f}{v[:, 1].mean():>13.3f}{v[:, 1].min():>7.3f}"
              f"{used:>12}{np.median(v[:, 4] / v[:, 3]):>8.2f}{np.median(v[:, 7] / v[:, 6]):>9.2f}")
    v = np.concatenate(every)
    print(f"{'all':<16}{v[:, 0].mean():>13.3f}{v[:, 0].min():>7.3f}{v[:, 1].mean():>13.3f}{v[:, 1].min():>7.3f}"
          f"{'max ' + str(int(v[:, 2].max())):>12}{np.median(v[:, 4] / v[:, 3]):>8.2f}{np.median(v[:, 7] / v[:, 6]):>9.2f}")
    one, few = v[:, 2] == 1, (v[:, 2] > 1) & (v[:, 2] <= 4)
    for label, pick in (("stayed one part", one), ("2-4 parts", few)):
        if not pick.any():
            continue
        for over, column in (("max_parts=1 here", 3), ("today's code", 5)):
            timed = pick & np.isfinite(v[:, column])  # the code before parts fails on a few scans
            ratio = v[timed, 4] / v[timed, column]
            if len(ratio):
                print(f"  time of parts over {over}, {label} ({timed.sum()} scans): median {np.median(ratio):.2f}x, "
                      f"worst {ratio.max():.2f}x (parts: median {np.median(v[timed, 4]):.1f} ms, "
                      f"{over}: {np.median(v[timed, column]):.1f} ms)")
        work = v[pick, 7] / v[pick, 6]
        print(f"  evaluations with parts over one superquadric, {label}: median {np.median(work):.2f}x, "
              f"worst {work.max():.2f}x")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--keep", type=Path, help="keep the simulated sets here (and reuse them)")
    parser.add_argument("--per-kind", type=int, default=2, help="scans per compound kind (default 2)")
    parser.add_argument("--views", type=int, nargs="+", default=[3], help="numbers of views (default 3)")
    parser.add_argument("--repeat", type=int, default=2, help="timing passes per scan, best kept (default 2)")
    parser.add_argument("--skip-standard", action="store_true", help="leave out the standard set's superquadrics")
    parser.add_argument("--skip-ycb", action="store_true", help="leave out the YCB-like products")
    parser.add_argument("--today", type=Path, help="a built checkout of the code before parts, timed beside")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    out = args.keep or Path(tempfile.mkdtemp(prefix="bench_parts_"))
    out.mkdir(parents=True, exist_ok=True)
    for views in args.views:
        specs = compound_set(0, per_kind=args.per_kind, n_views=views)
        for name in COMPOUNDS:
            for i in range(args.per_kind):
                obj = compound(name, (0.6, 0.0), yaw_deg=37.0 * i, seed=i)
                specs.append(make_spec(f"{name}-{views}v-{i:02d}", obj, seed=500 + i, n_views=views))
        table(f"compound objects, {views} views all around: volumetric IoU against the true union",
              measure(specs, out / f"compound-{views}", args.repeat, args.today))
    if not args.skip_standard:
        specs = [s for s in standard_set(0) if not s.name.startswith(("cup-stack", "lumpy"))]
        table("superquadric objects (standard set, 3 views): volumetric IoU, parts used",
              measure(specs, out / "standard", args.repeat, args.today))
    if not args.skip_ycb:
        for views in args.views:
            table(f"YCB-like products, {views} views all around: volumetric IoU against the true union",
                  measure(ycb_like_set(0, n_views=views), out / f"ycb-{views}", args.repeat, args.today))


if __name__ == "__main__":
    main()
