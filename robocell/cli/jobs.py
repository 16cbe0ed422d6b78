"""``robocell scan``, ``background``, ``jobs``, ``job``, ``status`` and ``cancel``: the cell from a shell."""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import sys
import time
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, TextIO

from .command import Commands

if TYPE_CHECKING:
    from robocell.wire.client import AsyncCellClient
    from robocell.wire.messages import CellStatus, JobEvent, ScanRequest

__all__ = ["register", "format_status", "format_result", "print_event"]

#: As a shell reports a program that Ctrl-C stopped.
_INTERRUPTED = 130
_POSES_SHAPE = "a JSON list of 2 to 16 4x4 flange poses (flange-to-base, metres)"

Action = Callable[["AsyncCellClient", argparse.Namespace], Awaitable[int]]


def register(commands: Commands) -> None:
    scan = commands.add("scan", _command(_scan, _scan_request),
                        help="submit a scan job, show its progress, print the result")
    views = scan.add_mutually_exclusive_group(required=True)
    views.add_argument("--target", nargs=3, type=float, metavar=("X", "Y", "Z"),
                       help="point to look at, robot base frame, metres (views from the configured plan)")
    views.add_argument("--poses", metavar="FILE", help=_POSES_SHAPE)
    scan.add_argument("--pick", action="store_true",
                      help="after the scan, pick the object up with the best grasp the robot can reach, and lift it")
    scan.add_argument("--place", nargs=2, type=float, metavar=("X", "Y"),
                      help="with --pick: then set it down here on the table, as it stood (base frame, metres)")
    scan.add_argument("--label", default="", help="free text stored with the job")
    scan.add_argument("--request-id", help="client-chosen id: submitting it again returns the same job")
    scan.add_argument("--timeout", type=float, default=300.0, help="seconds to wait (default %(default)s)")
    scan.add_argument("--no-wait", action="store_true", help="print the job id and return")
    scan.add_argument("--json", action="store_true",
                      help="print the result as one JSON document (the progress goes to stderr)")

    background = commands.add(
        "background", _command(_scan, _background_request),
        help="before the object is put there, photograph the empty workspace from a scan's poses: later "
             "scans from those poses use the pictures as their views' backgrounds")
    where = background.add_mutually_exclusive_group(required=True)
    where.add_argument("--target", nargs=3, type=float, metavar=("X", "Y", "Z"),
                       help="the point the later scan looks at, robot base frame, metres (its views from the "
                            "configured plan)")
    where.add_argument("--poses", metavar="FILE", help=_POSES_SHAPE)
    background.add_argument("--label", default="", help="free text stored with the job")
    background.add_argument("--request-id", help="client-chosen id: submitting it again returns the same job")
    background.add_argument("--timeout", type=float, default=300.0, help="seconds to wait (default %(default)s)")
    background.add_argument("--no-wait", action="store_true", help="print the job id and return")
    background.add_argument("--json", action="store_true",
                            help="print the job's final JobStatus as JSON (the progress goes to stderr)")

    jobs = commands.add("jobs", _command(_jobs, _job_states), help="list the cell's jobs, newest first")
    jobs.add_argument("--state", action="append", metavar="STATE",
                      help="only jobs in this state (queued, succeeded, failed, ...); may be repeated")
    jobs.add_argument("--limit", type=int, default=20)
    jobs.add_argument("--json", action="store_true", help="print the jobs' JobStatus as one JSON list")

    job = commands.add("job", _command(_job), help="show one job's status and, if done, its result")
    job.add_argument("job_id")
    job.add_argument("--json", action="store_true",
                     help="(the default) one JSON document: the JobStatus, with the ScanResult in 'result'")

    status = commands.add("status", _command(_status), help="the cell at a glance: workers and their load, the "
                                                            "queue, jobs by state, recent failures")
    status.add_argument("--failures", type=int, default=10, help="recent failures to show (default %(default)s)")
    status.add_argument("--json", action="store_true", help="print the daemon's CellStatus as JSON")

    cancel = commands.add("cancel", _command(_cancel), help="cancel a job")
    cancel.add_argument("job_id")
    cancel.add_argument("--token", help="the job's token, from its submit's answer (only its client may cancel it)")
    cancel.add_argument("--json", action="store_true", help="print the job's JobStatus as JSON")


