"""Benchmark of the reconstruction core: accuracy, speed per stage, and the real bunny.

    .venv/bin/python bench/bench_core.py [--repeat N] [--keep DIR]

(a) accuracy on the fixed simulated set (`robocell sim`'s standard set): volumetric
    IoU against the truth per family, for plain Jaklic, inside weighting alone, and
    the chosen cost (inside weighting + Cauchy loss outside); the non-superquadric
    objects against their true volume;
(b) time per stage, decode of three 640x480 JPEGs to fitted superquadric, on one core;
(c) ../shared/data/bunny (real photographs, supplied masks): silhouette IoU per view.

Prints tables; asserts nothing.
"""

from __future__ import annotations

import os

# One core: the numbers must not depend on how many threads BLAS or OpenCV would take.
for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import tempfile  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from wire.bundle import load_bundle  # noqa: E402
from workers.sim.scans import standard_set  # noqa: E402
from core_cy.reconstruct import Options, reconstruct  # noqa: E402
from core_cy.scoring import volumetric_iou  # noqa: E402
from core_cy.superquadric import Superquadric, inside_outside  # noqa: E402

BUNNY = Path(__file__).resolve().parents[2] / "shared" / "data" / "bunny"
STAGES = ("decode", "segment", "centroid", "carve", "fit", "quality", "total")
# The first two compare costs alone, so the silhouette refinement of poor fits is off for them.
COSTS = {
    "plain Jaklic": dict(inside_weight=1.0, outside_loss="squared", refine_below=0.0),
    "inside weight": dict(outside_loss="squared", refine_below=0.0),
    "chosen": dict(),
}


def object_iou(fit: Superquadric, obj, n: int = 200_000, seed: int = 0) -> float:
    """Volumetric IoU of a superquadric and any simulated object (Monte Carlo)."""
    vertices, _ = obj.mesh()
    centre = fit.T_world_object[:3, 3]
    reach = np.linalg.norm(fit.size) * 1.01
    lower = np.minimum(vertices.min(0), centre - reach)
    upper = np.maximum(vertices.max(0), centre + reach)
    points = np.random.default_rng(seed).uniform(lower, upper, size=(n, 3))
    in_fit = inside_outside(points, fit) <= 1.0
    in_object = obj.inside(points)
    return float((in_fit & in_object).sum() / max(1, (in_fit | in_object).sum()))


def run(bundle, options: Options):
    return reconstruct(bundle.views, segmentation=bundle.segmentation, support_plane=bundle.support_plane,
                       options=options)


def accuracy(specs, bundles) -> None:
    scores = {name: defaultdict(list) for name in COSTS}
    others = []
    for spec, bundle in zip(specs, bundles):
        family = spec.name.rsplit("-", 1)[0]
        obj = spec.objects[0]
        for name, cost in COSTS.items():
            fit = run(bundle, Options(**cost)).superquadric
            if obj.truth()["kind"] == "superquadric":
                scores[name][family].append(volumetric_iou(fit, Superquadric.from_dict(obj.truth())))
            elif name == "chosen":
                others.append((spec.name, object_iou(fit, obj)))
    families = list(scores["chosen"])
    print("\n(a) volumetric IoU against the truth, simulated set "
          f"({sum(len(v) for v in scores['chosen'].values())} superquadric scans, support plane given)")
    print(f"{'family':<14}" + "".join(f"{name:>28}" for name in COSTS))
    print(f"{'':<14}" + "".join(f"{'mean':>19}{'worst':>9}" for _ in COSTS))
    for family in families + ["all"]:
        row = f"{family:<14}"
        for name in COSTS:
            values = sum(scores[name].values(), []) if family == "all" else scores[name][family]
            row += f"{np.mean(values):>19.3f}{np.min(values):>9.3f}"
        print(row)
    print("\nnon-superquadric objects (chosen cost), IoU against the true volume:")
    for name, iou in others:
        print(f"  {name:<14}{iou:.3f}")


def timing(bundles, repeat: int) -> None:
    cv2.setNumThreads(1)
    samples = defaultdict(list)
    for _ in range(repeat):
        for bundle in bundles:
            result = run(bundle, Options())
            for stage in STAGES:
                samples[stage].append(result.timings_ms.get(stage, 0.0))
    n = len(samples["total"])
    print(f"\n(b) time per stage, ms, {n} reconstructions of 3 x 640x480 JPEG bundles, one core "
          f"({platform.processor() or platform.machine()})")
    print(f"{'stage':<10}{'median':>10}{'p90':>10}")
    for stage in STAGES:
        print(f"{stage:<10}{np.median(samples[stage]):>10.2f}{np.percentile(samples[stage], 90):>10.2f}")


def bunny() -> None:
    print(f"\n(c) {BUNNY} (real photographs, supplied masks): silhouette IoU per view")
    if not (BUNNY / "scan.json").exists():
        print("  not found")
        return
    result = run(load_bundle(BUNNY), Options())
    names = [view["mask"] for view in json.loads((BUNNY / "scan.json").read_text())["views"]]
    for name, iou in zip(names, result.silhouette_iou):
        print(f"  {name:<12}{iou:.3f}")
    print(f"  {'mean':<12}{np.mean(result.silhouette_iou):.3f}   ({result.timings_ms['total']:.1f} ms; "
          f"size {np.round(result.superquadric.size, 2).tolist()}, shape "
          f"{np.round(result.superquadric.shape, 2).tolist()})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=5, help="timing passes over the set (default 5)")
    parser.add_argument("--keep", help="write the simulated set here instead of a temporary directory")
    args = parser.parse_args()
    defaults = Options()
    print(f"robocell core benchmark: n_points={defaults.n_points}, inside_weight={defaults.inside_weight}, "
          f"cauchy_scale={defaults.cauchy_scale}, fit_points={defaults.fit_points}")
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(args.keep or scratch)
        specs = standard_set(seed=0)
        bundles = [load_bundle(spec.write(out)) for spec in specs]
        accuracy(specs, bundles)
        superquadric_bundles = [b for s, b in zip(specs, bundles) if s.objects[0].truth()["kind"] == "superquadric"]
        timing(superquadric_bundles, args.repeat)
    bunny()


if __name__ == "__main__":
    main()
