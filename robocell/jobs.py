"""``robocell scan``, ``jobs``, ``job``, ``status`` and ``cancel``: the cell from a shell."""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import time

from wire.client import AsyncCellClient
from wire.config import CellConfig
from wire.errors import CellError
from wire.messages import CellStatus, JobEvent, JobState, ScanRequest

__all__ = ["add_commands", "run"]


def add_commands(commands, handler) -> None:
    scan = commands.add_parser("scan", help="submit a scan job, show its progress, print the result")
    views = scan.add_mutually_exclusive_group(required=True)
    views.add_argument("--target", nargs=3, type=float, metavar=("X", "Y", "Z"),
                       help="point to look at, robot base frame, metres (views from the configured plan)")
    views.add_argument("--poses", metavar="FILE", help="JSON list of 4x4 flange poses (flange-to-base)")
    scan.add_argument("--label", default="", help="free text stored with the job")
    scan.add_argument("--request-id", help="client-chosen id: submitting it again returns the same job")
    scan.add_argument("--timeout", type=float, default=300.0, help="seconds to wait (default %(default)s)")
    scan.add_argument("--no-wait", action="store_true", help="print the job id and return")
    scan.set_defaults(run=handler, action="scan")

    jobs = commands.add_parser("jobs", help="list the cell's jobs, newest first")
    jobs.add_argument("--state", action="append", choices=[s.value for s in JobState])
    jobs.add_argument("--limit", type=int, default=20)
    jobs.set_defaults(run=handler, action="jobs")

    job = commands.add_parser("job", help="show one job's status and, if done, its result")
    job.add_argument("job_id")
    job.set_defaults(run=handler, action="job")

    status = commands.add_parser("status", help="the cell at a glance: workers and their load, the queue, "
                                                "jobs by state, recent failures")
    status.add_argument("--failures", type=int, default=10, help="recent failures to show (default %(default)s)")
    status.add_argument("--json", action="store_true", help="print the daemon's CellStatus as JSON")
    status.set_defaults(run=handler, action="status")

    cancel = commands.add_parser("cancel", help="cancel a job")
    cancel.add_argument("job_id")
    cancel.set_defaults(run=handler, action="cancel")


def _print_event(event: JobEvent) -> None:
    print(f"  {time.strftime('%H:%M:%S', time.localtime(event.time))}  {event.state.value:<14} {event.message}",
          flush=True)


async def _scan(client: AsyncCellClient, args: argparse.Namespace) -> int:
    if args.poses:
        with open(args.poses, encoding="utf-8") as file:
            request = ScanRequest(flange_poses=json.load(file), label=args.label, request_id=args.request_id)
    else:
        request = ScanRequest(target=args.target, label=args.label, request_id=args.request_id)
    if not args.no_wait:
        client.listen()  # before the submit: the job's first events can come before its answer
    status = await client.submit(request)
    print(f"job {status.job_id} {status.state.value}", flush=True)
    if args.no_wait:
        return 0
    final = await client.wait(status.job_id, timeout=args.timeout, on_event=_print_event)
    if final.state is not JobState.SUCCEEDED:
        print(f"job {final.job_id} {final.state.value}: {final.error or ''}", file=sys.stderr)
        return 1
    result = await client.result(final.job_id)
    print(json.dumps({"job_id": result.job_id, "superquadric": result.superquadric.model_dump(),
                      "silhouette_iou": result.silhouette_iou, "timings_ms": result.timings_ms,
                      "recording": result.recording}))
    return 0


def _age(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def format_status(status: CellStatus) -> str:
    """The cell's status as a few lines of text for a terminal."""
    lines = [f"cell {status.cell}: daemon up {_age(status.time - status.started)}",
             "workers: " + ", ".join(f"{part} {'up' if alive else 'DOWN'}" for part, alive in status.workers.items())]
    pool = status.reconstructors
    healthy = [r for r in pool if r.healthy]
    lines.append(f"reconstructors: {len(pool)} live, capacity {sum(r.capacity for r in healthy)}, "
                 f"{sum(r.in_flight for r in pool)} in flight")
    if pool:
        lines.append(f"  {'worker':<32}{'capacity':>9}{'load':>6}{'of ours':>8}{'heartbeat':>11}"
                     f"{'sent':>7}{'failed':>7}")
        for r in pool:
            heard = "none yet" if r.heartbeat_age_s is None else f"{r.heartbeat_age_s:.1f} s ago"
            if not r.healthy:
                heard = "SILENT " + heard
            lines.append(f"  {r.worker:<32}{r.capacity:>9}{r.in_flight:>6}{r.in_flight_here:>8}{heard:>11}"
                         f"{r.sent:>7}{r.failed:>7}")
    lines.append(f"queue: {status.queued} waiting for the robot (at most {status.max_queued}), "
                 f"{status.waiting_for_reconstructor} for a reconstructor")
    lines.append("jobs: " + ", ".join(f"{state} {n}" for state, n in status.jobs.items()))
    if status.recent_failures:
        lines.append("recent failures:")
        for failure in status.recent_failures:
            when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(failure.updated))
            lines.append(f"  {failure.job_id}  {when}  {failure.error}")
    return "\n".join(lines)


async def _run(args: argparse.Namespace, config: CellConfig) -> int:
    client = await AsyncCellClient.connect(config.zenoh.router, config.cell_id, settings=config.zenoh.client_settings())
    async with client:
        if args.action == "scan":
            return await _scan(client, args)
        if args.action == "jobs":
            states = {JobState(s) for s in args.state} if args.state else None
            for job in await client.list(states, args.limit):
                created = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(job.created))
                print(f"{job.job_id}  {created}  {job.state.value:<14} {job.error or job.request.label}")
            return 0
        if args.action == "status":
            overview = await client.cell_status(failures=args.failures)
            print(overview.model_dump_json(indent=1) if args.json else format_status(overview))
            return 0
        if args.action == "job":
            status = await client.status(args.job_id)
            print(status.model_dump_json(indent=1))
            if status.state is JobState.SUCCEEDED:
                print((await client.result(args.job_id)).model_dump_json(indent=1))
            return 0
        status = await client.cancel(args.job_id)
        print(f"job {status.job_id}: cancel requested ({status.state.value})")
        return 0


def run(args: argparse.Namespace, config: CellConfig) -> int:
    try:
        return asyncio.run(_run(args, config))
    except (CellError, TimeoutError) as exc:
        print(f"robocell {args.command}: {exc}", file=sys.stderr)
        return 1