def _command(action: Action, prepare: Callable[[argparse.Namespace], object] | None = None):
    """The run function of a client command: ``prepare`` checks the command's own input first (before
    any connection), then ``action`` talks to the cell's daemon."""

    def run(args: argparse.Namespace) -> int:
        from robocell.wire.config import load_config
        from robocell.wire.errors import AccessDenied, CellError, NoResponder

        config = load_config(args.config)
        args.cell_config = config
        if prepare is not None:
            args.prepared = prepare(args)
        try:
            return asyncio.run(_connected(action, args, config))
        except AccessDenied as exc:   # the daemon is up, and the router dropped this user's query
            print(f"robocell {args.command}: {exc}", file=sys.stderr)
            return 1
        except NoResponder:
            # Every query of these commands goes to the daemon: nobody answering means there is none,
            # or (Zenoh's access control drops a denied query unanswered) that this user may not ask it.
            denied = (f", or the router's access control does not let user {config.zenoh.user!r} ask it"
                      if config.zenoh.user is not None else "")
            print(f"robocell {args.command}: no cell daemon is running for cell {config.cell_id} at "
                  f"{config.zenoh.router}{denied}", file=sys.stderr)
            return 1
        except (CellError, TimeoutError) as exc:
            print(f"robocell {args.command}: {exc}", file=sys.stderr)
            return 1

    return run


async def _connected(action: Action, args: argparse.Namespace, config) -> int:
    from robocell.wire.client import AsyncCellClient

    client = await AsyncCellClient.connect(config.zenoh.router, config.cell_id,
                                           settings=config.zenoh.client_settings())
    async with client:
        return await action(client, args)


def print_event(event: JobEvent, file: TextIO | None = None) -> None:
    """One line of a job's progress (on stdout, or ``file``)."""
    print(f"  {time.strftime('%H:%M:%S', time.localtime(event.time))}  {event.state.value:<14} {event.message}",
          file=file or sys.stdout, flush=True)


def _scan_request(args: argparse.Namespace) -> ScanRequest:
    """The request, checked before connecting; a bad poses file is one line naming what is wrong."""
    import numpy as np
    from pydantic import ValidationError

    from robocell.wire.messages import PickRequest, ScanRequest, field_errors

    kind = getattr(args, "kind", "scan")
    if kind == "scan" and args.place is not None and not args.pick:
        raise ValueError("--place goes with --pick")
    pick = PickRequest(place=args.place) if kind == "scan" and args.pick else None
    if args.poses is None:
        return ScanRequest(target=args.target, label=args.label, request_id=args.request_id, pick=pick, kind=kind)
    try:
        with open(args.poses, encoding="utf-8") as file:
            poses = json.load(file)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{args.poses}: not JSON ({exc}); expected {_POSES_SHAPE}") from None
    try:
        shape = np.asarray(poses, dtype=np.float64).shape
    except (ValueError, TypeError):
        shape = None  # ragged, or not numbers
    if shape is None or len(shape) != 3 or shape[1:] != (4, 4):
        got = "not an array of numbers" if shape is None else f"an array of shape {shape}"
        raise ValueError(f"{args.poses}: expected {_POSES_SHAPE}, got {got}")
    try:
        return ScanRequest(flange_poses=poses, label=args.label, request_id=args.request_id, pick=pick, kind=kind)
    except ValidationError as exc:
        first = field_errors(exc, at_most=1).split("; ")[0]
        others = len(exc.errors()) - 1
        raise ValueError(f"{args.poses}: {first}{f' (and {others} more)' if others else ''}") from None


def _background_request(args: argparse.Namespace) -> ScanRequest:
    """A request of ``kind: backgrounds``: the views of a scan, of the empty workspace."""
    args.kind = "backgrounds"
    return _scan_request(args)


