"""``robocell router``, ``worker robot|camera|reconstruct``, ``cell`` and ``up``: the cell's processes.

Each runs until Ctrl-C or SIGTERM; ``up`` runs all of them at once as its
children (``robocell.cli.up``).
"""

from __future__ import annotations

import argparse

from robocell.wire import keys

from .command import Commands

__all__ = ["register"]


def _worker_id(text: str) -> str:
    if not keys.WORKER_ID.fullmatch(text):
        raise argparse.ArgumentTypeError(f"{text!r}: use letters, digits, '.', '_' and '-' (starting with a letter "
                                         f"or digit), at most 128")
    return text


def _config(args: argparse.Namespace):
    from robocell.wire.config import load_config

    return load_config(args.config)


def _router(args: argparse.Namespace) -> int:
    from robocell.cell.service import run_router

    from .up import check_port_free

    config = _config(args)
    endpoint = args.listen or config.zenoh.router
    check_port_free(endpoint, what="the router's port", setting="--listen or [zenoh] router")
    return run_router(config, args.listen)


def _worker(args: argparse.Namespace) -> int:
    config = _config(args)
    if args.kind == "robot":
        from robocell.workers.robot import worker as robot

        return robot.main(config)
    if args.kind == "camera":
        from robocell.workers.camera import worker as camera

        return camera.main(config)
    from robocell.workers.reconstruct import worker as reconstructor

    return reconstructor.main(config, args.id)


def _cell(args: argparse.Namespace) -> int:
    from robocell.cell.service import run_daemon

    return run_daemon(_config(args))


def _up(args: argparse.Namespace) -> int:
    from .up import up

    return up(_config(args))


def register(commands: Commands) -> None:
    router = commands.add("router", _router, help="run the Zenoh router the cell's processes connect to")
    router.add_argument("--listen", metavar="ENDPOINT", help="endpoint (default: zenoh.router of the config)")

    worker = commands.add("worker", _worker, help="run a robot, camera or reconstruction worker")
    worker.add_argument("kind", choices=["robot", "camera", "reconstruct"])
    worker.add_argument("--id", type=_worker_id, help="reconstruction worker id: letters, digits, '.', '_' "
                                                       "and '-' (default: host-pid)")

    commands.add("cell", _cell, help="run the cell daemon")
    commands.add("up", _up, help="run router, workers, daemon (and the simulated camera where the configuration "
                                 "needs it) on this machine; Ctrl-C stops all")
