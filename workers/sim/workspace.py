"""The simulated workspace is empty while the cell takes backgrounds: the simulator's stand-in for
the operator who takes the object away before ``robocell background`` and puts it back after.

The simulated camera hears the cell's job events (as its truth log does, ``workers.sim.truth_log``)
and photographs the empty workspace (``SceneCamera.object_present``) from the first event of a
running job of ``kind: backgrounds`` (``JobEvent.kind``) to its end. Nothing in the cell knows
the simulator: the events say each job's kind for every listener, and a real camera ignores
them. The daemon publishes a step's event before it asks the robot to move, so the camera hears
that the workspace is empty a move's round trip before the job's first picture.
"""

from __future__ import annotations

import logging
import threading

from robocell.wire.messages import JobEvent, Lifecycle, parse

from .camera import SceneCamera

__all__ = ["Workspace"]

log = logging.getLogger(__name__)


class Workspace:
    """Clears ``camera``'s workspace while a backgrounds job runs; thread-safe."""

    def __init__(self, camera: SceneCamera) -> None:
        self._camera = camera
        self._emptied_by: str | None = None      # the backgrounds job that runs
        self._lock = threading.Lock()

    def heard(self, payload: bytes) -> None:
        """An event (JobEvent JSON) of the cell's."""
        try:
            event = parse(JobEvent, payload)
        except ValueError:
            return
        with self._lock:
            if event.kind == "backgrounds" and event.lifecycle in (Lifecycle.RUNNING, Lifecycle.CANCELLING):
                if self._emptied_by != event.job_id:
                    log.info("job %s takes backgrounds: the object leaves the simulated workspace", event.job_id)
                self._emptied_by = event.job_id
                self._camera.object_present = False
            elif event.job_id == self._emptied_by and event.lifecycle.finished:
                log.info("the object is back in the simulated workspace")
                self._emptied_by = None
                self._camera.object_present = True
