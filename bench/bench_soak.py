"""Soak bench of the cell: many jobs, what every process and the disk hold over time; a full disk.

Runs a whole simulated cell on this machine (router, workers, simulated
camera, daemon, and what they start: the recorder, the reconstruction pool's
processes), the robot moving instantly, and prints tables; asserts nothing.

(a) Soak: N jobs, ``--in-flight`` at a time. For every process of the cell:
    resident memory, threads and open file descriptors after the first job,
    after 10 % of the jobs, half-way and at the end; and the run directory's
    size (recordings, pictures, store). With ``--retention`` this process
    applies ``cell.retention.apply_retention`` to the daemon's store every
    ``--retention-every`` jobs with small limits, as the daemon will once it
    is wired to (the disk should then stay flat). Targets (issue 23): 2000
    jobs, every process's RSS within 10 % of its value after the first 200,
    threads and fds flat, disk flat once retention applies.
(b) Disk full: the run directory on a ``--tmpfs-mb`` tmpfs (``mount -t tmpfs``:
    needs root; skipped with a message otherwise), ``--full-jobs`` jobs. Counts:
    jobs a client was told succeeded that the store does not hold as succeeded,
    jobs the store still shows unfinished at the end (phantoms), results naming
    no recording and no ``recording_error``; then space is freed and a few more
    jobs are run, to see whether the cell recovers without a restart.

    .venv/bin/python bench/bench_soak.py [--jobs 200] [--in-flight 2] [--retention] [--full-jobs 100]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robocell.cell.retention import apply_retention, disk_usage  # noqa: E402
from robocell.cell.store import JobStore  # noqa: E402
from robocell.cli.demo import local_config  # noqa: E402
from robocell.cli.up import CellProcesses  # noqa: E402
from robocell.wire.client import AsyncCellClient, JobFailed  # noqa: E402
from robocell.wire.config import CellConfig, RetentionConfig  # noqa: E402
from robocell.wire.errors import CellError  # noqa: E402
from robocell.wire.messages import DiskUsage, JobState, ScanRequest, ScanResult  # noqa: E402
from robocell.workers.sim.scene import target_from_config  # noqa: E402

_MB = 1024 * 1024


def _config(run_dir: Path) -> CellConfig:
    return local_config(run_dir, cell_id="soak", robot={"speed": 0.0, "rotation_speed_deg": 0.0},
                        timeouts={"outage_s": 10.0})


def _processes(cell: CellProcesses) -> dict[str, psutil.Process]:
    """Every process of the cell by a name: each child, and each of their descendants."""
    found: dict[str, psutil.Process] = {}
    for child in cell.children:
        if child.process is None or child.process.returncode is not None:
            continue
        try:
            top = psutil.Process(child.process.pid)
            found[child.name] = top
            below = [p for p in top.children(recursive=True) if p.status() != psutil.STATUS_ZOMBIE]
            for index, process in enumerate(sorted(below, key=lambda p: p.pid)):
                found[f"{child.name}/{_what(process)}-{index}"] = process
        except psutil.NoSuchProcess:
            continue
    return found


def _what(process: psutil.Process) -> str:
    """A short name for a process a child started: its module or the last word of its command."""
    try:
        words = process.cmdline()
    except psutil.Error:
        return "?"
    if "-m" in words[:-1]:
        return words[words.index("-m") + 1].rsplit(".", 1)[-1][:16]
    if "-c" in words[:-1]:
        code = words[words.index("-c") + 1]
        return "forkserver" if "forkserver" in code else "tracker" if "resource_tracker" in code else "child"
    return (words[-1] if words else process.name())[-16:]


def _sample(cell: CellProcesses) -> dict[str, tuple[float, int, int]]:
    """(RSS MB, threads, fds) of every process of the cell."""
    sample = {}
    for name, process in _processes(cell).items():
        try:
            with process.oneshot():
                sample[name] = (process.memory_info().rss / _MB, process.num_threads(), process.num_fds())
        except psutil.NoSuchProcess:
            continue
    return sample


def _disk(run_dir: Path, policy: RetentionConfig) -> DiskUsage:
    return disk_usage(run_dir, policy, now=time.time())


async def _jobs(client: AsyncCellClient, request: ScanRequest, count: int, in_flight: int,
                outcome: dict[str, int], told: dict[str, JobState], results: list[ScanResult] | None = None) -> None:
    """``count`` jobs, ``in_flight`` at a time; tally how each ended as the client was told."""
    queue = asyncio.Queue[int]()
    for k in range(count):
        queue.put_nowait(k)

    async def runner() -> None:
        while not queue.empty():
            queue.get_nowait()
            try:
                result: ScanResult = await client.scan(request, timeout=120.0)
                outcome["succeeded"] += 1
                told[result.job_id] = JobState.SUCCEEDED
                if results is not None:
                    results.append(result)
                if result.recording is None and result.recording_error is None:
                    outcome["recording unnamed"] += 1
                elif result.recording_error is not None:
                    outcome["recording error named"] += 1
            except JobFailed as failed:
                outcome[failed.status.state.value] += 1
                told[failed.status.job_id] = failed.status.state
            except (CellError, TimeoutError) as exc:
                outcome["no answer"] += 1
                why = f"({type(exc).__name__}: {str(exc)[:60]})"
                outcome[why] = outcome.get(why, 0) + 1

    await asyncio.gather(*(runner() for _ in range(in_flight)))


def _table(samples: list[tuple[str, dict[str, tuple[float, int, int]], DiskUsage]]) -> None:
    names = sorted({name for _, sample, _ in samples for name in sample})
    labels = [label for label, _, _ in samples]
    print(f"\n{'process':34s} " + " ".join(f"{label:>24s}" for label in labels))
    print(f"{'':34s} " + " ".join(f"{'RSS MB / thr / fds':>24s}" for _ in labels))
    for name in names:
        cells = []
        for _, sample, _ in samples:
            value = sample.get(name)
            cells.append(f"{value[0]:9.1f} / {value[1]:4d} / {value[2]:4d}" if value else f"{'-':>24s}")
        print(f"{name:34s} " + " ".join(f"{c:>24s}" for c in cells))
    for what in ("recordings", "pictures", "store", "other"):
        print(f"{'run directory: ' + what + ', MB':34s} "
              + " ".join(f"{getattr(disk, what) / _MB:>24.2f}" for _, _, disk in samples))
    print("(other: the logs of the cell's processes)")


async def soak(n_jobs: int, in_flight: int, run_dir: Path, retention: RetentionConfig | None, every: int) -> None:
    config = _config(run_dir)
    cell = CellProcesses(config)
    policy = retention or RetentionConfig()
    store: JobStore | None = None
    began = time.perf_counter()
    try:
        await cell.start()
        store = JobStore(run_dir / "jobs.sqlite")
        request = ScanRequest(target=target_from_config(config.sim))
        outcome: dict[str, int] = {"succeeded": 0, "failed": 0, "cancelled": 0, "no answer": 0,
                                   "recording unnamed": 0, "recording error named": 0}
        told: dict[str, JobState] = {}
        async with await AsyncCellClient.connect(config.zenoh.router, config.cell_id, timeout=30.0) as client:
            marks = sorted({1, max(1, n_jobs // 10), max(1, n_jobs // 2), n_jobs})
            samples, done, pruned = [], 0, 0
            step = every if retention is not None else n_jobs
            for mark in marks:
                while done < mark:
                    batch = min(mark - done, step - done % step)
                    await _jobs(client, request, batch, in_flight, outcome, told)
                    done += batch
                    if retention is not None and done % step == 0:
                        # In this thread: the store is its opener's (blocking the bench's loop a moment is fine).
                        pruned += apply_retention(run_dir, store, policy, time.time()).jobs_pruned
                await asyncio.sleep(1.0)   # the recorder and the store catch up
                samples.append((f"after {mark} jobs", _sample(cell), _disk(run_dir, policy)))
    finally:
        if store is not None:
            store.close()
        await cell.stop()
    elapsed = time.perf_counter() - began
    print(f"\n(a) soak: {n_jobs} jobs, {in_flight} at a time, robot moving instantly, {elapsed:.0f} s"
          + (f"; retention every {every} jobs (recordings <= {policy.recordings_max_mb:g} MB, "
             f"ended jobs <= {policy.jobs_max_count}), {pruned} jobs pruned" if retention else "; no retention"))
    print("outcomes: " + ", ".join(f"{k} {v}" for k, v in outcome.items()))
    _table(samples)
    first = samples[1][1] if len(samples) > 1 else samples[0][1]
    last = samples[-1][1]
    growth = {name: (last[name][0] / first[name][0] - 1) * 100 for name in last if name in first and first[name][0]}
    if growth:
        worst = max(growth, key=lambda n: abs(growth[n]))
        mean = sum(growth.values()) / len(growth)
        print(f"RSS from {samples[1][0] if len(samples) > 1 else samples[0][0]} to the end: mean "
              f"{mean:+.1f} %, worst {growth[worst]:+.1f} % ({worst})")


def _mount_tmpfs(directory: Path, size_mb: int) -> bool:
    directory.mkdir(parents=True, exist_ok=True)
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_mb}m", "tmpfs", str(directory)],
                              capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as exc:
        print(f"\n(b) disk full: skipped: cannot mount a tmpfs ({exc})")
        return False
    if done.returncode != 0:
        print(f"\n(b) disk full: skipped: cannot mount a tmpfs ({done.stderr.strip() or done.returncode})")
        return False
    return True


async def disk_full(n_jobs: int, size_mb: int, directory: Path) -> None:
    if not _mount_tmpfs(directory, size_mb):
        return
    try:
        run_dir = directory / "run"
        config = _config(run_dir)
        cell = CellProcesses(config)
        outcome: dict[str, int] = {"succeeded": 0, "failed": 0, "cancelled": 0, "no answer": 0,
                                   "recording unnamed": 0, "recording error named": 0}
        after: dict[str, int] = dict.fromkeys(outcome, 0)
        told: dict[str, JobState] = {}
        results: list[ScanResult] = []
        try:
            await cell.start()
            request = ScanRequest(target=target_from_config(config.sim))
            async with await AsyncCellClient.connect(config.zenoh.router, config.cell_id, timeout=30.0) as client:
                await _jobs(client, request, n_jobs, 1, outcome, told, results)
                full = shutil.disk_usage(directory)
                await asyncio.sleep(2.0)    # the last recordings are completed
                # A recording named in a result, with no recording_error, that is missing or empty.
                lost = sum(1 for r in results if r.recording_error is None and r.recording is not None
                           and (not Path(r.recording).exists() or Path(r.recording).stat().st_size == 0))
                # Space returns: the recordings go, as retention would delete them.
                for recording in run_dir.glob("*.rrd"):
                    recording.unlink()
                await asyncio.sleep(2.0)
                await _jobs(client, request, 5, 1, after, {})
        finally:
            await cell.stop()
        store = JobStore(run_dir / "jobs.sqlite")
        try:
            lies = sum(1 for job_id, state in told.items()
                       if state is JobState.SUCCEEDED and ((s := store.get(job_id)) is None or s.state is not state))
            phantoms = len(store.unfinished())
        finally:
            store.close()
        print(f"\n(b) disk full: {n_jobs} jobs with the run directory on a {size_mb} MB tmpfs "
              f"({full.free / _MB:.1f} MB free at the end)")
        print("outcomes: " + ", ".join(f"{k} {v}" for k, v in outcome.items()))
        print(f"told succeeded but not stored as succeeded: {lies}; unfinished in the store after the run "
              f"(phantoms): {phantoms}; recordings named with no error but missing or empty: {lost}")
        print("after freeing the recordings, 5 more jobs: " + ", ".join(f"{k} {v}" for k, v in after.items()))
    finally:
        subprocess.run(["umount", str(directory)], capture_output=True, timeout=30)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=200, help="soak jobs (the target is 2000)")
    parser.add_argument("--in-flight", type=int, default=2)
    parser.add_argument("--retention", action="store_true", help="apply retention with small limits while soaking")
    parser.add_argument("--retention-every", type=int, default=50)
    parser.add_argument("--recordings-mb", type=float, default=20.0, help="with --retention")
    parser.add_argument("--full-jobs", type=int, default=100, help="0 skips table (b)")
    parser.add_argument("--tmpfs-mb", type=int, default=30)
    parser.add_argument("--run-dir", help="where the cells keep their files (default: a temporary directory)")
    args = parser.parse_args()
    retention = RetentionConfig(recordings_max_mb=args.recordings_mb, jobs_max_count=args.retention_every,
                                pictures_max_age_days=1e-3) if args.retention else None
    with tempfile.TemporaryDirectory(prefix="bench-soak-") as tmp:
        root = Path(args.run_dir) if args.run_dir else Path(tmp)
        if args.jobs > 0:
            asyncio.run(soak(args.jobs, args.in_flight, root / "soak", retention, args.retention_every))
        if args.full_jobs > 0:
            if os.geteuid() != 0:
                print("\n(b) disk full: skipped: mounting a tmpfs needs root")
            else:
                asyncio.run(disk_full(args.full_jobs, args.tmpfs_mb, root / "full"))


if __name__ == "__main__":
    main()
