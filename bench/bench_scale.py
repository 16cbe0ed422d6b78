"""Benchmark of scale-out: reconstruction throughput against workers, and a burst of jobs.

Every part is its own process, talking Zenoh on loopback; prints tables,
asserts nothing.

(a) Reconstruction throughput with 1 and 2 reconstruct processes (one worker
    with a pool of 1 or 2, and two workers of 1). Jobs that only reconstruct:
    the bench sends pre-captured views (simulated scans of the standard set,
    rendered once) to the pool keys itself, through the daemon's own
    ``cell.pool.ReconstructorPool`` (the same choice of worker, slots and
    failover), bypassing robot and camera. Target: 2 processes >= 1.7 x 1.
(b) A burst: N jobs (default 500) submitted at once to a whole simulated cell
    (robot moving instantly, simulated camera, daemon, two reconstructors),
    each with a request id. Counted from the store and the daemon's status:
    every job accepted, processed and reported, none lost, none duplicated;
    every result fetched; the whole burst submitted again, which must make no
    new job.

    .venv/bin/python bench/bench_scale.py [--jobs 200] [--burst 500] [--skip-burst]
"""

from __future__ import annotations

import os

for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse  # noqa: E402
import asyncio  # noqa: E402
import collections  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robocell.wire import keys  # noqa: E402
from robocell.wire.client import AsyncCellClient  # noqa: E402
from robocell.wire.config import CellConfig  # noqa: E402
from robocell.cli.demo import local_config  # noqa: E402
from robocell.wire.messages import (CameraModel, JobState, ReconstructReply, ReconstructRequest,  # noqa: E402
                           ReconstructView, ScanRequest)
from robocell.cell.pool import ReconstructorPool  # noqa: E402
from robocell.workers.sim.scans import standard_set  # noqa: E402
from robocell.workers.sim.scene import target_from_config  # noqa: E402
from robocell.cell.store import JobStore  # noqa: E402
from robocell.wire.transport import Transport  # noqa: E402
from robocell.cli.up import CellProcesses  # noqa: E402


def _config(run_dir: Path, **fields) -> CellConfig:
    return local_config(run_dir, cell_id="bench", robot={"speed": 0.0, "rotation_speed_deg": 0.0}, **fields)


# --- (a) throughput --------------------------------------------------------------------------------

_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")


def _cpu_s(pid: int) -> float:
    """CPU seconds (user + system) of a process so far; 0 if it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) * _TICK_S


def _children(pid: int) -> list[int]:
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def _cpu_by_role(cell: CellProcesses) -> dict[str, float]:
    """CPU seconds so far of the router, the workers' main processes, their pool processes, and this one."""
    cpu = {"router": 0.0, "worker main": 0.0, "pool processes": 0.0,
           "bench (dispatch)": time.process_time()}
    for child in cell.children:
        pid = child.process.pid
        if child.name == "router":
            cpu["router"] += _cpu_s(pid)
        elif child.name.startswith("reconstruct"):
            cpu["worker main"] += _cpu_s(pid)
            cpu["pool processes"] += sum(_cpu_s(c) for c in _children(pid))
    return cpu


def prepared_scans(directory: Path, n: int) -> list[tuple[str, bytes]]:
    """``n`` simulated scans of superquadrics as (ReconstructRequest JSON without ticket, payload)."""
    specs = [s for s in standard_set() if not s.name.startswith(("cup", "lumpy"))][:n]
    scans = []
    for spec in specs:
        bundle = spec.write(directory)
        scan = json.loads((bundle / "scan.json").read_text())
        jpegs = [(bundle / view["image"]).read_bytes() for view in scan["views"]]
        views = [ReconstructView(camera=CameraModel(K=view["K"], dist=view.get("dist")),
                                 T_world_cam=view["T_world_cam"], length=len(jpeg))
                 for view, jpeg in zip(scan["views"], jpegs)]
        request = ReconstructRequest(job_id=spec.name, views=views, segmentation=scan["segmentation"],
                                     support_plane=scan["support_plane"], options={"n_points": 1000})
        scans.append((request.model_dump_json(), b"".join(jpegs)))
    return scans


