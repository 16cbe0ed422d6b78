"""The margins of the daemon's check of a worker's answer (cell/verify.py), and what it costs.

On the simulator's standard set and grasp set (``robocell sim scans --set standard|grasp``), each
scan is reconstructed by the real pipeline (``auto`` segmentation, as a worker does); then, as the
daemon does, its evidence is made once (the pictures at 1/4 scale, segmented: ``job_evidence``'s
work) and answers are checked against it (``check_answer``): the honest fit, and the fit made 1.5,
8 and 10 times too big. Prints the worst view's IoU of each (the threshold is MIN_VIEW_IOU), and the
seconds of the evidence (made while the worker reconstructs, off the job's path) beside those of a
check (on it), as a ratio to the reconstruction of the same scan. Asserts nothing.

    .venv/bin/python bench/probe_verify.py [--sets standard grasp] [--limit N]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from robocell.cell.verify import MIN_VIEW_IOU, Evidence, check_answer, reduced_camera, reduced_silhouettes  # noqa: E402
from robocell.core_cy.camera import Camera  # noqa: E402
from robocell.core_cy.grasp import plan_grasps  # noqa: E402
from robocell.core_cy.gripper import Gripper  # noqa: E402
from robocell.core_cy.reconstruct import View, reconstruct  # noqa: E402
from robocell.core_cy.segment import Segmentation  # noqa: E402
from robocell.wire.messages import Grasp, Reconstruction, Superquadric  # noqa: E402
from robocell.workers.sim.grasp_set import grasp_set  # noqa: E402
from robocell.workers.sim.scans import standard_set  # noqa: E402

PLANE = [0.0, 0.0, 1.0, 0.0]
GRIPPER = Gripper()
FACTORS = (1.5, 8.0, 10.0)


def _answer(fit, grasps) -> Reconstruction:
    sq = fit.superquadric
    return Reconstruction(
        superquadric=Superquadric(size=sq.size.tolist(), shape=sq.shape.tolist(), T_world_object=sq.T_world_object.tolist()),
        silhouette_iou=list(fit.silhouette_iou), residual=fit.residual, timings_ms={},
        centre=np.asarray(fit.centre).tolist(), radius=float(fit.radius),
        grasps=[Grasp(T_world_grasp=g.T_world_grasp.tolist(), width=g.width, score=g.score, approach=g.approach)
                for g in grasps])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sets", nargs="+", default=["standard", "grasp"], choices=["standard", "grasp"])
    parser.add_argument("--limit", type=int, help="at most this many scans of each set")
    args = parser.parse_args()
    specs = []
    for name in args.sets:
        found = standard_set(seed=0) if name == "standard" else grasp_set(seed=0)
        specs += found[:args.limit] if args.limit else found
    rows = []
    with tempfile.TemporaryDirectory(prefix="probe-verify-") as tmp:
        for spec in specs:
            directory = spec.write(Path(tmp))
            scan = json.loads((directory / "scan.json").read_text())
            jpegs = [(directory / view["image"]).read_bytes() for view in scan["views"]]
            full = [Camera(K=v["K"], T_world_cam=v["T_world_cam"], view=i) for i, v in enumerate(scan["views"])]
            cameras = tuple(reduced_camera(v["K"], v["T_world_cam"], view=i) for i, v in enumerate(scan["views"]))
            began = time.perf_counter()
            try:
                fit = reconstruct([View(c, image=j) for c, j in zip(full, jpegs)], support_plane=PLANE)
            except Exception as exc:  # the core's verdict: no answer a worker could give
                print(f"{spec.name:<28} no reconstruction: {exc}")
                continue
            reconstructed = time.perf_counter() - began
            grasps = plan_grasps(fit.superquadric, PLANE, GRIPPER, residual=fit.residual,
                                 silhouette_iou=fit.silhouette_iou, points=fit.points)
            began = time.perf_counter()
            silhouettes = reduced_silhouettes(jpegs, Segmentation(), cameras, PLANE)
            evidence = Evidence(cameras, tuple(silhouettes), PLANE, GRIPPER)
            made = time.perf_counter() - began
            honest = _answer(fit, grasps)
            began = time.perf_counter()
            verdict = check_answer(honest, evidence)
            checked = time.perf_counter() - began
            worst = {1.0: min(verdict.ious)}
            for factor in FACTORS:
                big = honest.superquadric.model_copy(update={"size": [a * factor for a in honest.superquadric.size]})
                worst[factor] = max(check_answer(honest.model_copy(update={"superquadric": big}), evidence).ious)
            rows.append((spec.name, worst, verdict.ok, len(grasps), len(verdict.grasps), made / reconstructed,
                         checked / reconstructed))
            print(f"{spec.name:<28} worst view {worst[1.0]:.3f} ok={verdict.ok} grasps {len(verdict.grasps)}/"
                  f"{len(grasps)}; best view of 1.5x {worst[1.5]:.3f}, 8x {worst[8.0]:.3f}, 10x {worst[10.0]:.3f}; "
                  f"evidence {made / reconstructed:.3f}, check {checked / reconstructed:.3f} of the reconstruction",
                  flush=True)
    print(f"\n{len(rows)} scans; threshold {MIN_VIEW_IOU}")
    honest_worst = sorted(rows, key=lambda r: r[1][1.0])
    print(f"honest fit, worst view: min {honest_worst[0][1][1.0]:.3f} ({honest_worst[0][0]}), "
          f"median {statistics.median(r[1][1.0] for r in rows):.3f}; refused: {sum(not r[2] for r in rows)}")
    for factor in FACTORS:
        best = max(rows, key=lambda r: r[1][factor])
        print(f"{factor:g} x too big, best view: max {best[1][factor]:.3f} ({best[0]}), "
              f"median {statistics.median(r[1][factor] for r in rows):.3f}; "
              f"passed: {sum(r[1][factor] >= MIN_VIEW_IOU for r in rows)}")
    print(f"grasps kept {sum(r[4] for r in rows)} of {sum(r[3] for r in rows)}")
    for label, index in (("evidence (off the path)", 5), ("check (on the path)", 6)):
        values = [r[index] for r in rows]
        print(f"{label}: mean {statistics.mean(values):.3f}, worst {max(values):.3f} of the scan's reconstruction")


if __name__ == "__main__":
    main()