async def _scan(client: AsyncCellClient, args: argparse.Namespace) -> int:
    """Submit, show the progress, print the result; Ctrl-C cancels the job (a second leaves it running)."""
    from robocell.wire.errors import CellError

    # Progress is for a person: with --json it goes to stderr, and stdout has the one JSON document.
    progress = sys.stderr if args.json else sys.stdout
    interrupts: asyncio.Queue[None] = asyncio.Queue()
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGINT, interrupts.put_nowait, None)
    if not args.no_wait:
        client.listen()  # before the submit: the job's first events can come before its answer
    # A Ctrl-C during the submit is heard once its answer says which job to cancel.
    try:
        status = await client.submit(args.prepared)
    except CellError as exc:
        hint = _plan_hint(args, exc)
        if not hint:
            raise
        print(f"robocell {args.command}: {exc}{hint}", file=sys.stderr)
        return 1
    job_id = status.job_id
    print(f"job {job_id} {status.state.value}", file=progress, flush=True)
    if args.no_wait:
        if args.json:
            print(status.model_dump_json())
        return 0
    began = loop.time()
    return await _watch(client, args, job_id, interrupts, progress, began)


async def _watch(client: AsyncCellClient, args: argparse.Namespace, job_id: str, interrupts: asyncio.Queue,
                 progress: TextIO, began: float) -> int:
    from robocell.wire.errors import CellError
    from robocell.wire.messages import JobState

    loop = asyncio.get_running_loop()
    heard = ["queued"]  # the job's last state, as its events told

    def on_event(event: JobEvent) -> None:
        heard[0] = event.state.value
        print_event(event, file=progress)

    waiting = asyncio.ensure_future(client.wait(job_id, timeout=args.timeout, on_event=on_event))
    cancelling: asyncio.Future | None = None
    try:
        if await _first(waiting, interrupts):
            print(f"Ctrl-C: cancelling job {job_id} (Ctrl-C again leaves it running)", file=sys.stderr, flush=True)
            # The cancel is asked while the next Ctrl-C is listened for: a cell slow to answer keeps no one waiting.
            cancelling = asyncio.ensure_future(client.cancel(job_id))
            if await _first(waiting, interrupts):
                print(f"job {job_id} was {heard[0]} when last heard of, and this command no longer watches it: "
                      f"watch it with robocell job {job_id}, cancel it with robocell cancel {job_id}",
                      file=sys.stderr, flush=True)
                return _INTERRUPTED
            final = waiting.result()
            if cancelling.done() and not cancelling.cancelled() and isinstance(cancelling.exception(), CellError):
                print(f"robocell {args.command}: the cancel was refused: {cancelling.exception()}", file=sys.stderr)
            print(f"job {final.job_id} {final.state.value}" + (f": {final.error}" if final.error else ""),
                  file=sys.stderr, flush=True)
            return _INTERRUPTED
        final = waiting.result()
    except TimeoutError:
        print(f"robocell {args.command}: job {job_id} is not finished after {args.timeout:g} s: it goes on; "
              f"watch it with robocell job {job_id}, cancel it with robocell cancel {job_id}", file=sys.stderr)
        return 1
    finally:
        waiting.cancel()
        if cancelling is not None and not cancelling.done():
            cancelling.cancel()  # sent already: the cell acts on it whether or not its answer is heard
        await asyncio.gather(waiting, *([cancelling] if cancelling else []), return_exceptions=True)
    if final.state is not JobState.SUCCEEDED:
        print(f"job {final.job_id} {final.state.value}: {final.error or ''}", file=sys.stderr)
        if args.json:
            print(final.model_dump_json())
        return 1
    if final.request.kind == "backgrounds":  # no model: the backgrounds are kept by the cell
        if args.json:
            print(final.model_dump_json())
        else:
            print(f"job {final.job_id}: {final.n_views} backgrounds kept; scans from these poses use them")
        return 0
    result = await client.result(final.job_id)
    if args.json:
        print(json.dumps(_summary(result)))
    else:
        print(format_result(result, seconds=loop.time() - began))
    return 0


