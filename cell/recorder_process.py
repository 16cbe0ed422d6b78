"""The recorder process (:class:`robocell.cell.recorder.Recorder` starts it): it applies the daemon's
messages to each job's :class:`~robocell.cell.recording.JobRecording` until told to stop, or until
the daemon is gone, and reports each recording's verdict as it closes it."""

from __future__ import annotations

import logging
import os
import signal
import socket
from multiprocessing.connection import Connection
from pathlib import Path
from urllib.parse import urlsplit

__all__ = ["run_recorder"]

log = logging.getLogger("robocell.cell.recorder")
_NICENESS = 10  # below the jobs: the recording may wait, the robot may not (a success waits for its close)
LOG_FORMAT = "%(asctime)s %(name)s %(levelname)s %(message)s"
_VIEWER_PROBE_S = 0.3   # a viewer on this machine or the next answers a connection within it


def run_recorder(connection: Connection, reports: Connection, n_points: int, live: str | None, level: int) -> None:
    """The recorder process: apply messages until told to stop, or until the daemon is gone."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a terminal's Ctrl-C is for the daemon, which stops this process
    logging.basicConfig(level=level or logging.INFO, format=LOG_FORMAT)
    # Recording is background work: on a busy machine the processes that run the jobs go first.
    os.nice(_NICENESS)
    from .recording import JobRecording

    recordings: dict[str, JobRecording] = {}
    unopened: dict[str, str] = {}   # why a job's recording could not be opened
    unwritten: set[str] = set()     # the recordings logged to since they were last flushed
    drawing = _Drawing(n_points)
    viewer = _Viewer(live)

    def report(job_id: str, problem: str | None) -> None:
        try:
            reports.send((job_id, problem))
        except OSError:  # the daemon is gone: nobody to tell
            pass

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
                    try:
                        recordings[job_id] = JobRecording(Path(body), job_id, live=viewer.url())
                    except Exception as exc:
                        unopened[job_id] = f"the recording {body} could not be opened: {exc}"
                        raise
                    continue
                if kind == "close" and job_id in unopened:
                    report(job_id, unopened.pop(job_id))
                    continue
                recording = recordings.get(job_id)
                if recording is None:
                    continue  # its opening failed, and was logged
                if kind == "close":
                    del recordings[job_id]
                    # The verdict is told as soon as the file is read back whole; the stream is
                    # freed after, as nobody waits for that.
                    report(job_id, recording.end())
                    recording.release()
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
            unwritten.add(job_id)
            # Nothing waiting: what was logged goes to disk now, not at the close that a success waits for.
            if not connection.poll():
                for written in unwritten & recordings.keys():
                    recordings[written].flush()
                unwritten.clear()
    finally:
        for job_id, recording in recordings.items():
            report(job_id, recording.close())
        for job_id, problem in unopened.items():
            report(job_id, problem)
        connection.close()
        reports.close()
        # Every recording is closed: Rerun's own exit handler would flush them again, and after a
        # failed write (a full disk) it never returns, leaving the process running for ever.
        logging.shutdown()
        os._exit(0)


class _Viewer:
    """The live viewer, if any: a recording opened while it takes no connections is not streamed
    (Rerun would retry for seconds at the recording's end, holding the other jobs' recordings up)."""

    def __init__(self, url: str | None) -> None:
        self._url = url
        self._reachable: bool | None = None

    def url(self) -> str | None:
        if self._url is None:
            return None
        address = urlsplit(self._url)
        try:
            with socket.create_connection((address.hostname or "127.0.0.1", address.port or 9876),
                                          timeout=_VIEWER_PROBE_S):
                reachable = True
        except OSError:
            reachable = False
        if reachable != self._reachable:
            if reachable:
                log.info("streaming the recordings to the viewer at %s", self._url)
            else:
                log.warning("no viewer takes connections at %s: the next jobs are recorded to files only, "
                            "until one does", self._url)
            self._reachable = reachable
        return self._url if reachable else None


class _Drawing:
    """What a reconstruction looks like in a recording (in the recorder process)."""

    def __init__(self, n_points: int) -> None:
        self.n_points = n_points

    def reconstruction(self, recording, reply_json: str, payload: bytes) -> None:
        import numpy as np

        from robocell.core_cy.sphere import fibonacci_sphere
        from robocell.core_cy.superquadric import Superquadric
        from robocell.wire.messages import ReconstructReply

        answer = ReconstructReply.model_validate_json(reply_json)
        result = answer.result
        if result is None or answer.points is None:
            return
        ends = np.cumsum([0] + [blob.length for blob in answer.silhouettes])  # the PNGs, then the points
        points = np.frombuffer(payload, "<f4", count=answer.points.length // 4, offset=int(ends[-1])).reshape(-1, 3)
        sphere = np.asarray(result.centre) + result.radius * fibonacci_sphere(self.n_points)
        recording.log_points("sphere", sphere, colour=(150, 150, 150))
        recording.log_points("carved", points.astype(np.float64))
        if result.parts:  # each part in its colour, and the union's outline over each image
            recording.log_parts("fit", [Superquadric.from_dict(part.model_dump()) for part in result.parts])
        else:  # an older worker's one superquadric
            recording.log_superquadric("fit", Superquadric.from_dict(result.superquadric.model_dump()))
        timings = ", ".join(f"{stage} {ms:.1f} ms" for stage, ms in result.timings_ms.items())
        recording.log_text(f"reconstruction on {answer.worker}: {timings}")
        for view, (start, end) in enumerate(zip(ends[:-1], ends[1:])):
            try:
                recording.log_silhouette(view, payload[start:end])
            except ValueError as exc:  # not a PNG of its view's size: the rest is drawn still
                recording.log_text(f"the worker's silhouette of view {view} is not drawn: {exc}", "WARNING")
