"""Benchmark of the pick in the whole simulated cell: prints a table, asserts nothing.

For each scene of the grasp benchmark's mix (``workers/sim/grasp_set.py``: the superquadric
families, a plate, a lying cylinder, the compound objects), a whole simulated cell starts with
that object on its table, scans it (three views), plans its grasps, picks it up and lifts it.
The simulated gripper judges the grasp it closes against the true object
(``workers/sim/judge.py``, written apart from the planner). Target: held in at least 9 of 10
scenes.

    .venv/bin/python bench/bench_pick.py [--seed 0] [--families box cylinder ...]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robocell.cli.demo import local_config  # noqa: E402
from robocell.cli.up import CellProcesses  # noqa: E402
from robocell.wire.client import AsyncCellClient, JobFailed  # noqa: E402
from robocell.wire.errors import CellError  # noqa: E402
from robocell.wire.messages import PickRequest, ScanRequest  # noqa: E402
from robocell.workers.sim.scene import target_from_config  # noqa: E402

MIX = ("box", "cylinder", "ellipsoid", "rounded-box", "plate", "lying-cylinder", "cups", "mug", "box-and-ball",
       "l-boxes")


async def pick_one(family: str, seed: int, run_dir: Path) -> dict:
    config = local_config(run_dir, cell_id="pick", sim={"grasp_scene": family, "seed": seed},
                          robot={"speed": 0.0, "rotation_speed_deg": 0.0})
    cell = CellProcesses(config)
    began = time.perf_counter()
    row = {"family": family, "seed": seed, "held": None, "why": "", "grasps": 0, "seconds": 0.0}
    try:
        await cell.start()
        async with await AsyncCellClient.connect(config.zenoh.router, config.cell_id) as client:
            request = ScanRequest(target=target_from_config(config.sim), pick=PickRequest(), label=family)
            result = await client.scan(request, timeout=180)
        row["grasps"] = len(result.grasps)
        assert result.pick is not None
        row["held"], row["why"] = result.pick.held, result.pick.reason
    except JobFailed as exc:
        row["held"], row["why"] = False, str(exc).split(": ", 1)[-1]
    except CellError as exc:
        row["why"] = f"the cell: {exc}"
    finally:
        await cell.stop()
    row["seconds"] = time.perf_counter() - began
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--families", nargs="*", default=list(MIX))
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="robocell-pick-") as tmp:
        print(f"{'scene':<16} {'seed':>4} {'grasps':>6}  {'picked':<7} why", flush=True)
        for k, family in enumerate(args.families):
            row = asyncio.run(pick_one(family, args.seed + k, Path(tmp) / f"{k}-{family}"))
            rows.append(row)
            verdict = {True: "held", False: "missed", None: "?"}[row["held"]]
            print(f"{family:<16} {row['seed']:>4} {row['grasps']:>6}  {verdict:<7} {row['why']}", flush=True)
    held = sum(row["held"] is True for row in rows)
    print(f"\nheld in {held} of {len(rows)} scenes (target: 9 of 10)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
