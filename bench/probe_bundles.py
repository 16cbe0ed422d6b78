"""Hostile scan bundles (DESIGN.md §3, "A bundle is untrusted input") against `robocell reconstruct`.

    .venv/bin/python bench/probe_bundles.py [--kill-after S] [--keep DIR]

For each hostile bundle of ``tests/bundles.py`` (a file outside the bundle, a
symlink to /dev/zero, a FIFO, a 2 GB scan.json, 16,000 views, a 20000x20000
PNG, a 100x100 mask against a 640x480 K, distortion 1e300, ...), runs
``robocell reconstruct HOSTILE GOOD`` in a child process limited to 4 GB of
address space, and prints the seconds it took, the child's peak resident
memory, its line for the hostile bundle, and whether the good bundle beside it
was still reconstructed. The target: a one-line error within 5 s, under the
4 GB limit, and the good bundle done. A child still running after
``--kill-after`` seconds is killed and shown as such.

Then the same for legitimate bundles as large as the limits allow, to show what
the limits let a bundle cost. Times depend on the machine's load: each is also
given as a ratio to the good bundle alone, measured in the same run.
Asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.bundles import (HOSTILE_BUNDLES, SPHERE_CENTRE, SPHERE_RADIUS, edit_scan,  # noqa: E402
                           tabletop_poses, write_sphere_bundle)
from tests.helpers import intrinsics  # noqa: E402

MEMORY_LIMIT = 4 * 2**30
BUDGET_S = 5.0


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def run_reconstruct(bundles: list[Path], cwd: Path, kill_after: float) -> tuple[float, float, float, list[str], str]:
    """Wall and CPU seconds, peak resident MB, stdout lines and the exit code (or "killed") of one child."""
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        start = time.perf_counter()
        child = subprocess.Popen([sys.executable, "-m", "robocell", "reconstruct", *map(str, bundles)],
                                 stdout=out, stderr=err, stdin=subprocess.DEVNULL, cwd=cwd,
                                 preexec_fn=_limit_memory)
        status = "killed"
        while True:
            pid, wait_status, usage = os.wait4(child.pid, os.WNOHANG)
            if pid:
                status = str(os.waitstatus_to_exitcode(wait_status))
                break
            if time.perf_counter() - start > kill_after:
                child.kill()
                _, _, usage = os.wait4(child.pid, 0)
                break
            time.sleep(0.01)
        seconds = time.perf_counter() - start
        child.returncode = 0  # reaped by wait4 above; keep Popen from waiting again
        out.seek(0)
        lines = out.read().decode(errors="replace").splitlines()
    return seconds, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, lines, status


def _line_for(lines: list[str], bundle: Path) -> dict | None:
    for line in lines:
        try:
            result = json.loads(line)
        except ValueError:
            continue
        if result.get("scan") == str(bundle):
            return result
    return None


def _summary(result: dict | None, width: int) -> str:
    if result is None:
        return "(no line)"
    text = result["error"] if "error" in result else f"reconstructed, silhouette IoU {result['silhouette_iou']}"
    return text if len(text) <= width else text[:width - 1] + "…"


def _disc_bundle(directory: Path, views: int, width: int, height: int, *, images: bool) -> Path:
    """A sphere seen by ``views`` cameras pointed at it, ``width`` x ``height`` each: masks or JPEGs."""
    directory.mkdir(parents=True)
    focal = 600.0 * width / 640
    K = intrinsics(focal, width, height)
    azimuths = np.linspace(0, 360, views, endpoint=False)
    poses = tabletop_poses(SPHERE_CENTRE, elevations=[45.0] * views, azimuths=azimuths)
    radius = focal * np.tan(np.arcsin(SPHERE_RADIUS / 0.5))  # the sphere is on each optical axis
    picture = np.zeros((height, width), np.uint8)
    cv2.circle(picture, ((width - 1) // 2, (height - 1) // 2), int(radius), 255, -1)
    if images:
        colour = np.full((height, width, 3), (110, 120, 125), np.uint8)
        colour[picture > 0] = (30, 30, 200)
        data, name = cv2.imencode(".jpg", colour)[1].tobytes(), "view.jpg"
    else:
        data, name = cv2.imencode(".png", picture)[1].tobytes(), "mask.png"
    (directory / name).write_bytes(data)
    key = "image" if images else "mask"
    scan = {"views": [{key: name, "K": K.tolist(), "T_world_cam": pose.tolist()} for pose in poses],
            "support_plane": [0, 0, 1, 0]}
    (directory / "scan.json").write_text(json.dumps(scan))
    return directory


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kill-after", type=float, default=30.0, help="seconds before a child is killed")
    parser.add_argument("--keep", type=Path, help="build the bundles here and keep them")
    args = parser.parse_args()
    root = Path(tempfile.mkdtemp(prefix="probe-bundles-")) if args.keep is None else args.keep
    root.mkdir(parents=True, exist_ok=True)
    try:
        template = write_sphere_bundle(root / "template")
        good = shutil.copytree(template, root / "good")
        alone, alone_cpu, _, _, _ = run_reconstruct([good], root, args.kill_after)
        print(f"robocell reconstruct HOSTILE GOOD, each in a child under a {MEMORY_LIMIT / 2**30:.0f} GB address-space "
              f"limit; target: a one-line error within {BUDGET_S:.0f} s and GOOD done.")
        print(f"The good bundle alone: {alone:.2f} s, {alone_cpu:.2f} s of CPU (process start included).\n")
        print("| bundle | s | x alone | CPU s | peak MB | exit | line for the bundle | good done |")
        print("|---|---|---|---|---|---|---|---|")
        for name, (change, _) in HOSTILE_BUNDLES.items():
            bundle = shutil.copytree(template, root / name)
            change(bundle)
            seconds, cpu, peak, lines, status = run_reconstruct([bundle, good], root, args.kill_after)
            done = "superquadric" in (_line_for(lines, good) or {})
            print(f"| {name} | {seconds:.2f} | {seconds / alone:.1f} | {cpu:.2f} | {peak:.0f} | {status} | "
                  f"{_summary(_line_for(lines, bundle), 110)} | {'yes' if done else 'NO'} |", flush=True)

        print("\nLegitimate bundles at the limits (each alone):\n")
        print("| bundle | s | x alone | CPU s | peak MB | exit | line |")
        print("|---|---|---|---|---|---|---|")
        at_limits = {
            "64 views (the most), 640x480 JPEG": lambda d: edit_scan(
                shutil.copytree(template, d), lambda s: s.update(views=[s["views"][i % 3] for i in range(64)])),
            "5 masks of 8160x6120 (49.9 MP each, 250 MP in all)": lambda d: _disc_bundle(d, 5, 8160, 6120,
                                                                                        images=False),
            "3 JPEGs of 8160x6120": lambda d: _disc_bundle(d, 3, 8160, 6120, images=True),
            "64 masks of 2000x2000 (256 MP in all)": lambda d: _disc_bundle(d, 64, 2000, 2000, images=False),
        }
        for index, (name, make) in enumerate(at_limits.items()):
            bundle = root / f"limit-{index}"
            make(bundle)
            seconds, cpu, peak, lines, status = run_reconstruct([bundle], root, args.kill_after)
            print(f"| {name} | {seconds:.2f} | {seconds / alone:.1f} | {cpu:.2f} | {peak:.0f} | {status} | "
                  f"{_summary(_line_for(lines, bundle), 90)} |", flush=True)
    finally:
        if args.keep is None:
            shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
