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

A recorder process makes at most ``recordings_per_process`` recordings; the
next job's goes to a new one, and the old one ends once its last recording is
closed. Rerun never ends the two threads it starts for a recording made from
Python (rerun-io/rerun#2116: the recording is only disconnected, never
dropped); each wakes five times a second, and a process that had recorded a
day of jobs would hold tens of thousands of them.

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
import signal
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
#: Recordings a recorder process makes before a new one takes over (see the module's text): its
#: leftover threads then cost at most 9 ms of processor a second (measured with 100), and starting
#: the next process (0.9-1.1 s of processor, measured) a hundredth of that a job.
RECORDINGS_PER_PROCESS = 100


class Recorder:
    """Writes the jobs' recordings in a child process; every method returns at once.

    Parameters
    ----------
    n_points : int
        Points on the sphere the reconstruction starts from (drawn before carving).
    recordings_per_process : int
        Recordings a recorder process makes before a new one takes over.
    """

    def __init__(self, *, n_points: int, recordings_per_process: int = RECORDINGS_PER_PROCESS) -> None:
        self._arguments = (n_points,)
        self._per_process = recordings_per_process
        self._outbox: queue.SimpleQueue = queue.SimpleQueue()
        self._feeder = threading.Thread(target=self._feed, name="recorder-feeder", daemon=True)
        self._current: _Child | None = None     # where new recordings go
        self._child_of: dict[str, _Child] = {}  # the open recordings, by job: the child that has each
        self._processes: list[multiprocessing.process.BaseProcess] = []  # every one not known to have ended

    def start(self) -> None:
        """Start the recorder process (it imports Rerun meanwhile: messages wait in the pipe)."""
        self._current = self._start_child()
        self._feeder.start()

    def _start_child(self) -> _Child:
        context = multiprocessing.get_context("spawn")  # never fork a process that runs threads
        reader, writer = context.Pipe(duplex=False)
        # The child gets only the reading end: when this process dies, it reads end-of-file.
        process = context.Process(target=_main, args=(reader, *self._arguments, logging.getLogger().level),
                                  name="robocell-recorder", daemon=True)
        process.start()
        reader.close()
        self._processes = [p for p in self._processes if p.is_alive()] + [process]
        return _Child(writer)

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
        if self._current is None:
            return
        self._outbox.put(None)
        self._feeder.join(_STOP_WAIT_S)
        for process in list(self._processes):
            process.join(_STOP_WAIT_S)
            if process.is_alive():
                log.warning("the recorder did not stop in %g s: terminating it", _STOP_WAIT_S)
                process.terminate()
                process.join(_STOP_WAIT_S)

    def _feed(self) -> None:
        try:
            while (message := self._outbox.get()) is not None:
                kind, job_id = message[0], message[1]
                if kind == "open":
                    self._child_of[job_id] = self._child_for_a_new_recording()
                child = self._child_of.get(job_id)
                if child is None:
                    continue  # its recording was never opened: nothing to add it to
                child.send(message)
                if kind == "open":
                    child.made += 1
                elif kind == "close":
                    del self._child_of[job_id]
                    self._end_if_done(child)
        finally:
            ending = set(self._child_of.values())
            if self._current is not None:
                ending.add(self._current)
            for child in ending:
                self._end(child)

    def _child_for_a_new_recording(self) -> _Child:
        current = self._current
        assert current is not None, "start() starts the first"
        if current.made < self._per_process or current.broken:  # a dead one is not replaced: see the module's text
            return current
        successor = self._current = self._start_child()
        self._end_if_done(current)
        return successor

    def _end_if_done(self, child: _Child) -> None:
        """A child that takes no new recordings ends once none of its recordings is open."""
        if child is not self._current and child not in self._child_of.values():
            self._end(child)

    def _end(self, child: _Child) -> None:
        """Tell a child to close its recordings and end (:meth:`stop` still waits for it)."""
        child.send(None)
        child.writer.close()


class _Child:
    """A recorder process, as the end of the pipe that feeds it."""

    def __init__(self, writer: Connection) -> None:
        self.writer = writer
        self.made = 0           # recordings it was asked to make
        self.broken = False     # it is gone

    def send(self, message: tuple | None) -> None:
        if self.broken:
            return
        try:
            self.writer.send(message)
        except OSError as exc:  # the recorder is gone
            self.broken = True
            if message is not None:
                log.error("the recorder process is gone (%s): jobs are no longer recorded", exc)


def _main(connection: Connection, n_points: int, level: int) -> None:
    """The recorder process: apply messages until told to stop, or until the daemon is gone."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a terminal's Ctrl-C is for the daemon, which stops this process
    logging.basicConfig(level=level or logging.INFO, format=_LOG_FORMAT)
    # Recording is background work: on a busy machine the processes that run the jobs go first.
    os.nice(_NICENESS)
    from .recording import JobRecording

    recordings: dict[str, JobRecording] = {}
    drawing = _Drawing(n_points)
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

    def __init__(self, n_points: int) -> None:
        self.n_points = n_points

    def reconstruction(self, recording, reply_json: str, payload: bytes) -> None:
        import cv2
        import numpy as np

        from robocell.core_cy.sphere import fibonacci_sphere
        from robocell.core_cy.superquadric import Superquadric
        from robocell.wire.messages import ReconstructReply

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
