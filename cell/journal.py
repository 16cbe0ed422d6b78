"""A job's share of its Rerun recording, kept with the job until the job waits for something slow.

Handing a message to the recorder process costs the event loop and the
interpreter time, and a robot that moves at once answers in under a
millisecond; so a job's recording messages wait in its :class:`Journal`, and go
over while the job waits for a snapshot or for the reconstruction, and once
its end is published.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from .executor import later
from .recorder import Recorder

__all__ = ["Journal"]


class Journal:
    """The recording messages of job ``job_id``, timed from ``started`` by ``clock``."""

    def __init__(self, recorder: Recorder, job_id: str, path: Path, *, started: float,
                 clock: Callable[[], float]) -> None:
        self._recorder, self.job_id, self._started, self._clock = recorder, job_id, started, clock
        self._waiting: list[tuple[float, str, tuple[Any, ...], dict[str, Any]]] = []
        later(recorder.open, job_id, path)

    def record(self, method: str, *args: Any, **kwargs: Any) -> None:
        """``JobRecording.<method>(*args, **kwargs)`` at the job time of now, when handed over."""
        self._waiting.append((self._clock() - self._started, method, args, kwargs))

    def hand_over(self) -> None:
        """Hand what waits to the recorder, when the event loop next looks round."""
        for at, method, args, kwargs in self._waiting:
            later(self._recorder.call, self.job_id, at, method, *args, **kwargs)
        self._waiting.clear()

    def reconstruction(self, reply_json: str, payload: bytes, *, at: float) -> None:
        """The reconstruction's silhouettes, clouds and meshes, drawn at job time ``at``."""
        later(self._recorder.reconstruction, self.job_id, at, reply_json, payload)

    def close(self) -> None:
        """Hand over what waits, then close the recording (the recorder writes its footer)."""
        self.hand_over()
        later(self._recorder.close, self.job_id)