def _plan_hint(args: argparse.Namespace, error: Exception) -> str:
    """For views planned around ``--target`` that the workspace refuses: the setting that moves them."""
    if args.target is None or "outside the workspace" not in str(error):
        return ""
    plan = args.cell_config.scan.plan
    return (f" (the views are planned {plan.standoff:g} m from the target, at elevations "
            f"{', '.join(f'{e:g}' for e in plan.elevations_deg)} deg: [scan] plan standoff, or elevations_deg, "
            f"of the configuration moves them)")


async def _first(waiting: asyncio.Future, interrupts: asyncio.Queue) -> bool:
    """Wait for ``waiting`` to end or a Ctrl-C to come: whether a Ctrl-C came first."""
    interrupted = asyncio.ensure_future(interrupts.get())
    try:
        await asyncio.wait({waiting, interrupted}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        interrupted.cancel()
    if interrupted.done() and not interrupted.cancelled():
        return True
    waiting.result()  # its error, if it had one
    return False


def _summary(result) -> dict:
    """The result's essentials, as ``scan --json`` prints them."""
    return {"job_id": result.job_id, "superquadric": result.superquadric.model_dump(),
            "silhouette_iou": result.silhouette_iou, "timings_ms": result.timings_ms,
            "grasps": [grasp.model_dump() for grasp in result.grasps[:3]],
            "pick": None if result.pick is None else result.pick.model_dump(),
            "recording": result.recording}


def format_result(result, *, seconds: float | None = None) -> str:
    """A finished scan's result as a few lines for a person."""
    sq = result.superquadric
    size = " x ".join(f"{2 * a * 100:.1f}" for a in sq.size)
    centre = ", ".join(f"{v:.3f}" for v in (row[3] for row in sq.T_world_object[:3]))
    took = f" in {seconds:.1f} s" if seconds is not None else ""
    lines = [f"job {result.job_id} succeeded{took}: a superquadric {size} cm (shape {sq.shape[0]:.2f}, "
             f"{sq.shape[1]:.2f}) centred at [{centre}] m",
             "  silhouette IoU " + ", ".join(f"{v:.3f}" for v in result.silhouette_iou)
             + f"; reconstruction {result.timings_ms.get('total', 0.0):.1f} ms"]
    if result.grasps:
        best = result.grasps[0]
        lines.append(f"  {len(result.grasps)} grasps; the best: {best.approach}, closing across "
                     f"{best.width * 100:.2f} cm, score {best.score:.2f}")
    else:
        lines.append("  no grasp of the cell's gripper holds it")
    if result.pick is not None:
        verdict = {True: "held it", False: "missed it", None: "cannot tell whether it held"}[result.pick.held]
        lines.append(f"  pick with grasp {result.pick.grasp}: {verdict}"
                     + (f" ({result.pick.reason})" if result.pick.reason and not result.pick.held else "")
                     + (", and placed it" if result.pick.placed else ""))
    if result.recording:
        lines.append(f"  recording {result.recording}; replay it: robocell replay {result.job_id}")
    else:
        lines.append(f"  no recording: {result.recording_error}")
    lines.append(f"  its model for a simulator or MoveIt: robocell export {result.job_id} --format urdf")
    return "\n".join(lines)


def _job_states(args: argparse.Namespace) -> set | None:
    from robocell.wire.messages import JobState

    known = [state.value for state in JobState]
    unknown = [state for state in args.state or [] if state not in known]
    if unknown:
        raise ValueError(f"--state {unknown[0]}: no such state; the states are {', '.join(known)}")
    return {JobState(s) for s in args.state} if args.state else None


async def _jobs(client: AsyncCellClient, args: argparse.Namespace) -> int:
    listed = await client.list(args.prepared, args.limit)
    if args.json:
        print(json.dumps([job.model_dump(mode="json") for job in listed], indent=1))
        return 0
    for job in listed:
        created = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(job.created))
        print(f"{job.job_id}  {created}  {job.state.value:<14} {job.error or job.request.label}")
    return 0


