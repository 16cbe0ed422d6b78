"""The ``robocell`` command."""

from __future__ import annotations

import argparse
import json
import logging
import sys

from core_cy.errors import CoreError
from core_cy.reconstruct import Options, reconstruct

from .bundle import load_bundle
from .errors import BundleError

log = logging.getLogger("robocell")


def _reconstruct_command(args: argparse.Namespace) -> int:
    options = Options(n_points=args.n_points, inside_weight=args.inside_weight,
                      cauchy_scale=args.cauchy_scale)
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


def _demo_command(args: argparse.Namespace) -> int:
    from .demo import run_demo

    return run_demo(args)


def _sim_command(args: argparse.Namespace) -> int:
    from .sim import cli as sim_cli

    return sim_cli.run(args)


def build_parser() -> argparse.ArgumentParser:
    defaults = Options()
    parser = argparse.ArgumentParser(
        prog="robocell", description="Graspable superquadric models of unknown objects.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    rec = commands.add_parser(
        "reconstruct", help="fit a superquadric to each scan bundle, one JSON line each",
        description="Reconstruct scan bundles (DESIGN.md §3). Prints one JSON object per "
                    "bundle, in order; exits non-zero if any bundle failed.")
    rec.add_argument("scan_dirs", nargs="+", metavar="SCAN_DIR")
    rec.add_argument("--points", action="store_true", help="add the carved point cloud")
    rec.add_argument("--n-points", type=int, default=defaults.n_points,
                     help="points on the starting sphere (default %(default)s)")
    rec.add_argument("--inside-weight", type=float, default=defaults.inside_weight,
                     help="weight of points inside the superquadric; 1 = plain Jaklic "
                          "(default %(default)s)")
    rec.add_argument("--cauchy-scale", type=float, default=defaults.cauchy_scale,
                     help="robust loss scale for points outside, in cloud radii "
                          "(default %(default)s)")
    rec.set_defaults(run=_reconstruct_command)

    sim = commands.add_parser("sim", help="write simulated scan bundles of known objects")
    from .sim import cli as sim_cli

    sim_cli.add_arguments(sim)
    sim.set_defaults(run=_sim_command)

    demo = commands.add_parser("demo", help="simulate a scan, reconstruct it, compare with the truth")
    demo.add_argument("--out", default="runs/demo", help="where to write the scan (default %(default)s)")
    demo.add_argument("--seed", type=int, default=7)
    demo.set_defaults(run=_demo_command)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    try:
        return args.run(args)
    except ValueError as exc:  # option values the parser could not check
        print(f"robocell {args.command}: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
