"""``robocell sim scans|camera|kuka``: the simulators, each with only its own options.

``sim scans`` writes simulated scan bundles of known objects (its options:
:func:`add_arguments`, its run: :func:`run`); ``sim camera`` serves the
simulated Axis camera at ``camera.url``, posed by the cell's robot; ``sim
kuka`` is a simulated KUKA controller behind KukaVarProxy or the OpenOPC
gateway.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from robocell.workers.sim.objects import COMPOUND_KINDS, FAMILIES, CupStack, LumpyFigure, SimObject, SuperquadricObject, compound

from .command import Commands

__all__ = ["register", "add_arguments", "run"]

# A flat box is a box thin along z; a plate, a thin cylinder standing on its rim.
PRESETS = {"flat-box": ("box", False), "plate": ("cylinder", True)}
SHAPES = [*FAMILIES, *PRESETS, "cup-stack", "lumpy", *COMPOUND_KINDS]
# Defaults for --size per shape (metres). For a cup stack: bottom radius, rim
# radius, height of one cup; for a lumpy figure: the radii of its ellipsoid.
DEFAULT_SIZE = {
    "box": (0.05, 0.03, 0.025),
    "cylinder": (0.03, 0.03, 0.06),
    "ellipsoid": (0.045, 0.035, 0.03),
    "rounded-box": (0.05, 0.035, 0.03),
    "flat-box": (0.05, 0.04, 0.01),
    "plate": (0.06, 0.06, 0.008),
    "cup-stack": (0.025, 0.038, 0.06),
    "lumpy": (0.05, 0.04, 0.045),
}
_SHAPE_ONLY = ("size", "yaw", "lying", "position", "count", "views", "distance", "elevation", "jpeg_quality",
               "noise", "ambient")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``sim`` options to ``parser``."""
    parser.add_argument("--out", type=Path, default=Path("sim-scans"), metavar="DIR",
                        help="directory to write bundles under (default: sim-scans)")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--set", choices=["standard", "broad", "grasp", "printed", "printed-products", "compound"],
                       dest="set_name",
                       help="write a fixed benchmark set: standard (the default when --shape is not given; "
                            "32 scans), broad (126: seven families, 3, 4 and 6 views, see bench/bench_core.py), "
                            "grasp (bench/bench_grasp.py's scenes, 10 per family), or printed (16: printed "
                            "grocery-like objects on oak, rubber mat, laminate, cutting mat, wood and fabric, "
                            "lit by a lamp that casts their shadows; no segmentation named, true masks as "
                            "truth_mask{i}.png; see bench/bench_segment.py), printed-products (11: the YCB-like "
                            "products, a mug, drill, hammer, banana, bottles, boxes and cans, in parts, wearing "
                            "printed looks on those tables under such a lamp), or compound (22: two of each "
                            "everyday compound object, a bottle, mug, dumbbell, lamp, hammer, ..., truth.json "
                            "listing its parts)")
    which.add_argument("--shape", choices=SHAPES, help="write scans of one object")
    parser.add_argument("--size", type=float, nargs=3, metavar=("A1", "A2", "A3"),
                        help="half-sizes in metres (cup-stack: bottom radius, rim radius, cup height; "
                             "lumpy: ellipsoid radii)")
    parser.add_argument("--yaw", type=float, metavar="DEG", help="turn about the vertical (default 30)")
    parser.add_argument("--lying", action="store_true", default=None,
                        help="superquadric lies on its side; cup-stack: upper cup upright, nested")
    parser.add_argument("--position", type=float, nargs=2, metavar=("X", "Y"),
                        help="where the object stands on the table (default 0.6 0)")
    parser.add_argument("--distance", type=float, nargs=2, metavar=("MIN", "MAX"),
                        help="camera distance range in metres (default 0.4 0.7)")
    parser.add_argument("--elevation", type=float, nargs=2, metavar=("MIN", "MAX"),
                        help="camera elevation range in degrees (default 35 55)")
    parser.add_argument("--views", type=int, metavar="N", help="views per scan (default 3)")
    parser.add_argument("--seed", type=int, default=0, help="seed for cameras, table and noise (default 0)")
    parser.add_argument("--masks", action="store_true", help="also write mask{i}.png (not named in scan.json)")
    parser.add_argument("--supplied-masks", action="store_true",
                        help="write mask{i}.png and name them in scan.json (a reconstruction then uses them)")
    parser.add_argument("--backgrounds", action="store_true",
                        help="also write background{i}.jpg, the empty workspace from each view's pose under the "
                             "same light, and name it as the view's background in scan.json")
    parser.add_argument("--jpeg-quality", type=int, metavar="Q", help="JPEG quality 1-100 (default 90)")
    parser.add_argument("--noise", type=float, metavar="SIGMA",
                        help="sensor noise, standard deviation in grey levels (default 2)")
    parser.add_argument("--ambient", type=float, metavar="A",
                        help="light on the side turned from the lamp, 0-1: the lower, the darker the shaded "
                             "faces (default: the renderer's, workers.sim.render.AMBIENT)")
    parser.add_argument("--count", type=int, metavar="N",
                        help="scans of the object, seeds SEED..SEED+N-1 (default 1)")


