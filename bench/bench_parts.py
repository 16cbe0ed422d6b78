"""Benchmark of the model in parts (DESIGN.md §1.11) beside one superquadric, in the same run, on one core.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_parts.py [--keep DIR] [--per-kind N] [--views 3 4 6]

For every scan: the reconstruction with one superquadric (``Options(max_parts=1)``, as before parts
existed) and with parts (the default), each timed in process (best of ``--repeat``, interleaved, on
one core). Scored by the judge (workers/sim/judge.py, written apart from the fit): volumetric IoU of
the model's union against the true union. Sets: the everyday compound objects of
``workers.sim.scans.compound_set`` (and the older ``COMPOUNDS``: cups, mug, box and ball, L) per number
of views, and the superquadric scans of the standard set (how often one is split). Prints, per kind:
IoU mean and worst (one superquadric / parts), parts used, and the time of parts over one
superquadric (median; for the scans that stayed one part, and for those of up to four parts).
Asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from core_cy.reconstruct import Options, reconstruct
from wire.bundle import load_bundle
from workers.sim.judge import Part, parts_from_truth, union_iou
from workers.sim.objects import COMPOUNDS, compound
from workers.sim.scans import compound_set, make_spec, standard_set


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


def _as_parts(model) -> list[Part]:
    return [Part.from_dict(part.to_dict()) for part in model]


def measure(specs, out: Path, repeat: int):
    """{kind: [(iou one, iou parts, parts used, ms one, ms parts)]}"""
    rows = defaultdict(list)
    for spec in specs:
        bundle = _written(spec, out)
        truth = parts_from_truth(spec.objects[0].truth())
        one, ms_one = _timed(bundle, Options(max_parts=1), repeat)
        many, ms_many = _timed(bundle, Options(), repeat)
        kind = spec.name.rsplit("-", 1)[0]
        rows[kind].append((union_iou(_as_parts([one.superquadric]), truth), union_iou(_as_parts(many.parts), truth),
                           len(many.parts), ms_one, ms_many))
    return rows


def table(title: str, rows) -> None:
    print(f"\n{title}")
    print(f"{'kind':<16}{'one sq: mean':>13}{'worst':>7}{'parts: mean':>13}{'worst':>7}{'parts used':>12}"
          f"{'time x':>8}")
    every = []
    for kind, values in rows.items():
        v = np.array(values)
        every.append(v)
        used = ",".join(str(int(n)) for n in v[:, 2])
        print(f"{kind:<16}{v[:, 0].mean():>13.3f}{v[:, 0].min():>7.3f}{v[:, 1].mean():>13.3f}{v[:, 1].min():>7.3f}"
              f"{used:>12}{np.median(v[:, 4] / v[:, 3]):>8.2f}")
    v = np.concatenate(every)
    print(f"{'all':<16}{v[:, 0].mean():>13.3f}{v[:, 0].min():>7.3f}{v[:, 1].mean():>13.3f}{v[:, 1].min():>7.3f}"
          f"{'max ' + str(int(v[:, 2].max())):>12}{np.median(v[:, 4] / v[:, 3]):>8.2f}")
    ratio = v[:, 4] / v[:, 3]
    one, few = v[:, 2] == 1, (v[:, 2] > 1) & (v[:, 2] <= 4)
    for label, pick in (("stayed one part", one), ("2-4 parts", few)):
        if pick.any():
            print(f"  time of parts over one superquadric, {label} ({pick.sum()} scans): median {np.median(ratio[pick]):.2f}"
                  f"x, worst {ratio[pick].max():.2f}x (one superquadric: median {np.median(v[pick, 3]):.1f} ms)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--keep", type=Path, help="keep the simulated sets here (and reuse them)")
    parser.add_argument("--per-kind", type=int, default=2, help="scans per compound kind (default 2)")
    parser.add_argument("--views", type=int, nargs="+", default=[3], help="numbers of views (default 3)")
    parser.add_argument("--repeat", type=int, default=2, help="timing passes per scan, best kept (default 2)")
    parser.add_argument("--skip-standard", action="store_true", help="leave out the standard set's superquadrics")
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
              measure(specs, out / f"compound-{views}", args.repeat))
    if not args.skip_standard:
        specs = [s for s in standard_set(0) if not s.name.startswith(("cup-stack", "lumpy"))]
        table("superquadric objects (standard set, 3 views): volumetric IoU, parts used",
              measure(specs, out / "standard", args.repeat))
        others = [s for s in standard_set(0) if s.name.startswith(("cup-stack", "lumpy"))]
        table("the standard set's non-superquadric objects (cup stacks, lumpy figures)",
              measure(others, out / "standard", args.repeat))


if __name__ == "__main__":
    main()
