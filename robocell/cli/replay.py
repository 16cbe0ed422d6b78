"""``robocell replay JOB``: a job's Rerun recording in the viewer, native or served to a browser.

Only recordings of the cell's run directory are opened: a path that leads
outside it is refused. The viewer's servers listen on loopback unless
``--bind`` says otherwise.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path
from urllib.parse import quote

from .command import Commands

__all__ = ["register", "web_viewer_address"]

_LOOPBACK = "127.0.0.1"
_STOP_WAIT_S = 10.0


def register(commands: Commands) -> None:
    replay = commands.add("replay", _replay, help="open a job's Rerun recording in the viewer",
                          description="Open a job's recording (<run dir>/<job id>.rrd) in the Rerun viewer, "
                                      "or with --web serve it to a browser.")
    replay.add_argument("job", metavar="JOB_ID_OR_FILE", help="a job id, or a .rrd file in the run directory")
    replay.add_argument("--web", action="store_true", help="serve the web viewer instead; prints its address")
    replay.add_argument("--web-port", type=int, default=9090, help="the web viewer's HTTP port (default %(default)s)")
    replay.add_argument("--grpc-port", type=int, default=9876,
                        help="the port the viewer gets the recording from (default %(default)s)")
    replay.add_argument("--bind", default=_LOOPBACK, metavar="ADDRESS",
                        help="address the viewer's servers listen on (default %(default)s: this machine only; "
                             "0.0.0.0 for every network)")


def web_viewer_address(bind: str, web_port: int, grpc_port: int) -> str:
    """The address that opens the served recording in a browser: the web viewer, told by Rerun's ``?url=``
    where the recording's gRPC server is.

    Examples
    --------
    >>> web_viewer_address("127.0.0.1", 9090, 9876)
    'http://127.0.0.1:9090/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A9876%2Fproxy'
    """
    host = socket.gethostname() if bind in ("0.0.0.0", "::") else bind
    host = f"[{host}]" if ":" in host else host
    return f"http://{host}:{web_port}/?url=" + quote(f"rerun+http://{host}:{grpc_port}/proxy", safe="")


def _in_run_dir(path: Path, run_dir: Path) -> bool:
    return path.resolve().is_relative_to(run_dir.resolve())


def _has_display() -> bool:
    # Only X11 and Wayland need one named; other systems always have a desktop to open a window on.
    names = ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")
    return not sys.platform.startswith("linux") or any(os.environ.get(name) for name in names)


def _replay(args: argparse.Namespace) -> int:
    from robocell.cell.recording_files import find_recording, replay_command
    from robocell.wire.config import load_config
    from robocell.wire.errors import ConfigError

    run_dir = Path(load_config(args.config).run_dir)
    path = find_recording(args.job, run_dir)
    if not _in_run_dir(path, run_dir):
        raise ConfigError(f"{args.job} is not in the run directory {run_dir}: replay opens only the cell's own "
                          f"recordings")
    if not args.web and not _has_display():
        raise ConfigError("no display to open the viewer on (DISPLAY and WAYLAND_DISPLAY are not set): use --web, "
                          "and open the address it prints in a browser")
    argv = replay_command(path, web=args.web, bind=args.bind, web_port=args.web_port, grpc_port=args.grpc_port)
    if args.web:
        from .up import port_holder

        for option, port in (("--web-port", args.web_port), ("--grpc-port", args.grpc_port)):
            holder = port_holder(args.bind, port)
            if holder is not None:
                raise ConfigError(f"port {port} on {args.bind} is in use by {holder}: give {option} another port")
        print(f"serving {path}: open {web_viewer_address(args.bind, args.web_port, args.grpc_port)} "
              f"(Ctrl-C stops)", flush=True)
    # A `kill` of this command stops the viewer too, as a Ctrl-C does. Either may come while the viewer is
    # being started: it is a stop then too, not an error. Ctrl-C is caught here rather than left to Python's
    # default, which a process started with SIGINT ignored (a script's background job) never installs: such
    # a command, and the viewer it starts, would not hear a Ctrl-C sent to them.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _terminated)
    viewer: subprocess.Popen[bytes] | None = None
    try:
        viewer = subprocess.Popen(argv)
        return viewer.wait()
    except (KeyboardInterrupt, _Terminated):
        if viewer is None:  # a Ctrl-C reached the viewer's process group as well
            return 0
        viewer.terminate()  # whether or not the Ctrl-C reached it
        try:
            viewer.wait(_STOP_WAIT_S)
        except subprocess.TimeoutExpired:
            viewer.kill()
            viewer.wait()
        return 0


class _Terminated(Exception):
    """This command got SIGTERM."""


def _terminated(signum: int, frame: object) -> None:
    raise _Terminated
