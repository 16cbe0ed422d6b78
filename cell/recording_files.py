"""The recordings on disk: what one holds, the file of a job, and the viewer that replays it.

Written by :class:`robocell.cell.recording.JobRecording`; read here by ``robocell replay``, the
tests and anything else that looks at a run directory.
"""

from __future__ import annotations

import os
import shutil
import sys
import warnings
from pathlib import Path

from rerun.chunk import RrdReader
from rerun.error_utils import RerunWarning

__all__ = ["recording_summary", "find_recording", "rerun_executable", "shared_parts", "replay_command"]


def recording_summary(path) -> dict[str, list[str]]:
    """Entity paths of a recording and the archetypes logged on each.

    Works on a recording still being written (no footer yet): it is then
    read by a whole-file scan, whose warning about that is silenced.

    Returns
    -------
    dict of str to list of str
        e.g. ``{"/world/camera0/image": ["EncodedImage"], ...}``, names sorted.
    """
    found: dict[str, set[str]] = {}
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*no footer", category=RerunWarning)
        for chunk in RrdReader(str(path)).stream():
            names = found.setdefault(chunk.entity_path, set())
            for field in chunk.to_record_batch().schema:
                archetype = (field.metadata or {}).get(b"rerun:archetype")
                if archetype:
                    names.add(archetype.decode().rpartition(".")[2])
    return {entity: sorted(names) for entity, names in sorted(found.items())}


def find_recording(job_id_or_file: str, run_dir: Path) -> Path:
    """The ``.rrd`` file of a job: an existing ``.rrd`` path, or ``<run_dir>/<job id>.rrd``.

    Raises
    ------
    FileNotFoundError
        If none exists; the message lists the paths tried.
    """
    given, run_dir = Path(job_id_or_file).expanduser(), Path(run_dir)
    if given.suffix == ".rrd":
        candidates = [given]
        if not given.is_absolute() and len(given.parts) == 1:
            candidates.append(run_dir / given)
    else:
        candidates = [run_dir / f"{job_id_or_file}.rrd"]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(f"no recording for {job_id_or_file!r}: looked for "
                            + ", ".join(str(c) for c in candidates))


def rerun_executable() -> str:
    # The viewer binary that came with the installed SDK (so the versions match), run directly: the
    # venv's `rerun` script is a Python wrapper that runs it as a child of its own and, at a Ctrl-C,
    # returns at once, leaving the viewer running behind it. One on PATH may be another version.
    try:
        import rerun_cli

        bundled = Path(rerun_cli.__file__).with_name("rerun")
        if bundled.is_file() and os.access(bundled, os.X_OK):
            return str(bundled)
    except ImportError:
        pass
    beside = shutil.which("rerun", path=str(Path(sys.executable).parent))
    found = beside or shutil.which("rerun")
    if found is None:
        raise FileNotFoundError(f"no 'rerun' executable next to {sys.executable} or on PATH "
                                "(it comes with the rerun-sdk package)")
    return found


def shared_parts(path: Path) -> list[Path]:
    """The other files of the recording at ``path`` (``<job id>.<part>.rrd``, made by other
    processes with the same recording id: the simulator's truth, say), which a viewer shows with it."""
    path = Path(path)
    return sorted(path.parent.glob(f"{path.stem}.*.rrd"))


def replay_command(path: Path, *, web: bool = False, bind: str = "127.0.0.1", web_port: int = 9090,
                   grpc_port: int = 9876) -> list[str]:
    """The argv that opens a recording (with its :func:`shared_parts`) in the native viewer, or serves
    it to a browser.

    The viewer's servers listen on ``bind``, loopback by default (rerun's own default is
    0.0.0.0). With ``web`` the recording is served over gRPC on ``grpc_port`` and the web
    viewer on ``web_port``, and no browser is opened.
    """
    argv = [rerun_executable(), str(path), *map(str, shared_parts(path)), "--bind", bind]
    if web:
        argv += ["--serve-web", "--port", str(grpc_port), "--web-viewer-port", str(web_port)]
    return argv