def _make_object(args: argparse.Namespace) -> SimObject:
    position = tuple(args.position) if args.position is not None else (0.6, 0.0)
    if args.shape in COMPOUND_KINDS:
        if args.size is not None or args.lying:
            raise ValueError(f"--size and --lying do not apply to {args.shape} (its parts follow --seed)")
        return compound(args.shape, position, 30.0 if args.yaw is None else args.yaw, seed=args.seed)
    size = tuple(args.size) if args.size is not None else DEFAULT_SIZE[args.shape]
    if args.shape == "cup-stack":
        return CupStack(position, *size, top_inverted=not args.lying)
    if args.shape == "lumpy":
        return LumpyFigure(position, size, seed=args.seed)
    yaw = 30.0 if args.yaw is None else args.yaw
    family, lying = PRESETS.get(args.shape, (args.shape, False))
    return SuperquadricObject.on_table(family, size, position, yaw, lying or bool(args.lying))


def run(args: argparse.Namespace) -> int:
    """Write the bundles, print one path per line; 0 on success, 2 on bad options."""
    from robocell.workers.sim.grasp_set import grasp_set
    from robocell.workers.sim.scans import (broad_set, compound_set, make_spec, printed_products_set, printed_set,
                                            standard_set)

    if args.shape is None:
        given = [f"--{name}" for name in _SHAPE_ONLY if getattr(args, name) is not None]
        if given:
            print(f"robocell sim: {', '.join(given)} only apply with --shape", file=sys.stderr)
            return 2
        if args.supplied_masks:
            print("robocell sim: --supplied-masks only applies with --shape", file=sys.stderr)
            return 2
        sets = {"grasp": grasp_set, "broad": broad_set, "printed": printed_set, "standard": standard_set,
                "printed-products": printed_products_set, "compound": compound_set}
        for spec in sets[args.set_name or "standard"](args.seed):
            print(spec.write(args.out, write_masks=args.masks, backgrounds=args.backgrounds), flush=True)
        return 0
    count = 1 if args.count is None else args.count
    views = 3 if args.views is None else args.views
    if count < 1 or views < 1:
        print("robocell sim: --count and --views must be at least 1", file=sys.stderr)
        return 2
    try:
        obj = _make_object(args)
    except ValueError as exc:
        print(f"robocell sim: {exc}", file=sys.stderr)
        return 2
    distance = (args.distance[0], args.distance[1]) if args.distance is not None else (0.4, 0.7)
    elevation = (args.elevation[0], args.elevation[1]) if args.elevation is not None else (35.0, 55.0)
    if not (0 < distance[0] <= distance[1]) or not (0 < elevation[0] <= elevation[1] < 90):
        print("robocell sim: need 0 < MIN <= MAX for --distance and 0 < MIN <= MAX < 90 for --elevation",
              file=sys.stderr)
        return 2
    # What is not given keeps make_spec's defaults.
    given = {"jpeg_quality": args.jpeg_quality, "noise_sigma": args.noise, "ambient": args.ambient}
    look = {name: value for name, value in given.items() if value is not None}
    if not (1 <= look.get("jpeg_quality", 90) <= 100 and look.get("noise_sigma", 0) >= 0
            and 0 <= look.get("ambient", 0) <= 1):
        print("robocell sim: need 1 <= --jpeg-quality <= 100, --noise >= 0 and 0 <= --ambient <= 1",
              file=sys.stderr)
        return 2
    for i in range(count):
        seed = args.seed + i
        spec = make_spec(f"{args.shape}-{seed:03d}", obj, seed, views, distance, elevation,
                         fit_distance=args.distance is None, **look)
        print(spec.write(args.out, write_masks=args.masks, name_masks=args.supplied_masks,
                         backgrounds=args.backgrounds), flush=True)
    return 0


