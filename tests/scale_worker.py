"""``robocell worker reconstruct``, but every job takes ``--delay`` seconds longer: for the scale tests.

The real worker (``workers.reconstruct.worker.main``: its own Zenoh session, process
pool, heartbeat and liveliness token), whose pool processes sleep before the
real reconstruction, so that a test can catch a job in flight and kill or
freeze the worker under it. With ``--fail`` every job raises instead.

    python tests/scale_worker.py --config FILE --id WORKER_ID [--delay SECONDS] [--fail]
"""

from __future__ import annotations

import os

for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse  # noqa: E402
import functools  # noqa: E402
import logging  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robocell.wire.config import load_config  # noqa: E402
from robocell.workers.reconstruct import worker as reconstruct  # noqa: E402


def slow_reconstruct_request(delay: float, fail: bool, request_json: str, payload: bytes,
                             worker: str) -> tuple[str, bytes]:
    """``reconstruct_request``, ``delay`` seconds later (in a pool process)."""
    time.sleep(delay)
    if fail:
        raise RuntimeError("broken on purpose")
    return reconstruct.reconstruct_request(request_json, payload, worker)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", required=True)
    parser.add_argument("--id", required=True)
    parser.add_argument("--delay", type=float, default=0.0)
    parser.add_argument("--fail", action="store_true")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    job = functools.partial(slow_reconstruct_request, args.delay, args.fail)
    return reconstruct.main(load_config(args.config), args.id, job=job)


if __name__ == "__main__":
    sys.exit(main())
