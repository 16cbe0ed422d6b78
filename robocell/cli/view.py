"""``--view`` of ``robocell cell`` and ``robocell up``: every job streamed to a Rerun viewer as it happens.

Beside the per-job recordings (``<run dir>/<job id>.rrd``, unchanged), the
daemon's recorder streams each job, as one recording named ``job <id>``, to:

- ``--view``: the viewer the user has open (``rerun``, which listens on
  ``rerun+http://127.0.0.1:9876/proxy``);
- ``--view URL``: the viewer (or Rerun gRPC proxy) at that URL;
- ``--view web``: a web viewer robocell starts and stops with the cell
  (``rerun --serve-web`` on ``--view-web-port`` and ``--view-grpc-port``, on
  loopback); the address to open in a browser is printed.

A viewer that is not there when a job starts only costs that job its live
stream (the daemon's log says so once); the recording is written all the same.
"""

from __future__ import annotations

import argparse
import contextlib
import socket
import subprocess
import time
from collections.abc import Iterator
from urllib.parse import urlsplit

__all__ = ["add_view_arguments", "check_view_ports", "live_viewer", "view_url", "web_viewer_argv", "WEB",
           "DEFAULT_VIEWER_URL"]

WEB = "web"
_LOOPBACK = "127.0.0.1"
_SCHEMES = ("rerun", "rerun+http", "rerun+https")
_READY_S = 30.0   # the web viewer's servers listen within this long
_STOP_WAIT_S = 5.0
#: Where ``rerun`` (the native viewer) listens for SDKs by default.
DEFAULT_VIEWER_URL = "rerun+http://127.0.0.1:9876/proxy"
DEFAULT_WEB_PORT = 9090
#: Not the native viewer's 9876: one the user has open may hold that.
DEFAULT_GRPC_PORT = 9877


def _view(text: str) -> str:
    if text == WEB:
        return text
    address = urlsplit(text)
    if address.scheme not in _SCHEMES or address.path != "/proxy" or not address.hostname:
        raise argparse.ArgumentTypeError(f"{text!r}: give a Rerun viewer's gRPC URL "
                                         f"(rerun+http://HOST:PORT/proxy) or {WEB!r}")
    try:
        address.port
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: the port is not a number") from None
    return text


def add_view_arguments(parser: argparse.ArgumentParser) -> None:
    """``--view [URL|web]``, ``--view-web-port``, ``--view-grpc-port``."""
    parser.add_argument("--view", nargs="?", const=DEFAULT_VIEWER_URL, type=_view, metavar="URL|web",
                        help="stream every job to a Rerun viewer as it happens, beside the recordings: the viewer "
                             f"you have open (`rerun`; default {DEFAULT_VIEWER_URL}), the one at URL, or, with "
                             f"'{WEB}', a web viewer robocell starts (it prints the address to open)")
    parser.add_argument("--view-web-port", type=int, default=DEFAULT_WEB_PORT, metavar="PORT",
                        help="with --view web: the web viewer's HTTP port (default %(default)s)")
    parser.add_argument("--view-grpc-port", type=int, default=DEFAULT_GRPC_PORT, metavar="PORT",
                        help="with --view web: the port the web viewer takes the jobs on (default %(default)s)")


def web_viewer_argv(web_port: int, grpc_port: int, *, bind: str = _LOOPBACK) -> list[str]:
    """The web viewer with its gRPC proxy (SDKs send to it, browsers watch), no browser opened."""
    from robocell.cell.recording_files import rerun_executable

    return [rerun_executable(), "--serve-web", "--bind", bind, "--port", str(grpc_port),
            "--web-viewer-port", str(web_port)]


def view_url(view: str | None, grpc_port: int) -> str | None:
    """The gRPC URL the recorder streams to: ``view`` itself, or the web viewer's."""
    if view == WEB:
        return f"rerun+http://{_LOOPBACK}:{grpc_port}/proxy"
    return view


def check_view_ports(web_port: int, grpc_port: int) -> None:
    """Raise a :class:`~wire.errors.ConfigError` naming the port and its holder, if one is taken."""
    from robocell.wire.errors import ConfigError

    from .up import port_holder

    for option, port in (("--view-web-port", web_port), ("--view-grpc-port", grpc_port)):
        holder = port_holder(_LOOPBACK, port)
        if holder is not None:
            raise ConfigError(f"port {port} on {_LOOPBACK} is in use by {holder}: give {option} another port")


def _listening(port: int) -> bool:
    with socket.socket() as probe:
        return probe.connect_ex((_LOOPBACK, port)) == 0


@contextlib.contextmanager
def live_viewer(view: str | None, *, web_port: int = DEFAULT_WEB_PORT,
                grpc_port: int = DEFAULT_GRPC_PORT) -> Iterator[str | None]:
    """The URL to stream to (None: no live viewing); with ``view == "web"`` the web viewer runs
    meanwhile (its address printed), and is stopped at the end."""
    if view != WEB:
        if view is not None:
            print(f"streaming every job to the Rerun viewer at {view} (start `rerun` to watch)", flush=True)
        yield view
        return
    from robocell.wire.errors import ConfigError

    from .replay import web_viewer_address

    check_view_ports(web_port, grpc_port)
    viewer = subprocess.Popen(web_viewer_argv(web_port, grpc_port), stdin=subprocess.DEVNULL,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + _READY_S
        while not (_listening(grpc_port) and _listening(web_port)):
            if viewer.poll() is not None:
                raise ConfigError(f"the web viewer exited with status {viewer.returncode} as it started")
            if time.monotonic() > deadline:
                raise ConfigError(f"the web viewer did not listen on ports {web_port} and {grpc_port} "
                                  f"within {_READY_S:g} s")
            time.sleep(0.05)
        print(f"watch the jobs live: open {web_viewer_address(_LOOPBACK, web_port, grpc_port)}", flush=True)
        yield view_url(view, grpc_port)
    finally:
        viewer.terminate()
        try:
            viewer.wait(_STOP_WAIT_S)
        except subprocess.TimeoutExpired:
            viewer.kill()
            viewer.wait()

