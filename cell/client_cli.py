"""``robocell scan``, ``robocell jobs``, ``robocell status`` and ``robocell cancel``: the cell from a shell."""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import time

from .client import AsyncCellClient
from .config import CellConfig
from .errors import CellError
from .messages import JobEvent, JobState, ScanRequest

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

    status = commands.add_parser("status", help="show one job's status and, if done, its result")
    status.add_argument("job_id")
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
    status = await client.submit(request)
    print(f"job {status.job_id} {status.state.value}", flush=True)
    if args.no_wait:
        return 0
    final = await client.wait(status.job_id, timeout=args.timeout, on_event=_print_event)
    if final.state is not JobState.SUCCEEDED:
        print(f"job {final.job_id} {final.state.value}: {final.error or ''}", file=sys.stderr)
        return 1
    result = await client.result(final.job_id)
    print(json.dumps({"job_id": result.job_id, "superquadric": result.superquadric,
                      "silhouette_iou": result.silhouette_iou, "timings_ms": result.timings_ms,
                      "recording": result.recording}))
    return 0


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
