"""Compare two records of `bench/bench_segment.py --record FILE`, scan by scan and view by view.

    .venv/bin/python bench/compare_segment.py NEW.json [OLD.json]

For each way (default, + background, true masks) in NEW: the silhouette IoU per view, mean / worst /
views under 0.85, the volumetric IoU, mean / worst, and the best grasps that hold; with OLD, the same
for OLD over the scans both hold, how many views are the same to the bit, and every view that moved
by more than 0.02. A change to the segmentation is judged so: its gains and its losses, each named.
Prints; asserts nothing.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

#: A view that moved by more than this is listed.
MOVED = 0.02
#: The issue's target for the worst view.
WORST_TARGET = 0.85


def summary(record: dict, way: str, scans: list[str]) -> str:
    views = [(scan, i, iou) for scan in scans for i, iou in enumerate(record[scan][way]["views"])]
    ious = np.array([iou for _, _, iou in views])
    volumes = np.array([record[scan][way]["iou"] for scan in scans])
    held = sum(bool(record[scan][way]["holds"]) for scan in scans)
    worst = min(views, key=lambda view: view[2])
    return (f"silhouettes {ious.mean():.4f} / {ious.min():.3f} / {int((ious < WORST_TARGET).sum())} under "
            f"{WORST_TARGET} (worst {worst[0]} view {worst[1]}), volumetric {volumes.mean():.4f} / "
            f"{volumes.min():.3f}, grasps held {held} of {len(scans)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("new", type=Path)
    parser.add_argument("old", type=Path, nargs="?")
    args = parser.parse_args()
    new = json.loads(args.new.read_text())
    old = json.loads(args.old.read_text()) if args.old else None
    scans = sorted(new) if old is None else sorted(set(new) & set(old))
    if not scans:
        raise SystemExit("compare_segment: the two records share no scan")
    for way in new[scans[0]]:
        print(f"{way}:")
        if old is not None and way in old[scans[0]]:
            print(f"  old  {summary(old, way, scans)}")
        print(f"  new  {summary(new, way, scans)}")
        if old is None or way not in old[scans[0]]:
            continue
        same = total = 0
        moved = []
        for scan in scans:
            for i, (before, after) in enumerate(zip(old[scan][way]["views"], new[scan][way]["views"])):
                total += 1
                same += before == after
                if abs(after - before) > MOVED:
                    moved.append((after - before, scan, i, before, after))
        up = sum(change > 0 for change, *_ in moved)
        print(f"  {same} of {total} views the same; {up} up and {len(moved) - up} down by over {MOVED}")
        for _, scan, i, before, after in sorted(moved):
            print(f"    {scan} view {i}: {before:.3f} -> {after:.3f}")


if __name__ == "__main__":
    main()
