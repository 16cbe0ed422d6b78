"""``robocell demo`` (``make demo``): a whole simulated scan, end to end, no hardware.

Starts a cell (router, simulated robot, simulated Axis camera, camera and
reconstruction workers, daemon) on free local ports, submits a scan of the
simulated object, shows its progress, prints the superquadric beside the
truth with their volumetric IoU, and says how to replay the recording.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import random
import socket
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from .command import Commands

if TYPE_CHECKING:
    from robocell.wire.config import CellConfig

__all__ = ["register", "free_port", "local_config"]


def register(commands: Commands) -> None:
    demo = commands.add("demo", _run, help="run a simulated cell, scan an object, compare with the truth")
    demo.add_argument("--run-dir", default="runs/demo", help="where the cell keeps its files (default %(default)s)")


def free_port() -> int:
    """A TCP port nobody listens on now, on loopback, chosen at random below the ports the system hands out
    for outgoing connections and for port 0 (32768 up on Linux, 49152 up on macOS and Windows).

    The cell binds it seconds later, once its processes have started; a port from that range, released
    meanwhile, may be taken by one of their own connections.

    Raises
    ------
    OSError
        If no port of the range could be bound (after :data:`_PORT_TRIES` tries).
    """
    pick = random.SystemRandom()
    for _ in range(_PORT_TRIES):
        port = pick.randrange(*_PORTS)
        with socket.socket() as probe:
            try:
                probe.bind(("127.0.0.1", port))
            except OSError:
                continue
        return port
    raise OSError(f"no free TCP port on 127.0.0.1 between {_PORTS[0]} and {_PORTS[1] - 1}")


#: The ports :func:`free_port` chooses from: registered ports no system hands out on its own.
_PORTS = (20000, 32768)
_PORT_TRIES = 200


def local_config(run_dir: str | Path, **fields) -> CellConfig:
    """A cell on this machine, its router and its camera on free loopback ports.

    ``fields`` are the configuration's other top-level fields; a section given as a dict
    is merged into the one made here (``camera={"timeout_s": 1.0}`` keeps the free port).
    """
    from robocell.wire.config import CellConfig

    data: dict = {"run_dir": str(run_dir), "zenoh": {"router": f"tcp/127.0.0.1:{free_port()}"},
                  "camera": {"url": f"http://127.0.0.1:{free_port()}"}}
    for key, value in fields.items():
        both = isinstance(data.get(key), dict) and isinstance(value, dict)
        data[key] = {**data[key], **value} if both else value
    return CellConfig.model_validate(data)


def _row(name: str, truth, fit) -> str:
    fmt = lambda values: "  ".join(f"{v:8.4f}" for v in values)  # noqa: E731
    return f"  {name:<10} {fmt(truth):<32} {fmt(fit)}"


#: As a shell reports a program that Ctrl-C stopped.
_INTERRUPTED = 130
#: How long an interrupted demo waits for its job's cancel to be accepted.
_CANCEL_WAIT_S = 3.0


async def _demo(run_dir: Path, cells: list) -> int:
    import numpy as np

    from robocell.core_cy.scoring import centre_error, volumetric_iou
    from robocell.core_cy.superquadric import Superquadric
    from robocell.wire.client import AsyncCellClient
    from robocell.wire.errors import CellError
    from robocell.wire.messages import JobState, PickRequest, ScanRequest
    from robocell.workers.sim.scene import truth_from_config

    from .jobs import print_event
    from .up import _STOP_WAIT_S, CellProcesses, on_interrupt

    # The simulated camera renders each picture on this machine's CPU (a printed box, its shadow, an
    # oak table): seconds on a busy machine, where an Axis camera answers in a fraction of one.
    config = local_config(run_dir, camera={"timeout_s": 15.0, "retries": 1}, timeouts={"capture_s": 40.0})
    truth = Superquadric.from_dict(truth_from_config(config.sim))
    target = truth.T_world_object[:3, 3]
    print(f"starting a simulated cell in {run_dir} (a {config.sim.shape} on the table at "
          f"{np.round(target, 3).tolist()} m)", flush=True)
    cell = CellProcesses(config)
    cells.append(cell)
    job: list[str] = []   # the job's id, once submitted: an interrupted demo cancels it

    async def scan():
        await cell.start()
        async with await AsyncCellClient.connect(config.zenoh.router, config.cell_id) as client:
            # Scan it, then pick it up and set it down 15 cm to the side.
            place = [float(target[0]), float(target[1]) + 0.15]
            request = ScanRequest(target=target.tolist(), label="demo", pick=PickRequest(place=place))
            client.listen()  # before the submit: the job's first events can come before its answer
            status = await client.submit(request)
            job.append(status.job_id)
            try:
                final = await client.wait(status.job_id, timeout=120, on_event=print_event)
            except asyncio.CancelledError:
                # Stopped by Ctrl-C: the job must not go on moving the robot, nor carry on at the next
                # demo (the run directory keeps its jobs). The cancel is asked for, and not waited for long.
                with contextlib.suppress(CellError, TimeoutError):
                    async with asyncio.timeout(_CANCEL_WAIT_S):
                        await client.cancel(status.job_id)
                raise
            if final.state is not JobState.SUCCEEDED:
                raise CellError(f"job {final.job_id} {final.state.value}: {final.error or 'no reason given'}")
            return await client.result(status.job_id)

    work = asyncio.ensure_future(scan())
    interrupts = on_interrupt(work, again=f"still stopping the simulated cell (each part gets {_STOP_WAIT_S:g} s, "
                                         f"then is killed)")
    try:
        result = await work
    except asyncio.CancelledError:
        if not interrupts():
            raise
        print("interrupted: stopping the simulated cell" + (f" (job {job[0]} cancelled)" if job else ""),
              file=sys.stderr, flush=True)
        return _INTERRUPTED
    except CellError as exc:
        print(f"robocell demo: {exc}", file=sys.stderr)
        return 1
    finally:
        await cell.stop()

    fit = Superquadric.from_dict(result.superquadric.model_dump())
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
    print(f"\ngrasps of the cell's gripper (opening {config.gripper.max_opening * 100:.1f} cm), best first:")
    for index, grasp in enumerate(result.grasps[:5]):
        T = np.asarray(grasp.T_world_grasp)
        print(f"  {index}  {grasp.approach:<6} closing across {grasp.width * 100:5.2f} cm at "
              f"{np.round(T[:3, 3], 3).tolist()} m, score {grasp.score:.2f}"
              + ("   <- picked with" if result.pick is not None and result.pick.grasp == index else ""))
    if result.pick is not None:
        verdict = {True: "held it", False: "missed it", None: "cannot tell"}[result.pick.held]
        print(f"  the pick, judged against the true object: {verdict}"
              + (f" ({result.pick.reason})" if result.pick.reason and not result.pick.held else "")
              + (", and put it down 15 cm to the side" if result.pick.placed else ""))
    robocell = Path(sys.executable).with_name("robocell")  # this venv's: .venv, or .venv-3.13 for another Python
    if robocell.is_relative_to(Path.cwd()):
        robocell = robocell.relative_to(Path.cwd())
    print(f"\nrecording: {result.recording}\nreplay it:  {robocell} replay {result.recording}"
          f"   (or --web for the web viewer)")
    return 0


def _run(args: argparse.Namespace) -> int:
    cells: list = []
    try:
        return asyncio.run(_demo(Path(args.run_dir), cells))
    finally:
        for cell in cells:  # only if the stop in _demo could not finish: its loop went away first
            cell.kill_remaining()
