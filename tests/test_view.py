"""``--view`` of ``robocell cell`` and ``robocell up`` (issue 24): what reaches the daemon, and a bad
value's one-line error. That a viewer receives whole jobs is ``tests/test_recorder_cell.py``'s."""

from __future__ import annotations

import subprocess
import sys

from robocell.cli.up import CellProcesses
from robocell.cli.view import WEB, view_url

from tests.cell_fixtures import cell_config


def test_up_view_hands_the_viewer_url_to_the_daemon(tmp_path):
    url = "rerun+http://127.0.0.1:9999/proxy"
    cell = CellProcesses(cell_config(tmp_path), view=url)
    daemon = cell.child("daemon")
    assert daemon.argv[-3:] == ["cell", "--view", url]
    assert "--view" not in CellProcesses(cell_config(tmp_path)).child("daemon").argv
    assert view_url(WEB, 9877) == "rerun+http://127.0.0.1:9877/proxy"


def test_a_view_that_is_no_viewer_url_is_a_one_line_error():
    done = subprocess.run([sys.executable, "-m", "robocell", "cell", "--view", "localhost:9876"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1] == (
        "robocell cell: error: argument --view: 'localhost:9876': give a Rerun viewer's gRPC URL "
        "(rerun+http://HOST:PORT/proxy) or 'web'")