# --- sim camera and sim kuka -----------------------------------------------------------------

#: ``sim kuka --fault`` names, and the simulated controller's.
_FAULTS = {"estop": "emergency_stop", "drives-off": "drives_off", "drop": "drop", "hang": "hang",
           "unreachable": "unreachable", "grip-stuck": "grip_stuck"}


def add_kuka_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``robocell sim kuka``."""
    parser.add_argument("--protocol", choices=["kvp", "opc"],
                        help="kvp: KukaVarProxy over TCP; opc: an OpenOPC gateway (Pyro5) (default: the "
                             "configuration's [robot.kuka] protocol, else kvp)")
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    parser.add_argument("--port", type=int,
                        help="port (default: the configuration's [robot.kuka] port, else the protocol's usual one)")
    parser.add_argument("--fault", choices=sorted(_FAULTS),
                        help="simulate a fault, to try a program's error handling: estop (emergency stop), "
                             "drives-off (a drive fault), drop (the link to the bridge dropped), hang (the "
                             "controller stops answering), unreachable (a pose the arm cannot reach), grip-stuck "
                             "(the gripper's input never changes)")
    parser.add_argument("--fault-after", type=int, default=0, metavar="N",
                        help="with --fault: start it as the program takes its command N + 1, after N moves or "
                             "gripper commands (default 0: the first); SIGUSR1 resets the controller, as after "
                             "acknowledging the fault")
    parser.add_argument("--speed", type=float, default=500.0, metavar="MM_S",
                        help="linear speed at 100 %% override, mm/s (default 500)")
    parser.add_argument("--rotation-speed", type=float, default=90.0, metavar="DEG_S",
                        help="rotation speed at 100 %% override, degrees/s (default 90)")


def _kuka(args: argparse.Namespace) -> int:
    import asyncio

    from robocell.wire.config import load_config
    from robocell.wire.process import run_until_stopped
    from robocell.workers.sim import kuka
    from robocell.workers.sim.robot import SceneGripper

    config = load_config(args.config)
    # The gripper's input confirms a hold where the configuration's [gripper] holds its [sim] object.
    holds = SceneGripper.from_config(config).holds
    # Where the configuration's KUKA bridge would look for it, unless told otherwise.
    configured = config.robot.kuka if config.robot.backend == "kuka" else None
    protocol = args.protocol or (configured.protocol if configured is not None else "kvp")
    port = args.port if args.port is not None else (
        configured.port if configured is not None and configured.protocol == protocol else None)
    if args.fault is None and args.fault_after:
        raise ValueError("--fault-after goes with --fault")
    fault_after = None if args.fault is None else (_FAULTS[args.fault], args.fault_after)

    async def serve(stop: asyncio.Event) -> None:
        await kuka.main(protocol, args.host, port, stop=stop, speed_mm_s=args.speed,
                        rotation_deg_s=args.rotation_speed, holds=holds, fault_after=fault_after)

    return run_until_stopped(serve, "simulated KUKA controller")


def _camera(args: argparse.Namespace) -> int:
    from robocell.wire.config import load_config
    from robocell.workers.sim import axis_process

    return axis_process.main(load_config(args.config))


def register(commands: Commands) -> None:
    sim = commands.group("sim", help="simulators: scan bundles, an Axis camera, a KUKA controller")
    add_arguments(sim.add("scans", run, help="write simulated scan bundles of known objects, with their truth.json",
                          description="Write simulated scan bundles (DESIGN.md §3), one path per line: the "
                                      "standard benchmark set, or scans of one object (--shape)."))
    sim.add("camera", _camera, help="serve the simulated Axis camera at camera.url, posed by the cell's robot")
    add_kuka_arguments(sim.add("kuka", _kuka, help="a simulated KUKA controller speaking KukaVarProxy (kvp) "
                                                  "or the OpenOPC gateway (opc); its gripper holds what the "
                                                  "configuration's [gripper] holds of its [sim] object"))
