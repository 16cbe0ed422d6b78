"""``robocell demo`` (``make demo``): a whole simulated scan, end to end, no hardware.

Starts a cell (router, simulated robot, simulated Axis camera, camera and
reconstruction workers, daemon) on free local ports, submits a scan of the
simulated object, shows its progress, prints the superquadric beside the
truth with their volumetric IoU, and says how to replay the recording.
"""

from __future__ import annotations

import argparse
import asyncio
import socket
import sys
from pathlib import Path

import numpy as np

from core_cy.scoring import centre_error, volumetric_iou
from core_cy.superquadric import Superquadric

from .client import AsyncCellClient
from .client_cli import _print_event
from .config import CellConfig
from .errors import CellError
from .messages import ScanRequest
from .sim.scene import truth_from_config
from .up import CellProcesses

__all__ = ["run_demo", "free_port", "local_config"]


def free_port() -> int:
    """A TCP port nobody listens on now (bound to port 0 on loopback, then released)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def local_config(run_dir: str | Path, **fields) -> CellConfig:
    """A cell on this machine, its router and its camera on free loopback ports.

    ``fields`` are the configuration's other top-level fields; a section given as a dict
    is merged into the one made here (``camera={"timeout_s": 1.0}`` keeps the free port).
    """
    data: dict = {"run_dir": str(run_dir), "zenoh": {"router": f"tcp/127.0.0.1:{free_port()}"},
                  "camera": {"url": f"http://127.0.0.1:{free_port()}"}}
    for key, value in fields.items():
        both = isinstance(data.get(key), dict) and isinstance(value, dict)
        data[key] = {**data[key], **value} if both else value
    return CellConfig.model_validate(data)


def _row(name: str, truth, fit) -> str:
    fmt = lambda values: "  ".join(f"{v:8.4f}" for v in values)  # noqa: E731
    return f"  {name:<10} {fmt(truth):<32} {fmt(fit)}"


async def _demo(run_dir: Path) -> int:
    config = local_config(run_dir)
    truth = Superquadric.from_dict(truth_from_config(config.sim))
    target = truth.T_world_object[:3, 3]
    print(f"starting a simulated cell in {run_dir} (a {config.sim.shape} on the table at "
          f"{np.round(target, 3).tolist()} m)", flush=True)
    cell = CellProcesses(config)
    try:
        await cell.start()
        async with await AsyncCellClient.connect(config.zenoh.router, config.cell_id) as client:
            result = await client.scan(ScanRequest(target=target.tolist(), label="demo"), timeout=120,
                                       on_event=_print_event)
    except CellError as exc:
        print(f"robocell demo: {exc}", file=sys.stderr)
        return 1
    finally:
        await cell.stop()

    fit = Superquadric.from_dict(result.superquadric)
    print(f"\nsuperquadric of job {result.job_id}:        truth                            fit")
    # Axis order is a choice of parameterisation (DESIGN.md §1): compare the sizes sorted.
    print(_row("size (m)", np.sort(truth.size), np.sort(fit.size)))
    print(_row("shape", truth.shape, fit.shape))
    print(_row("centre (m)", truth.T_world_object[:3, 3], fit.T_world_object[:3, 3]))
    print(f"  volumetric IoU {volumetric_iou(truth, fit):.3f}, centre error "
          f"{1000 * centre_error(truth, fit):.1f} mm, silhouette IoU "
          f"{', '.join(f'{v:.3f}' for v in result.silhouette_iou)}")
    print(f"  reconstruction {result.timings_ms['total']:.1f} ms (" +
          ", ".join(f"{k} {v:.1f}" for k, v in result.timings_ms.items() if k != "total") + ")")
    robocell = Path(sys.executable).with_name("robocell")  # this venv's: .venv, or .venv-3.13 for another Python
    if robocell.is_relative_to(Path.cwd()):
        robocell = robocell.relative_to(Path.cwd())
    print(f"\nrecording: {result.recording}\nreplay it:  {robocell} replay {result.recording}"
          f"   (or --web for the web viewer)")
    return 0


def run_demo(args: argparse.Namespace) -> int:
    return asyncio.run(_demo(Path(args.run_dir)))