async def _run_jobs(pool: ReconstructorPool, scans: list[tuple[str, bytes]], n: int, tag: str) -> list[bytes]:
    async def one(k: int) -> bytes:
        request_json, payload = scans[k % len(scans)]
        request = ReconstructRequest.model_validate_json(request_json)
        request.ticket = keys.ticket("bench", f"{tag}-{k}", 1)
        _, reply = await pool.run(request.ticket, payload, request.model_dump_json(), timeout=120, wait_s=10)
        return reply.attachment

    return await asyncio.gather(*(one(k) for k in range(n)))


async def throughput(layout: tuple[int, int], scans: list[tuple[str, bytes]], n_jobs: int, run_dir: Path) -> dict:
    """Jobs per second with ``workers`` workers of ``processes`` processes each."""
    workers, processes = layout
    config = _config(run_dir, reconstruct={"processes": processes})
    cell = CellProcesses(config, reconstructors=workers, robot=False, camera=False, sim_camera=False, daemon=False)
    try:
        await cell.start()
        async with await Transport.open(config.zenoh.router, connect_timeout_s=10) as transport:
            pool = ReconstructorPool(transport, heartbeat_s=10.0)
            pool.start()
            try:
                deadline = time.monotonic() + 20
                while sum(r.capacity for r in pool.snapshot() if r.heartbeat_age_s is not None) \
                        < workers * processes:
                    if time.monotonic() > deadline:
                        raise RuntimeError("the bench's pool never saw every worker")
                    await asyncio.sleep(0.05)
                await _run_jobs(pool, scans, 4 * workers * processes, "warm-up")
                cpu_before = _cpu_by_role(cell)
                began = time.perf_counter()
                replies = await _run_jobs(pool, scans, n_jobs, "timed")
                elapsed = time.perf_counter() - began
                cpu = {role: 1000 * (used - cpu_before[role]) / n_jobs for role, used in _cpu_by_role(cell).items()}
            finally:
                await pool.close()
    finally:
        await cell.stop()
    answers = [ReconstructReply.model_validate_json(r) for r in replies]
    errors = [a.error for a in answers if a.error]
    if errors:
        raise RuntimeError(f"{len(errors)} reconstructions failed, e.g. {errors[0]}")
    core = [a.result.timings_ms["total"] for a in answers if a.result is not None]
    return {"layout": layout, "elapsed": elapsed, "per_s": n_jobs / elapsed, "ms_per_job": 1000 * elapsed / n_jobs,
            "core_ms": statistics.median(core), "by_worker": collections.Counter(a.worker for a in answers),
            "cpu_ms": cpu}


async def scaling(n_jobs: int, root: Path) -> None:
    scans = prepared_scans(root / "scans", 8)
    rows = [await throughput(layout, scans, n_jobs, root / f"w{layout[0]}p{layout[1]}")
            for layout in ((1, 1), (1, 2), (2, 1))]
    base = rows[0]["per_s"]
    print(f"\n(a) reconstruction throughput, {n_jobs} jobs per row ({len(scans)} different simulated scans, "
          f"1000 points), {os.cpu_count()} cores")
    print(f"{'workers x processes':<22}{'processes':>10}{'jobs/s':>9}{'ms/job':>9}{'core ms (median)':>18}"
          f"{'speed-up':>10}  jobs per worker")
    for row in rows:
        workers, processes = row["layout"]
        print(f"{f'{workers} x {processes}':<22}{workers * processes:>10}{row['per_s']:>9.1f}{row['ms_per_job']:>9.1f}"
              f"{row['core_ms']:>18.1f}{row['per_s'] / base:>9.2f}x  {sorted(row['by_worker'].values())}")
    print("CPU per job, ms, by process (the pool processes do the reconstructions; the rest is transport):")
    roles = list(rows[0]["cpu_ms"])
    print(f"{'workers x processes':<22}" + "".join(f"{role:>18}" for role in roles))
    for row in rows:
        workers, processes = row["layout"]
        print(f"{f'{workers} x {processes}':<22}" + "".join(f"{row['cpu_ms'][role]:>18.1f}" for role in roles))
    best = max(row["per_s"] for row in rows[1:]) / base
    print(f"target: 2 processes >= 1.7 x 1 -> {'met' if best >= 1.7 else 'NOT met'} ({best:.2f} x at best)")


# --- (b) burst -------------------------------------------------------------------------------------

