"""``robocell reconstruct SCAN_DIR ...``: one JSON line per scan bundle (DESIGN.md §3)."""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time

from .command import Commands

__all__ = ["register"]

log = logging.getLogger("robocell")


def register(commands: Commands) -> None:
    parser = commands.add(
        "reconstruct", _reconstruct, help="fit a superquadric to each scan bundle, one JSON line each",
        description="Reconstruct scan bundles (DESIGN.md §3). Prints one JSON object per bundle, in order; "
                    "exits non-zero if any bundle failed.")
    parser.add_argument("scan_dirs", nargs="+", metavar="SCAN_DIR")
    parser.add_argument("--points", action="store_true", help="add the carved point cloud")
    # Defaults are the algorithm's own (core_cy.reconstruct.Options), not repeated here.
    parser.add_argument("--n-points", type=int, help="points on the starting sphere (default: the algorithm's)")
    parser.add_argument("--inside-weight", type=float,
                        help="weight of points inside the superquadric; 1 = plain Jaklic (default: the algorithm's)")
    parser.add_argument("--cauchy-scale", type=float,
                        help="robust loss scale for points outside, in cloud radii (default: the algorithm's)")
    parser.add_argument("--grasps", action="store_true",
                        help="add parallel-jaw grasps of the object, best first (DESIGN.md §3)")
    parser.add_argument("--gripper", metavar="GRIPPER.json",
                        help="the gripper's dimensions for --grasps (default: the built-in gripper)")
    parser.add_argument("--max-grasps", type=_positive, metavar="N", help="at most N grasps per bundle (default 10)")
    parser.add_argument("--masks-out", metavar="DIR",
                        help="write the silhouettes each reconstruction used as DIR/<bundle name>/mask<i>.png "
                             "(255 = object), one per view in scan.json's order")
    parser.add_argument("--next-view", action="store_true",
                        help="add the view that would most reduce the model's uncertainty: one of scan.json's "
                             "'candidates', or a pose proposed at the views' distance")


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive whole number")
    return value


def _gripper(path: str | None):
    """The gripper of ``--gripper``, or the built-in one; a bad file is a one-line error."""
    from robocell.core_cy.errors import CoreError
    from robocell.core_cy.gripper import DEFAULT_GRIPPER, Gripper

    if path is None:
        return DEFAULT_GRIPPER
    try:
        with open(path, "rb") as file:
            return Gripper.from_json(file.read(1 << 16))
    except OSError as exc:
        raise CoreError(f"cannot read the gripper file: {exc.strerror}") from exc


def _with_grasps(line: dict, result, bundle, gripper, max_grasps: int | None = None) -> dict:
    """Add DESIGN.md §3's ``grasps`` to a result line, and their time to ``timings_ms``: planned on the
    model's union of parts (``max_grasps`` None: the planner's own default)."""
    from robocell.core_cy.grasp import plan_grasps
    from robocell.core_cy.gripper import grasps_to_json

    start = time.perf_counter()
    limit = {} if max_grasps is None else {"max_grasps": max_grasps}
    grasps = plan_grasps(result.parts, bundle.support_plane, gripper, residual=result.residual,
                         silhouette_iou=result.silhouette_iou, points=result.points, **limit)
    ms = (time.perf_counter() - start) * 1e3
    timings = line["timings_ms"]
    timings["grasp"] = round(ms, 3)
    timings["total"] = round(timings["total"] + ms, 3)
    return {**line, "grasps": grasps_to_json(grasps)}


def _write_masks(directory: str, scan: str, silhouettes) -> None:
    """DESIGN.md §3's ``--masks-out``: the silhouettes the fit used, ``mask<i>.png`` in the bundle's folder."""
    import cv2
    from pathlib import Path

    out = Path(directory) / Path(scan).resolve().name
    out.mkdir(parents=True, exist_ok=True)
    for index, silhouette in enumerate(silhouettes):
        if not cv2.imwrite(str(out / f"mask{index}.png"), silhouette):
            raise OSError(f"cannot write {out / f'mask{index}.png'}")


def _with_next_view(line: dict, result, bundle) -> dict:
    """Add ``next_view`` (core_cy.next_view) to a result line, and its time to ``timings_ms``."""
    from robocell.core_cy.next_view import choose_next_view

    start = time.perf_counter()
    choice = choose_next_view(result, [view.camera for view in bundle.views], bundle.candidates,
                              support_plane=bundle.support_plane)
    ms = (time.perf_counter() - start) * 1e3
    timings = line["timings_ms"]
    timings["next_view"] = round(ms, 3)
    timings["total"] = round(timings["total"] + ms, 3)
    return {**line, "next_view": {"candidate": choice.candidate, "T_world_cam": choice.T_world_cam.tolist(),
                                  "expected_gain": round(choice.expected_gain, 4),
                                  "uncertainty": round(choice.uncertainty, 4), "sure": choice.sure}}


def _reconstruct(args: argparse.Namespace) -> int:
    from robocell.core_cy.errors import CoreError
    from robocell.core_cy.reconstruct import Options, reconstruct
    from robocell.wire.bundle import load_bundle
    from robocell.wire.errors import BundleError

    given = {"n_points": args.n_points, "inside_weight": args.inside_weight, "cauchy_scale": args.cauchy_scale}
    options = Options(**{name: value for name, value in given.items() if value is not None})
    if not args.grasps and (args.gripper is not None or args.max_grasps is not None):
        print("robocell reconstruct: --gripper and --max-grasps only apply with --grasps", file=sys.stderr)
        return 2
    gripper = None
    if args.grasps:
        try:
            gripper = _gripper(args.gripper)
        except CoreError as exc:
            print(f"robocell reconstruct: {args.gripper}: {exc}", file=sys.stderr)
            return 2
    failures = 0
    for scan in args.scan_dirs:
        try:
            bundle = load_bundle(scan)
            result = reconstruct(bundle.views, segmentation=bundle.segmentation,
                                 support_plane=bundle.support_plane, options=options)
            line = {"scan": scan, **result.to_dict(points=args.points)}
            if args.masks_out is not None:
                _write_masks(args.masks_out, scan, result.silhouettes)
            if gripper is not None:
                line = _with_grasps(line, result, bundle, gripper, args.max_grasps)
            if args.next_view:
                line = _with_next_view(line, result, bundle)
        except (BundleError, CoreError, OSError) as exc:
            failures += 1
            line = {"scan": scan, "error": str(exc)}
            print(f"robocell reconstruct: {scan}: {exc}", file=sys.stderr)
        except Exception as exc:  # a bug must not cost the other bundles their results
            failures += 1
            log.exception("internal error on %s", scan)
            line = {"scan": scan, "error": f"internal error: {type(exc).__name__}: {exc}"}
        print(json.dumps(line), flush=True)
    return 1 if failures else 0