async def _job(client: AsyncCellClient, args: argparse.Namespace) -> int:
    from robocell.wire.messages import JobState

    status = await client.status(args.job_id)
    document = status.model_dump(mode="json")
    document["result"] = ((await client.result(args.job_id)).model_dump(mode="json")
                          if status.state is JobState.SUCCEEDED else None)
    print(json.dumps(document, indent=1))
    return 0


async def _status(client: AsyncCellClient, args: argparse.Namespace) -> int:
    overview = await client.cell_status(failures=args.failures)
    print(overview.model_dump_json(indent=1) if args.json else format_status(overview))
    return 0


async def _cancel(client: AsyncCellClient, args: argparse.Namespace) -> int:
    status = await client.cancel(args.job_id, args.token)
    print(status.model_dump_json(indent=1) if args.json else
          f"job {status.job_id}: cancel requested ({status.state.value})")
    return 0


# --- status --------------------------------------------------------------------------------------

def _age(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def _table(headers: list[str], rows: list[list[str]], indent: str = "  ") -> list[str]:
    """Columns as wide as their widest cell; the first left-aligned, the others right-aligned."""
    widths = [max(len(cell) for cell in column) for column in zip(headers, *rows)]

    def line(cells: list[str]) -> str:
        first = cells[0].ljust(widths[0])
        return indent + "  ".join([first, *(cell.rjust(width) for cell, width in zip(cells[1:], widths[1:]))])

    return [line(headers), *(line(row) for row in rows)]


def format_status(status: CellStatus) -> str:
    """The cell's status as a few lines of text for a terminal."""
    lines = [f"cell {status.cell}: daemon up {_age(status.time - status.started)}",
             "workers: " + ", ".join(f"{part} {'up' if alive else 'DOWN'}" for part, alive in status.workers.items())]
    pool = status.reconstructors
    healthy = [r for r in pool if r.healthy]
    lines.append(f"reconstructors: {len(pool)} live, capacity {sum(r.capacity for r in healthy)}, "
                 f"{sum(r.in_flight for r in pool)} in flight")
    if pool:
        rows = []
        for r in pool:
            heard = "none yet" if r.heartbeat_age_s is None else f"{r.heartbeat_age_s:.1f} s ago"
            rows.append([r.worker, str(r.capacity), str(r.in_flight), str(r.in_flight_here),
                         heard if r.healthy else f"SILENT {heard}", str(r.sent), str(r.failed)])
        lines += _table(["worker", "capacity", "load", "of ours", "heartbeat", "sent", "failed"], rows)
    lines.append(f"queue: {status.queued} waiting for the robot (at most {status.max_queued}), "
                 f"{status.waiting_for_reconstructor} for a reconstructor")
    lines.append("jobs: " + ", ".join(f"{state} {n}" for state, n in status.jobs.items()))
    if status.disk is not None:
        disk, mb = status.disk, 1024 * 1024
        free = "" if disk.free_on_disk is None else f", {disk.free_on_disk / mb:.0f} MB free on its disk"
        total = disk.recordings + disk.pictures + disk.backgrounds + disk.store + disk.other
        to_free = disk.recordings_to_free + disk.pictures_to_free + disk.backgrounds_to_free
        lines.append(f"disk: {total / mb:.1f} MB "
                     f"(recordings {disk.recordings / mb:.1f}, pictures {disk.pictures / mb:.1f}, "
                     f"backgrounds {disk.backgrounds / mb:.1f}, store {disk.store / mb:.1f}){free}; retention "
                     f"will free {to_free / mb:.1f} MB and {disk.jobs_to_prune} jobs")
        from robocell.cell.reserve import MIN_FREE_BYTES

        if disk.free_on_disk is not None and disk.free_on_disk < MIN_FREE_BYTES:
            lines.append(f"disk FULL: no new job is taken until {MIN_FREE_BYTES / mb:.0f} MB are free on it")
    if status.recent_failures:
        lines.append("recent failures:")
        for failure in status.recent_failures:
            when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(failure.updated))
            lines.append(f"  {failure.job_id}  {when}  {failure.error}")
    return "\n".join(lines)
