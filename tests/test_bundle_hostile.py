"""Hostile scan bundles (DESIGN.md §3, "A bundle is untrusted input") through `robocell reconstruct`.

Every bundle of ``tests.bundles.HOSTILE_BUNDLES`` sits between two good ones in one real
process: each gets its one-line error naming the view and what is wrong, the good ones
are still reconstructed, and the exit status says that something failed.
"""

import json
import shutil
import subprocess
import sys

from tests.bundles import HOSTILE_BUNDLES


def test_hostile_bundles_get_one_line_errors_and_the_good_ones_are_still_done(tmp_path, sphere_bundle_template):
    good = shutil.copytree(sphere_bundle_template, tmp_path / "good")
    hostile = []
    for name, (change, _) in HOSTILE_BUNDLES.items():
        hostile.append(shutil.copytree(sphere_bundle_template, tmp_path / name))
        change(hostile[-1])
    process = subprocess.run([sys.executable, "-m", "robocell", "reconstruct", good, *hostile, good],
                             capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert process.returncode == 1
    results = [json.loads(line) for line in process.stdout.splitlines()]
    assert [r["scan"] for r in results] == [str(p) for p in [good, *hostile, good]]  # nothing lost, in order
    assert "superquadric" in results[0] and "superquadric" in results[-1]
    for (name, (_, message)), result in zip(HOSTILE_BUNDLES.items(), results[1:-1]):
        assert message in result.get("error", ""), (name, result)
        assert "internal error" not in result["error"] and "\n" not in result["error"]
    assert "Traceback" not in process.stderr
