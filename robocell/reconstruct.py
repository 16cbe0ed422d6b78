"""``robocell reconstruct SCAN_DIR ...``: one JSON line per scan bundle (DESIGN.md §3)."""

from __future__ import annotations

import argparse
import json
import logging
import sys

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


def _reconstruct(args: argparse.Namespace) -> int:
    from core_cy.errors import CoreError
    from core_cy.reconstruct import Options, reconstruct
    from wire.bundle import load_bundle
    from wire.errors import BundleError

    given = {"n_points": args.n_points, "inside_weight": args.inside_weight, "cauchy_scale": args.cauchy_scale}
    options = Options(**{name: value for name, value in given.items() if value is not None})
    failures = 0
    for scan in args.scan_dirs:
        try:
            bundle = load_bundle(scan)
            result = reconstruct(bundle.views, segmentation=bundle.segmentation,
                                 support_plane=bundle.support_plane, options=options)
            line = {"scan": scan, **result.to_dict(points=args.points)}
        except (BundleError, CoreError) as exc:
            failures += 1
            line = {"scan": scan, "error": str(exc)}
            print(f"robocell reconstruct: {scan}: {exc}", file=sys.stderr)
        except Exception as exc:  # a bug must not cost the other bundles their results
            failures += 1
            log.exception("internal error on %s", scan)
            line = {"scan": scan, "error": f"internal error: {type(exc).__name__}: {exc}"}
        print(json.dumps(line), flush=True)
    return 1 if failures else 0
