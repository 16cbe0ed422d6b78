"""The ``robocell`` command: one entry point for every part of robocell."""

from __future__ import annotations

import os

# The fit's 11-parameter L-BFGS-B gains nothing from BLAS threads, and loses a lot to them on a
# busy machine (measured: 4 ms alone, 15-97 ms beside another process). This must precede numpy.
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse
import json
import logging
import sys

from core_cy.errors import CoreError
from core_cy.reconstruct import Options, reconstruct

from . import keys
from .bundle import load_bundle
from .config import CellConfig, load_config
from .errors import BundleError, CellError

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


def _config(args: argparse.Namespace) -> CellConfig:
    return load_config(args.config)


def _sim_command(args: argparse.Namespace) -> int:
    if args.what == "camera":
        from workers import sim_camera_worker

        return sim_camera_worker.main(_config(args))
    if args.what == "kuka":
        from .sim import kuka

        return kuka.run(args)
    from .sim import cli as sim_cli

    return sim_cli.run(args)


def _worker_id(text: str) -> str:
    if not keys.WORKER_ID.fullmatch(text):
        raise argparse.ArgumentTypeError(f"{text!r}: use letters, digits, '.', '_' and '-' (starting with a letter "
                                         f"or digit), at most 128")
    return text


def _worker_command(args: argparse.Namespace) -> int:
    config = _config(args)
    if args.kind == "robot":
        from workers import robot

        return robot.main(config)
    if args.kind == "camera":
        from workers import camera

        return camera.main(config)
    from workers import reconstruct as reconstructor

    return reconstructor.main(config, args.id)


def _router_command(args: argparse.Namespace) -> int:
    from .service import run_router

    return run_router(_config(args), args.listen)


def _cell_command(args: argparse.Namespace) -> int:
    from .service import run_daemon

    return run_daemon(_config(args))


def _up_command(args: argparse.Namespace) -> int:
    from .up import up

    return up(_config(args))


def _client_command(args: argparse.Namespace) -> int:
    from . import client_cli

    return client_cli.run(args, _config(args))


def _replay_command(args: argparse.Namespace) -> int:
    import subprocess

    from .recording import find_recording, replay_command

    path = find_recording(args.job, _config(args).run_dir)
    argv = replay_command(path, web=args.web, web_port=args.web_port, grpc_port=args.grpc_port)
    if args.web:
        print(f"serving {path} at http://127.0.0.1:{args.web_port} (Ctrl-C stops)", flush=True)
    return subprocess.call(argv)


def _config_command(args: argparse.Namespace) -> int:
    print(_config(args).model_dump_json(indent=2))
    return 0


def _demo_command(args: argparse.Namespace) -> int:
    from .demo import run_demo

    return run_demo(args)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The ``robocell`` parser; with ``only="reconstruct"``, that command alone (see :func:`main`)."""
    defaults = Options()
    parser = argparse.ArgumentParser(
        prog="robocell", description="Graspable superquadric models of unknown objects, from a robot cell.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    parser.add_argument("--config", metavar="FILE", help="cell configuration, TOML (default: built-in)")
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
                     help="weight of points inside the superquadric; 1 = plain Jaklic (default %(default)s)")
    rec.add_argument("--cauchy-scale", type=float, default=defaults.cauchy_scale,
                     help="robust loss scale for points outside, in cloud radii (default %(default)s)")
    rec.set_defaults(run=_reconstruct_command)
    if only == "reconstruct":
        return parser

    sim = commands.add_parser(
        "sim", help="write simulated scan bundles; `sim camera`: a simulated Axis camera; "
                    "`sim kuka`: a simulated KUKA controller")
    sim.add_argument("what", nargs="?", choices=["scans", "camera", "kuka"], default="scans",
                     help="scans (default): write bundles; camera: serve the cell's simulated camera; "
                          "kuka: a KUKA controller speaking KukaVarProxy (kvp) or the OpenOPC gateway (opc)")
    from .sim import cli as sim_cli
    from .sim import kuka as sim_kuka

    sim_cli.add_arguments(sim)
    sim_kuka.add_arguments(sim)
    sim.set_defaults(run=_sim_command)

    router = commands.add_parser("router", help="run the Zenoh router the cell's processes connect to")
    router.add_argument("--listen", metavar="ENDPOINT", help="endpoint (default: zenoh.router of the config)")
    router.set_defaults(run=_router_command)

    worker = commands.add_parser("worker", help="run a robot, camera or reconstruction worker")
    worker.add_argument("kind", choices=["robot", "camera", "reconstruct"])
    worker.add_argument("--id", type=_worker_id, help="reconstruction worker id: letters, digits, '.', '_' "
                                                       "and '-' (default: host-pid)")
    worker.set_defaults(run=_worker_command)

    commands.add_parser("cell", help="run the cell daemon").set_defaults(run=_cell_command)
    commands.add_parser("up", help="run router, workers, simulated camera and daemon; Ctrl-C stops all") \
        .set_defaults(run=_up_command)

    from . import client_cli

    client_cli.add_commands(commands, _client_command)

    from . import calibrate_cli

    calibrate_cli.add_commands(commands)

    replay = commands.add_parser("replay", help="open a job's Rerun recording in the viewer")
    replay.add_argument("job", metavar="JOB_ID_OR_FILE")
    replay.add_argument("--web", action="store_true", help="serve the web viewer on a local port instead")
    replay.add_argument("--web-port", type=int, default=9090)
    replay.add_argument("--grpc-port", type=int, default=9876)
    replay.set_defaults(run=_replay_command)

    commands.add_parser("config", help="print the configuration in effect (defaults + --config)") \
        .set_defaults(run=_config_command)

    demo = commands.add_parser("demo", help="run a simulated cell, scan an object, compare with the truth")
    demo.add_argument("--run-dir", default="runs/demo", help="where the cell keeps its files (default %(default)s)")
    demo.set_defaults(run=_demo_command)
    return parser


def _command(argv: list[str]) -> str | None:
    """The command word of a command line: its first argument that is neither an option nor --config's value."""
    words = iter(argv)
    for word in words:
        if word == "--config":
            next(words, None)
        elif not word.startswith("-"):
            return word
    return None


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    # Building every command's options imports every command's modules (the KUKA simulator's scipy,
    # the client's Zenoh): most of a second, more than a batch of reconstructions takes.
    only = "reconstruct" if _command(argv) == "reconstruct" else None
    args = build_parser(only).parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    try:
        return args.run(args)
    except (CellError, OSError) as exc:  # OSError: a file or directory that cannot be read or made
        print(f"robocell {args.command}: {exc}", file=sys.stderr)
        return 1
    except ValueError as exc:  # option values the parser could not check
        print(f"robocell {args.command}: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
