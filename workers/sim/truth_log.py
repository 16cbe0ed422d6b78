"""The simulator's truth in each job's recording: the true object's meshes, logged by the simulator
itself (Rerun's shared recordings: the same application id and recording id as the job's own
recording, ``cell.recording``, written to ``<run dir>/<job id>.truth.rrd`` beside it; the viewer
shows the union). Neither the daemon nor its recorder know the simulator.

It hears of a job from the job's first event, and logs the scene as the simulator holds it.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path

from robocell.core_cy.meshes import vertex_normals
from robocell.wire import keys
from robocell.wire.messages import JobEvent, parse
from robocell.wire.transport import BaseTransport

from .objects import SimObject

__all__ = ["TruthLog", "follow", "truth_path", "write_truth"]

log = logging.getLogger(__name__)
_REMEMBERED = 1000      # jobs whose truth was logged, kept to log each once


def truth_path(run_dir: Path, job_id: str) -> Path:
    """Where the simulator logs job ``job_id``'s truth."""
    return Path(run_dir) / f"{job_id}.truth.rrd"


def write_truth(path: Path, job_id: str, scene: Sequence[SimObject]) -> None:
    """Log the true objects' meshes as ``world/truth`` (static) into job ``job_id``'s shared recording."""
    import rerun as rr

    recording = rr.RecordingStream(keys.RECORDING_APPLICATION_ID, recording_id=job_id)
    recording.save(path)
    try:
        for k, obj in enumerate(scene):
            vertices, triangles = obj.mesh()
            recording.log("world/truth" if k == 0 else f"world/truth/{k}", rr.Mesh3D(
                vertex_positions=vertices, triangle_indices=triangles,
                vertex_normals=vertex_normals(vertices, triangles), albedo_factor=(200, 200, 200, 120)), static=True)
    finally:
        recording.flush()
        recording.disconnect()


class TruthLog:
    """Logs ``scene`` into the recording of each job it hears of (from the job's events), once;
    thread-safe (a Zenoh callback may call it)."""

    def __init__(self, run_dir: Path, scene: Sequence[SimObject]) -> None:
        self._run_dir, self._scene = Path(run_dir), list(scene)
        self._logged: OrderedDict[str, None] = OrderedDict()
        self._lock = threading.Lock()

    def heard(self, payload: bytes) -> None:
        """An event (JobEvent JSON) of the cell's: the first of a job logs its truth."""
        try:
            job_id = parse(JobEvent, payload).job_id
        except ValueError:
            return
        with self._lock:
            if job_id in self._logged:
                return
            self._logged[job_id] = None
            if len(self._logged) > _REMEMBERED:
                self._logged.popitem(last=False)
        path = truth_path(self._run_dir, job_id)
        try:
            write_truth(path, job_id, self._scene)
        except OSError as exc:
            log.warning("job %s: the truth cannot be logged to %s: %s", job_id, path, exc)


async def follow(truth: TruthLog, transport: BaseTransport, cell: str) -> None:
    """Feed ``truth`` the events of ``cell``, until cancelled."""
    events = transport.subscribe(keys.events(cell))
    try:
        async for sample in events:
            await asyncio.to_thread(truth.heard, sample.payload)
    finally:
        events.close()
