"""The daemon's recorder: a process of its own that writes every job's Rerun recording.

Logging a job costs milliseconds of Python (pictures, clouds, meshes, the
file's flush). In the daemon's process that work would compete with the event
loop for the interpreter and delay every step of every job; in a process of
its own it only competes for a processor. The daemon hands messages to
:class:`Recorder` without waiting; a thread pickles them down a pipe; the
recorder process writes each job's ``.rrd`` in the order given, and closes it
(the file then has its footer) when told the job is over.

If the daemon dies, the pipe's other end closes: the recorder closes every
recording it has open and exits. If the recorder dies, the daemon goes on
without recordings and says so in its log.

Messages are tuples ``(kind, job_id, job_time_s, body)``:

==================  ==============================================================
``open``            body: the ``.rrd`` path
``call``            body: ``(method, args, kwargs)`` of :class:`~cell.recording.JobRecording`
``reconstruction``  body: a ReconstructReply's JSON and its payload: silhouettes, clouds and meshes
``close``           body: None
==================  ==============================================================
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import queue
import threading
from multiprocessing.connection import Connection
from pathlib import Path

__all__ = ["Recorder"]

log = logging.getLogger(__name__)
# Within what a stopping cell allows its daemon (robocell up waits 5 s, then kills): the recorder
# is secondary, and one still importing Rerun on a busy machine must not hold the daemon up.
_STOP_WAIT_S = 3.0
_NICENESS = 19  # the lowest: the recording may wait, the robot may not
_LOG_FORMAT = "%(asctime)s %(name)s %(levelname)s %(message)s"


class Recorder:
    """Writes the jobs' recordings in a child process; every method returns at once.

    Parameters
    ----------
    n_points : int
        Points on the sphere the reconstruction starts from (drawn before carving).
    sim : dict or None
        The ``[sim]`` section, to draw the true object beside the fit; None on a real cell.
    """

    def __init__(self, *, n_points: int, sim: dict | None) -> None:
        self._arguments = (n_points, sim)
        self._outbox: queue.SimpleQueue = queue.SimpleQueue()
        self._feeder = threading.Thread(target=self._feed, name="recorder-feeder", daemon=True)
        self._process: multiprocessing.process.BaseProcess | None = None
        self._writer: Connection | None = None
        self._broken = False

    def start(self) -> None:
        """Start the recorder process (it imports Rerun meanwhile: messages wait in the pipe)."""
        context = multiprocessing.get_context("spawn")  # never fork a process that runs threads
        reader, self._writer = context.Pipe(duplex=False)
        # The child gets only the reading end: when this process dies, it reads end-of-file.
        self._process = context.Process(target=_main, args=(reader, *self._arguments, logging.getLogger().level),
                                        name="robocell-recorder", daemon=True)
        self._process.start()
        reader.close()
        self._feeder.start()

    def open(self, job_id: str, path: Path) -> None:
        self._outbox.put(("open", job_id, 0.0, str(path)))

    def call(self, job_id: str, at: float, method: str, *args, **kwargs) -> None:
        """``JobRecording.<method>(*args, **kwargs)`` at job time ``at`` seconds."""
        self._outbox.put(("call", job_id, at, (method, args, kwargs)))

    def reconstruction(self, job_id: str, at: float, reply_json: str, payload: bytes) -> None:
        self._outbox.put(("reconstruction", job_id, at, (reply_json, payload)))

    def close(self, job_id: str) -> None:
        self._outbox.put(("close", job_id, 0.0, None))

    def stop(self) -> None:
        """Let the recorder finish and close every recording; bounded in time."""
        if self._process is None:
            return
        self._outbox.put(None)
        self._feeder.join(_STOP_WAIT_S)
        self._process.join(_STOP_WAIT_S)
        if self._process.is_alive():
            log.warning("the recorder did not stop in %g s: terminating it", _STOP_WAIT_S)
            self._process.terminate()
            self._process.join(_STOP_WAIT_S)

    def _feed(self) -> None:
        assert self._writer is not None
        try:
            while (message := self._outbox.get()) is not None:
                if self._broken:
                    continue
                try:
                    self._writer.send(message)
                except OSError as exc:  # the recorder is gone
                    self._broken = True
                    log.error("the recorder process is gone (%s): jobs are no longer recorded", exc)
            if not self._broken:
                self._writer.send(None)
        except OSError:
            pass
        finally:
            self._writer.close()


def _main(connection: Connection, n_points: int, sim: dict | None, level: int) -> None:
    """The recorder process: apply messages until told to stop, or until the daemon is gone."""
    logging.basicConfig(level=level or logging.INFO, format=_LOG_FORMAT)
    # Recording is background work: on a busy machine the processes that run the jobs go first.
    os.nice(_NICENESS)
    from .recording import JobRecording

    recordings: dict[str, JobRecording] = {}
    drawing = _Drawing(n_points, sim)
    try:
        while True:
            try:
                message = connection.recv()
            except EOFError:
                log.warning("the daemon is gone: closing %d open recordings", len(recordings))
                break
            if message is None:
                break
            kind, job_id, at, body = message
            try:
                if kind == "open":
                    recordings[job_id] = JobRecording(Path(body), job_id)
                    continue
                recording = recordings.get(job_id)
                if recording is None:
                    continue  # its opening failed, and was logged
                if kind == "close":
                    del recordings[job_id]
                    recording.close()
                    continue
                recording.set_time(at)
                if kind == "call":
                    method, args, kwargs = body
                    getattr(recording, method)(*args, **kwargs)
                elif kind == "reconstruction":
                    drawing.reconstruction(recording, *body)
            except Exception as exc:  # one bad message must not cost the other jobs their recordings
                log.exception("job %s: recording %s failed", job_id, kind)
                if job_id in recordings:
                    recordings[job_id].log_text(f"recording {kind} failed: {type(exc).__name__}: {exc}", "ERROR")
    finally:
        for recording in recordings.values():
            recording.close()
        connection.close()


class _Drawing:
    """What a reconstruction looks like in a recording (in the recorder process)."""

    def __init__(self, n_points: int, sim: dict | None) -> None:
        self.n_points = n_points
        self.sim = sim
        self._truth: list | None = None

    def reconstruction(self, recording, reply_json: str, payload: bytes) -> None:
        import cv2
        import numpy as np

        from core_cy.sphere import fibonacci_sphere
        from core_cy.superquadric import Superquadric
        from wire.messages import ReconstructReply

        answer = ReconstructReply.model_validate_json(reply_json)
        result = answer.result
        if result is None or answer.points is None:
            return
        at = 0
        for view, blob in enumerate(answer.silhouettes):
            png = np.frombuffer(payload, np.uint8, count=blob.length, offset=at)
            recording.log_silhouette(view, cv2.imdecode(png, cv2.IMREAD_GRAYSCALE))
            at += blob.length
        points = np.frombuffer(payload, "<f4", count=answer.points.length // 4, offset=at).reshape(-1, 3)
        sphere = np.asarray(result.centre) + result.radius * fibonacci_sphere(self.n_points)
        recording.log_points("sphere", sphere, colour=(150, 150, 150))
        recording.log_points("carved", points.astype(np.float64))
        recording.log_superquadric("fit", Superquadric.from_dict(result.superquadric.model_dump()))
        timings = ", ".join(f"{stage} {ms:.1f} ms" for stage, ms in result.timings_ms.items())
        recording.log_text(f"reconstruction on {answer.worker}: {timings}")
        if self.sim is not None:
            for vertices, triangles in self._truth_meshes():
                recording.log_mesh("truth", vertices, triangles)

    def _truth_meshes(self) -> list:
        if self._truth is None:
            from wire.config import SimConfig
            from workers.sim.scene import scene_from_config

            self._truth = [obj.mesh() for obj in scene_from_config(SimConfig.model_validate(self.sim))]
        return self._truth
