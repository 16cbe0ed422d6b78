"""The daemon's recorder: a process of its own that writes every job's Rerun recording.

Logging a job costs milliseconds of Python (pictures, clouds, meshes, the
file's flush). In the daemon's process that work would compete with the event
loop for the interpreter and delay every step of every job; in a process of
its own it only competes for a processor. The daemon hands messages to
:class:`Recorder` without waiting; a thread pickles them down a pipe; the
recorder process writes each job's ``.rrd`` in the order given, and closes it
(the file then has its footer) when told the job is over.

If the daemon dies, the pipe's other end closes: the recorder closes every
recording it has open and exits.

Every recording closed is checked (it must read back with its footer) and the
verdict goes back up a second pipe: :meth:`Recorder.finish` is the future of
it, which the daemon awaits before it tells a job's result, so that a recording
that could not be written (a full disk, a file cut short, 0 bytes) is named in
the result's ``recording_error``, never told as a recording. A recorder process
that dies (``kill -9``, say) loses the recordings it had open, each named so;
the next recording goes to a new process.

A recorder process makes at most ``recordings_per_process`` recordings; the
next job's goes to a new one, and the old one ends once its last recording is
closed. Rerun never ends the two threads it starts for a recording made from
Python (rerun-io/rerun#2116: the recording is only disconnected, never
dropped); each wakes five times a second, and a process that had recorded a
day of jobs would hold tens of thousands of them. Nor does it free what was
logged to a recording: a recorder process grows by about each job's data
until it is replaced (the soak's +28 %).

Messages are tuples ``(kind, job_id, job_time_s, body)``:

==================  ==============================================================
``open``            body: the ``.rrd`` path
``call``            body: ``(method, args, kwargs)`` of :class:`~cell.recording.JobRecording`
``reconstruction``  body: a ReconstructReply's JSON and its payload: silhouettes, clouds and meshes
``close``           body: None; the recorder answers ``(job_id, problem)`` up its report pipe
==================  ==============================================================

With ``live`` (a viewer's gRPC URL, ``robocell cell --view``), each recording is also streamed to
that viewer as it is written, when the viewer takes connections as the recording opens.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import multiprocessing
import multiprocessing.connection
import queue
import signal
import threading
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from .recorder_process import run_recorder

__all__ = ["Recorder"]

log = logging.getLogger(__name__)
# Within what a stopping cell allows its daemon (robocell up waits 5 s, then kills): the recorder
# is secondary, and one still importing Rerun on a busy machine must not hold the daemon up.
_STOP_WAIT_S = 3.0
#: Recordings a recorder process makes before a new one takes over (see the module's text): its
#: leftover threads then cost at most 9 ms of processor a second (measured with 100), and what
#: Rerun keeps of its closed recordings (1.1-1.6 MB of resident memory per MB logged, measured over
#: 60 recordings with Rerun 0.41, whatever the batcher's settings) about 25 jobs' data; starting
#: the next process (0.9-1.1 s of processor, measured) costs a 25th of that a job.
RECORDINGS_PER_PROCESS = 25
_WATCH_S = 0.5          # how often the watcher looks for recorder processes started meanwhile
_REAP_WAIT_S = 1.0


class Recorder:
    """Writes the jobs' recordings in a child process; every method returns at once.

    Parameters
    ----------
    n_points : int
        Points on the sphere the reconstruction starts from (drawn before carving).
    recordings_per_process : int
        Recordings a recorder process makes before a new one takes over.
    live : str, optional
        A Rerun viewer's gRPC URL: every recording is streamed to it too.
    """

    def __init__(self, *, n_points: int, recordings_per_process: int = RECORDINGS_PER_PROCESS,
                 live: str | None = None) -> None:
        self._arguments = (n_points, live)
        self._per_process = recordings_per_process
        self._outbox: queue.SimpleQueue = queue.SimpleQueue()
        self._feeder = threading.Thread(target=self._feed, name="recorder-feeder", daemon=True)
        self._watcher = threading.Thread(target=self._watch, name="recorder-watcher", daemon=True)
        # Shared by the feeder, the watcher and the callers of finish():
        self._lock = threading.Lock()
        self._current: _Child | None = None     # where new recordings go
        self._child_of: dict[str, _Child] = {}  # the open recordings, by job: the child that has each
        self._children: list[_Child] = []       # every one not yet seen to end
        self._verdicts: dict[str, concurrent.futures.Future[str | None]] = {}  # finish() waiting, by job
        self._lost: dict[str, str] = {}         # recordings lost with their process, by job, until closed
        self._stopped = threading.Event()

    def start(self) -> None:
        """Start the recorder process (it imports Rerun meanwhile: messages wait in the pipe)."""
        with self._lock:
            self._current = self._start_child()
        self._feeder.start()
        self._watcher.start()

    def _start_child(self) -> _Child:
        context = multiprocessing.get_context("spawn")  # never fork a process that runs threads
        reader, writer = context.Pipe(duplex=False)
        report_reader, report_writer = context.Pipe(duplex=False)
        # The child gets only the reading end: when this process dies, it reads end-of-file.
        process = context.Process(target=run_recorder,
                                  args=(reader, report_writer, *self._arguments, logging.getLogger().level),
                                  name="robocell-recorder", daemon=True)
        process.start()
        reader.close()
        report_writer.close()
        child = _Child(process, writer, report_reader)
        self._children.append(child)
        return child

    @property
    def pids(self) -> list[int]:
        """The process ids of the recorder processes now running, the one taking new recordings last."""
        with self._lock:
            children = sorted(self._children, key=lambda child: child is self._current)
            return [child.process.pid for child in children if child.process.pid is not None and not child.gone]

    def open(self, job_id: str, path: Path) -> None:
        self._outbox.put(("open", job_id, 0.0, str(path)))

    def call(self, job_id: str, at: float, method: str, *args, **kwargs) -> None:
        """``JobRecording.<method>(*args, **kwargs)`` at job time ``at`` seconds."""
        self._outbox.put(("call", job_id, at, (method, args, kwargs)))

    def reconstruction(self, job_id: str, at: float, reply_json: str, payload: bytes) -> None:
        self._outbox.put(("reconstruction", job_id, at, (reply_json, payload)))

    def close(self, job_id: str) -> None:
        self._outbox.put(("close", job_id, 0.0, None))

    def finish(self, job_id: str) -> concurrent.futures.Future[str | None]:
        """Close the job's recording; the future's result is None once the file is complete, else
        what is wrong with it (it could not be written, it is cut short, its recorder died)."""
        future: concurrent.futures.Future[str | None] = concurrent.futures.Future()
        with self._lock:
            self._verdicts[job_id] = future
        self.close(job_id)
        return future

    async def verdict(self, job_id: str, path: Path, within_s: float) -> str | None:
        """:meth:`finish` awaited: None once the job's recording at ``path`` is complete, else what
        is wrong with it; after ``within_s`` without the recorder's word, that it may be incomplete."""
        try:
            async with asyncio.timeout(within_s):
                return await asyncio.wrap_future(self.finish(job_id))
        except TimeoutError:
            return (f"the recorder had not closed the recording {path} {within_s:g} s after the job ended: "
                    f"it may be incomplete")

    def stop(self) -> None:
        """Let the recorder finish and close every recording; bounded in time."""
        if self._current is None:
            return
        self._outbox.put(None)
        self._feeder.join(_STOP_WAIT_S)
        with self._lock:
            processes = [child.process for child in self._children]
        for process in processes:
            process.join(_STOP_WAIT_S)
            if process.is_alive():
                log.warning("the recorder did not stop in %g s: terminating it", _STOP_WAIT_S)
                process.terminate()
                process.join(_STOP_WAIT_S)
        self._stopped.set()
        self._watcher.join(_STOP_WAIT_S)
        with self._lock:
            waiting, self._verdicts = self._verdicts, {}
        for job_id, future in waiting.items():
            _settle(future, f"the daemon stopped before the recording of job {job_id} was closed")

    # --- the feeder thread: messages to the children --------------------------------------------

    def _feed(self) -> None:
        try:
            while (message := self._outbox.get()) is not None:
                kind, job_id = message[0], message[1]
                with self._lock:
                    if kind == "open":
                        opener = self._child_of[job_id] = self._child_for_a_new_recording()
                        opener.made += 1
                        opener.unreported[job_id] = message[3]
                        self._lost.pop(job_id, None)
                    child = self._child_of.get(job_id)
                    lost = self._lost.pop(job_id, None) if child is None and kind == "close" else None
                if child is None:
                    if kind == "close":  # never opened, or lost with its process
                        self._settle(job_id, lost or f"job {job_id} had no recording open")
                    continue
                child.send(message)
                if kind == "close":
                    with self._lock:
                        del self._child_of[job_id]
                        # A child that died with the recording still has it unreported: the
                        # watcher names the loss when it sees the process end.
                        self._end_if_done(child)
        finally:
            with self._lock:
                ending = set(self._child_of.values())
                if self._current is not None:
                    ending.add(self._current)
                for child in ending:
                    self._end(child)

    def _child_for_a_new_recording(self) -> _Child:
        current = self._current
        assert current is not None, "start() starts the first"
        if current.made < self._per_process and not current.broken:
            return current
        if current.broken:
            log.warning("a new recorder process records the jobs from now on")
        successor = self._current = self._start_child()
        self._end_if_done(current)
        return successor

    def _end_if_done(self, child: _Child) -> None:
        """A child that takes no new recordings ends once none of its recordings is open."""
        if child is not self._current and child not in self._child_of.values():
            self._end(child)

    def _end(self, child: _Child) -> None:
        """Tell a child to close its recordings and end (:meth:`stop` still waits for it)."""
        if not child.ending:
            child.ending = True
            child.send(None)
            child.writer.close()

    # --- the watcher thread: verdicts and deaths from the children ------------------------------

    def _watch(self) -> None:
        while True:
            with self._lock:
                children = [child for child in self._children if not child.gone]
            if self._stopped.is_set() and not children:
                return
            waiting: list[Any] = [child.reports for child in children if not child.reports_closed]
            waiting += [child.process.sentinel for child in children]
            ready = set(multiprocessing.connection.wait(waiting, timeout=_WATCH_S)) if waiting else set()
            if not waiting:
                self._stopped.wait(_WATCH_S)
            for child in children:
                if child.reports in ready:
                    self._read_reports(child)
                if child.process.sentinel in ready:
                    self._read_reports(child)  # what it said before it ended comes first
                    self._gone(child)

    def _read_reports(self, child: _Child) -> None:
        while not child.reports_closed:
            try:
                if not child.reports.poll():
                    return
                job_id, problem = child.reports.recv()
            except (EOFError, OSError):
                child.reports_closed = True
                return
            with self._lock:
                child.unreported.pop(job_id, None)
            if problem is not None:
                log.error("job %s: %s", job_id, problem)
            self._settle(job_id, problem)

    def _gone(self, child: _Child) -> None:
        process = child.process
        process.join(_REAP_WAIT_S)  # its sentinel closes a moment before it can be reaped
        code = process.exitcode
        with self._lock:
            child.gone = child.broken = True
            self._children.remove(child)
            if not child.unreported:
                return
            if code is not None and code < 0:
                try:
                    how = f"killed by {signal.Signals(-code).name}"
                except ValueError:
                    how = f"killed by signal {-code}"
            else:
                how = f"exited with status {code}"
            lost = self._lose(child, f"the recorder process {process.pid} died ({how})")
        log.error("the recorder process %d died (%s): %d recordings lost; the next jobs are recorded by a "
                  "new one", process.pid, how, lost)

    def _lose(self, child: _Child, why: str) -> int:
        """Name every recording of ``child`` not yet reported as lost (the lock held); how many."""
        lost = 0
        for job_id, path in list(child.unreported.items()):
            del child.unreported[job_id]
            problem = f"{why} while writing the recording {path}: it is cut short, or empty"
            lost += 1
            if job_id in self._child_of:  # still open: its close settles it
                del self._child_of[job_id]
                self._lost[job_id] = problem
            self._settle(job_id, problem, locked=True)
        return lost

    def _settle(self, job_id: str, problem: str | None, *, locked: bool = False) -> None:
        if locked:
            future = self._verdicts.pop(job_id, None)
        else:
            with self._lock:
                future = self._verdicts.pop(job_id, None)
        if future is not None:
            _settle(future, problem)


def _settle(future: concurrent.futures.Future, value: str | None) -> None:
    try:
        future.set_result(value)
    except concurrent.futures.InvalidStateError:  # the waiter gave up, and cancelled it
        pass


class _Child:
    """A recorder process, the end of the pipe that feeds it, and the end of the one it reports on."""

    def __init__(self, process: multiprocessing.process.BaseProcess, writer: Connection,
                 reports: Connection) -> None:
        self.process = process
        self.writer = writer
        self.reports = reports
        self.made = 0           # recordings it was asked to make
        self.unreported: dict[str, str] = {}  # the recordings it has not yet said are closed: job -> path
        self.broken = False     # it is gone, as a pipe to write to
        self.gone = False       # its process has ended
        self.ending = False     # told to end
        self.reports_closed = False

    def send(self, message: tuple | None) -> None:
        if self.broken:
            return
        try:
            self.writer.send(message)
        except OSError as exc:  # the recorder is gone
            self.broken = True
            if message is not None:
                log.error("the recorder process is gone (%s)", exc)
