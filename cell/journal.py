"""A job's share of its Rerun recording, kept with the job until the job waits for something slow.

Handing a message to the recorder process costs the event loop and the
interpreter time, and the recorder's work costs a processor; a robot that moves
at once answers in under a millisecond. So a job's recording messages wait in
its :class:`Journal`, and go over while a job waits for a snapshot or for a
reconstruction. Opening the recording is the first of them: making a Rerun
recording and its file costs the recorder a millisecond or two of processor,
which the bench (bench/bench_cell.py) saw as a slower first move when it was
done as the job started. A finished job's last messages (its reconstruction
drawn, the file closed) wait the same way, for the next such wait of any job,
or until the cell has been quiet a moment (the daemon decides when:
:meth:`Journal.hand_over`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from .executor import later
from .recorder import Recorder

__all__ = ["Journal"]

# What a waiting entry may be besides a JobRecording method: the recorder's own steps.
_RECONSTRUCTION = "<reconstruction>"
_CLOSE = "<close>"


class Journal:
    """The recording messages of job ``job_id``, timed from ``started`` by ``clock``."""

    def __init__(self, recorder: Recorder, job_id: str, path: Path, *, started: float,
                 clock: Callable[[], float]) -> None:
        self._recorder, self.job_id, self._started, self._clock = recorder, job_id, started, clock
        self._waiting: list[tuple[float, str, tuple[Any, ...], dict[str, Any]]] = []
        self._path: Path | None = path  # until the recording is opened, at the first hand-over

    def record(self, method: str, *args: Any, **kwargs: Any) -> None:
        """``JobRecording.<method>(*args, **kwargs)`` at the job time of now, when handed over."""
        self._waiting.append((self._clock() - self._started, method, args, kwargs))

    def reconstruction(self, reply_json: str, payload: bytes, *, at: float) -> None:
        """The reconstruction's silhouettes, clouds and meshes, drawn at job time ``at``, when handed over."""
        self._waiting.append((at, _RECONSTRUCTION, (reply_json, payload), {}))

    def close(self) -> None:
        """The recording is closed (the recorder writes its footer) once what waits is handed over."""
        self._waiting.append((0.0, _CLOSE, (), {}))

    def hand_over(self) -> None:
        """Hand what waits to the recorder, in order, when the event loop next looks round."""
        recorder = self._recorder
        if self._path is not None:
            later(recorder.open, self.job_id, self._path)
            self._path = None
        for at, method, args, kwargs in self._waiting:
            if method == _RECONSTRUCTION:
                later(recorder.reconstruction, self.job_id, at, *args)
            elif method == _CLOSE:
                later(recorder.close, self.job_id)
            else:
                later(recorder.call, self.job_id, at, method, *args, **kwargs)
        self._waiting.clear()
