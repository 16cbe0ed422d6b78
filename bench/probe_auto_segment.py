"""Probe of the ``auto`` segmentation: silhouettes against the truth, the models they give, and speed.

Scenes from tests/seg_scenes.py (ray-traced apart from the segmentation: printed and flat objects,
textured tables, one light and its cast shadow, area-true edges, blur, noise, JPEG), 640x480, three
views, each with and without a support plane and with a background picture. For each: silhouette
IoU against the true masks (mean and worst view), and the volumetric IoU of the model against the
true object beside that of the same scan with the true masks supplied.

Speed: ``robocell reconstruct`` over the auto bundles, one process on one core (``taskset -c 0``
when available), timed from outside, against OpenCV decoding the same JPEGs in the same run.

    PYTHONPATH=. python bench/probe_auto_segment.py [--seed 0]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robocell.core_cy.errors import CoreError  # noqa: E402
from robocell.core_cy.reconstruct import View, reconstruct  # noqa: E402
from robocell.core_cy.camera import Camera  # noqa: E402
from robocell.core_cy.scoring import volumetric_iou  # noqa: E402
from robocell.core_cy.superquadric import Superquadric  # noqa: E402
from tests.seg_scenes import Scene, render_scan  # noqa: E402

SCENES = {
    "red box, beige": Scene(),
    "printed can, wood": Scene(shape="cylinder", size=(0.035, 0.035, 0.06), object_print="label",
                               table_texture="wood", yaw=1.0),
    "printed box, grid mat": Scene(size=(0.03, 0.045, 0.06), object_print="label", object_bgr=(160, 90, 30),
                                   table_bgr=(70, 120, 60), table_texture="grid", yaw=0.7),
    "white box, dark mat": Scene(object_bgr=(230, 230, 230), table_bgr=(30, 32, 35), light=(-0.4, 0.5, 0.8)),
    "dark can, dark grid": Scene(shape="cylinder", size=(0.03, 0.03, 0.05), object_bgr=(45, 40, 40),
                                 table_bgr=(55, 55, 60), table_texture="grid"),
    "yellow can, laminate": Scene(shape="cylinder", size=(0.04, 0.04, 0.05), object_bgr=(30, 200, 230),
                                  table_bgr=(215, 215, 210), light=(-0.5, -0.2, 0.7)),
    "table-coloured box, wood": Scene(object_bgr=(150, 170, 190), table_texture="wood"),
}


def _truth(scene: Scene) -> Superquadric:
    c, s = np.cos(scene.yaw), np.sin(scene.yaw)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = scene.centre
    shape = [0.1, 0.1] if scene.shape == "box" else [0.1, 1.0]
    return Superquadric(list(scene.size), shape, T)


def _iou(a, b) -> float:
    a, b = a > 0, b > 0
    return float((a & b).sum() / max(1, (a | b).sum()))


def _jpeg(image) -> bytes:
    return cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 92])[1].tobytes()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    plane = [0.0, 0.0, 1.0, 0.0]
    out = Path(tempfile.mkdtemp(prefix="auto-probe-"))
    rows, bundles = [], []
    try:
        for number, (name, scene) in enumerate(SCENES.items()):
            seed = args.seed * 100 + number
            images, truths, cams = render_scan(scene, size=(640, 480), seed=seed)
            empty, _, _ = render_scan(Scene(**{**scene.__dict__, "with_object": False}), size=(640, 480), seed=seed)
            cameras = [Camera(K=K, T_world_cam=T, view=i) for i, (K, T) in enumerate(cams)]
            jpegs = [_jpeg(image) for image in images]
            truth = _truth(scene)
            masked = reconstruct([View(c, mask=m) for c, m in zip(cameras, truths)], support_plane=plane)
            ceiling = volumetric_iou(masked.superquadric, truth)
            for label, kwargs in (("plane", {"support_plane": plane}), ("no plane", {}),
                                  ("background", {"support_plane": plane})):
                backgrounds = [_jpeg(e) for e in empty] if label == "background" else [None] * 3
                views = [View(c, image=j, background=b) for c, j, b in zip(cameras, jpegs, backgrounds)]
                try:
                    result = reconstruct(views, **kwargs)
                except CoreError as exc:
                    rows.append((name, label, None, None, None, ceiling, str(exc)))
                    continue
                ious = [_iou(s, t) for s, t in zip(result.silhouettes, truths)]
                rows.append((name, label, float(np.mean(ious)), float(min(ious)),
                             volumetric_iou(result.superquadric, truth), ceiling, ""))
            directory = out / f"scene{number}"
            directory.mkdir()
            for i, jpeg in enumerate(jpegs):
                (directory / f"view{i}.jpg").write_bytes(jpeg)
            (directory / "scan.json").write_text(json.dumps({"views": [
                {"image": f"view{i}.jpg", "K": np.asarray(K).tolist(), "T_world_cam": np.asarray(T).tolist()}
                for i, (K, T) in enumerate(cams)], "support_plane": plane}))
            bundles.append(directory)
        print("| scene | cues | silhouette IoU mean / worst | volumetric IoU | with true masks |")
        print("|---|---|---|---|---|")
        for name, label, mean, worst, vol, ceiling, error in rows:
            if error:
                print(f"| {name} | {label} | error: {error} | | {ceiling:.3f} |")
            else:
                print(f"| {name} | {label} | {mean:.3f} / {worst:.3f} | {vol:.3f} | {ceiling:.3f} |")
        for label in ("plane", "no plane", "background"):
            chosen = [r for r in rows if r[1] == label and not r[6]]
            if chosen:
                print(f"| **all** | {label} | {np.mean([r[2] for r in chosen]):.3f} / "
                      f"{min(r[3] for r in chosen):.3f} | {np.mean([r[4] for r in chosen]):.3f} | "
                      f"{np.mean([r[5] for r in chosen]):.3f} | ({len(chosen)} of {len(SCENES)} without error)")
        _speed(bundles)
    finally:
        shutil.rmtree(out, ignore_errors=True)
    return 0


def _speed(bundles: list[Path], rounds: int = 5) -> None:
    """``robocell reconstruct`` over the bundles, from outside, against decoding their JPEGs."""
    pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
    robocell = [sys.executable, "-m", "robocell", "reconstruct"]
    decode = [sys.executable, "-c", "import sys, time, cv2, numpy as np\n"
              "files = [open(p, 'rb').read() for p in sys.argv[1:]]\n"
              "start = time.perf_counter()\n"
              "for data in files: cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)\n"
              "print((time.perf_counter() - start) * 1e3)"]
    jpegs = [str(p) for b in bundles for p in sorted(b.glob("view*.jpg"))]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    # A process's start costs the same to both: time a run of one bundle and of all, take the difference.
    per_bundle, per_decode = [], []
    for _ in range(rounds):
        timed = []
        for chosen in (bundles[:1], bundles * 3):
            start = time.perf_counter()
            subprocess.run([*pin, *robocell, *map(str, chosen)], capture_output=True, env=env, check=False)
            timed.append(time.perf_counter() - start)
        per_bundle.append((timed[1] - timed[0]) / (3 * len(bundles) - 1) * 1e3)
        ms = float(subprocess.run([*pin, *decode, *jpegs], capture_output=True, text=True, env=env).stdout)
        per_decode.append(ms / len(bundles))
    ratio = [b / d for b, d in zip(per_bundle, per_decode)]
    print(f"\nrobocell reconstruct, auto, 3 views of 640x480, one core: median {np.median(per_bundle):.1f} ms a bundle "
          f"(from outside); decoding its 3 JPEGs: median {np.median(per_decode):.1f} ms; "
          f"ratio median {np.median(ratio):.2f} (range {min(ratio):.2f}-{max(ratio):.2f})")


if __name__ == "__main__":
    raise SystemExit(main())