async def burst(n_jobs: int, root: Path) -> None:
    config = _config(root / "burst", max_queued=max(100, 2 * n_jobs),
                     timeouts={"reconstruct_s": 120.0, "heartbeat_s": 10.0})
    target = target_from_config(config.sim)
    requests = [ScanRequest(target=target, request_id=f"burst-{k:04d}", label=f"burst {k}") for k in range(n_jobs)]
    cell = CellProcesses(config, reconstructors=2)
    try:
        await cell.start()
        async with await AsyncCellClient.connect(config.zenoh.router, config.cell_id, timeout=60.0) as client:
            began = time.perf_counter()
            accepted = await asyncio.gather(*(client.submit(r) for r in requests))
            submitted = time.perf_counter() - began
            print(f"\n(b) burst: {n_jobs} jobs submitted at once in {submitted:.2f} s; processing ...", flush=True)
            busiest = 0
            while True:
                status = await client.cell_status()
                busiest = max(busiest, status.queued)
                finished = sum(status.jobs[s.value] for s in JobState if s.finished)
                if finished >= n_jobs:
                    break
                await asyncio.sleep(1.0)
            elapsed = time.perf_counter() - began
            results = await asyncio.gather(*(client.result(s.job_id) for s in accepted))
            again = await asyncio.gather(*(client.submit(r) for r in requests))
            final_status = await client.cell_status()
    finally:
        await cell.stop()
    with JobStore(Path(config.run_dir) / "jobs.sqlite") as store:
        rows = store.list(limit=10 * n_jobs + 10)
        succeeded_events = [sum(e.state is JobState.SUCCEEDED for e in store.events(s.job_id)) for s in rows]
    ids = [s.job_id for s in accepted]
    by_request = collections.Counter(s.request.request_id for s in rows)
    states = collections.Counter(s.state.value for s in rows)
    workers = collections.Counter(r.worker for r in results)
    rows_out = [
        ("jobs submitted", n_jobs),
        ("accepted (distinct job ids acknowledged)", len(set(ids))),
        ("jobs in the store", len(rows)),
        ("  succeeded", states.get("succeeded", 0)),
        ("  failed / cancelled / unfinished", len(rows) - states.get("succeeded", 0)),
        ("lost (accepted, not in the store or not finished)",
         len(set(ids) - {s.job_id for s in rows if s.state.finished})),
        ("duplicated (store rows per request id > 1)", sum(n - 1 for n in by_request.values() if n > 1)),
        ("jobs with != 1 'succeeded' event", sum(n != 1 for n in succeeded_events)),
        ("results fetched (distinct, matching)", len({r.job_id for r in results if r.job_id in set(ids)})),
        ("submitted again: same job id", sum(a.job_id == b.job_id for a, b in zip(accepted, again))),
        ("jobs in the store after submitting again", sum(final_status.jobs.values())),
    ]
    for label, value in rows_out:
        print(f"  {label:<52}{value:>8}")
    print(f"  {'most jobs waiting for the robot at once':<52}{busiest:>8}")
    print(f"  {'reconstructed by':<52}{dict(workers)}")
    print(f"  wall time {elapsed:.1f} s from the first submit to the last job's end: {n_jobs / elapsed:.2f} jobs/s, "
          f"{1000 * elapsed / n_jobs:.0f} ms per job")
    captures = [v for r in results for k, v in r.durations_s.items() if k.startswith("capture")]
    reconstruct = statistics.median(r.durations_s["reconstruct"] for r in results)
    print(f"  per job (median): 3 captures {3 * statistics.median(captures):.3f} s (the robot and camera lane "
          f"is serial), reconstruction round trip {reconstruct:.3f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=200, help="jobs per throughput row (default %(default)s)")
    parser.add_argument("--burst", type=int, default=500, help="jobs in the burst (default %(default)s)")
    parser.add_argument("--skip-burst", action="store_true")
    parser.add_argument("--skip-throughput", action="store_true")
    parser.add_argument("--run-dir", help="where the cells keep their files (default: a temporary directory)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-scale-") as tmp:
        root = Path(args.run_dir) if args.run_dir else Path(tmp)
        if not args.skip_throughput:
            asyncio.run(scaling(args.jobs, root))
        if not args.skip_burst:
            asyncio.run(burst(args.burst, root))


if __name__ == "__main__":
    main()
