"""Probe of the cell's faults, as the hardening issue measures them: prints tables, asserts nothing.

(a) The router killed for 3, 10 and 20 s while 30 jobs wait: how many succeed, and the longest
    time the motion lane stood still beyond the outage (the gap between two steps of the lane,
    minus the time the router was away: from its kill until it answers again, its own start-up
    included). Target: 30/30 each time, at most outage + 5 s.
(b) The daemon killed with ``kill -9`` during a burst of 50 submits (a client submits with
    request ids and retries through the crash): how many succeed, fail, end twice.
    Target: 50/50 succeed after the restart, none "interrupted", none duplicated.

    .venv/bin/python bench/probe_faults.py [--jobs 30] [--outages 3 10 20] [--burst 50]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robocell.cell.store import JobStore  # noqa: E402
from robocell.cli.demo import local_config  # noqa: E402
from robocell.cli.up import CellProcesses  # noqa: E402
from robocell.wire.client import CellClient  # noqa: E402
from robocell.wire.errors import TransportError  # noqa: E402
from robocell.wire.messages import JobState, ScanRequest  # noqa: E402
from robocell.wire.transport import Transport  # noqa: E402
from robocell.workers.sim.scene import target_from_config  # noqa: E402

_STEPS = (JobState.MOVING, JobState.CAPTURING)


async def _router_back(endpoint: str) -> float:
    """When the router answers again (a session can be opened), unix time."""
    while True:
        try:
            transport = await Transport.open(endpoint, connect_timeout_s=0.2)
        except TransportError:
            await asyncio.sleep(0.05)
            continue
        await transport.close()
        return time.time()


def _longest_lane_gap(run_dir: Path, job_ids: list[str]) -> float:
    """The longest time between two successive moving/capturing events of these jobs, seconds."""
    with JobStore(run_dir / "jobs.sqlite") as store:
        times = sorted(e.time for job_id in job_ids for e in store.events(job_id) if e.state in _STEPS)
    return max((b - a for a, b in zip(times, times[1:])), default=0.0)


async def router_outage(outage_s: float, n_jobs: int, run_dir: Path) -> dict:
    config = local_config(run_dir, cell_id="probe", robot={"move_time_s": 0.2})
    cell = CellProcesses(config)
    await cell.start()
    try:
        with CellClient(config.zenoh.router, config.cell_id, timeout=10.0) as client:
            target = target_from_config(config.sim)
            ids = [client.submit(ScanRequest(target=target, label=f"outage {k}")).job_id for k in range(n_jobs)]
            await asyncio.sleep(1.0)  # some jobs under way, most waiting
            await cell.stop_child("router", kill=True)
            killed = time.time()
            await asyncio.sleep(outage_s)
            restart = asyncio.create_task(cell.start_child("router", ready_timeout=60.0))
            back = await _router_back(config.zenoh.router)
            await restart
            finals = await asyncio.to_thread(lambda: [client.wait(job_id, timeout=600) for job_id in ids])
        gap = _longest_lane_gap(run_dir, ids)
    finally:
        await cell.stop()
    failed = [f.error for f in finals if f.state is not JobState.SUCCEEDED]
    away = back - killed  # the outage as the cell saw it: the router's own start-up included
    return {"outage": outage_s, "away": away, "succeeded": n_jobs - len(failed), "jobs": n_jobs, "gap": gap,
            "beyond": gap - away, "failed": failed[:2]}


async def daemon_kill(n_jobs: int, run_dir: Path) -> dict:
    config = local_config(run_dir, cell_id="probe")
    cell = CellProcesses(config)
    await cell.start()
    acknowledged: dict[str, str] = {}
    errors: list[BaseException] = []
    target = target_from_config(config.sim)

    def submit_all() -> None:
        try:
            with CellClient(config.zenoh.router, config.cell_id, timeout=3.0) as client:
                for k in range(n_jobs):
                    request = ScanRequest(target=target, request_id=f"burst-{k}", label=f"burst {k}")
                    acknowledged[request.request_id] = client.submit(request, retry_s=60.0).job_id
        except BaseException as exc:  # noqa: BLE001 - reported in the table
            errors.append(exc)

    try:
        submitter = threading.Thread(target=submit_all)
        submitter.start()
        while len(acknowledged) < n_jobs // 3 and submitter.is_alive():
            await asyncio.sleep(0.01)
        await cell.stop_child("daemon", kill=True)
        killed_after = len(acknowledged)
        await cell.start_child("daemon", ready_timeout=60.0)
        await asyncio.to_thread(submitter.join, 120.0)

        def wait_all() -> list:
            with CellClient(config.zenoh.router, config.cell_id, timeout=10.0) as client:
                return [client.wait(job_id, timeout=600) for job_id in acknowledged.values()]

        finals = await asyncio.to_thread(wait_all)
        with JobStore(run_dir / "jobs.sqlite") as store:
            stored = [s for s in store.list(limit=10_000) if (s.request.request_id or "").startswith("burst-")]
    finally:
        await cell.stop()
    return {"jobs": n_jobs, "acknowledged": len(acknowledged), "killed after": killed_after,
            "succeeded": sum(f.state is JobState.SUCCEEDED for f in finals),
            "failed": sum(f.state is JobState.FAILED for f in finals),
            "interrupted": sum("interrupted" in (f.error or "") for f in finals),
            "stored": len(stored), "duplicated": len(stored) - len({s.request.request_id for s in stored}),
            "client errors": len(errors)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=30)
    parser.add_argument("--outages", type=float, nargs="*", default=[3.0, 10.0, 20.0])
    parser.add_argument("--burst", type=int, default=50)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="robocell-probe-") as tmp:
        print(f"(a) router killed during {args.jobs} queued jobs (outage allowance 30 s)")
        print(f"  {'outage s':>9} {'router away s':>14} {'succeeded':>10} {'lane gap s':>11} {'beyond away s':>14}"
              f"  first failures")
        for k, outage in enumerate(args.outages):
            row = asyncio.run(router_outage(outage, args.jobs, Path(tmp) / f"router-{k}"))
            print(f"  {row['outage']:9.0f} {row['away']:14.2f} {row['succeeded']:>5}/{row['jobs']:<4} {row['gap']:11.2f} "
                  f"{row['beyond']:14.2f}  {row['failed'] or ''}", flush=True)
        print(f"\n(b) daemon killed (kill -9) during a burst of {args.burst} submits")
        row = asyncio.run(daemon_kill(args.burst, Path(tmp) / "daemon"))
        print("  " + "  ".join(f"{name} {value}" for name, value in row.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
