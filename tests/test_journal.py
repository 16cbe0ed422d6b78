"""The recorder process (cell.recorder): what a job records reaches its file, in order, and a
recorder process makes a bounded number of recordings."""

from __future__ import annotations

import multiprocessing
from pathlib import Path

from rerun.chunk import RrdReader

from robocell.cell.recorder import Recorder
from tests.cell_fixtures import wait_until


def _texts(path: Path) -> list[tuple[float, str]]:
    """The job's log lines: (job time, text), in time order."""
    rows = []
    for chunk in RrdReader(str(path)).stream():
        if chunk.entity_path == "/log":
            batch = chunk.to_record_batch()
            rows += [(t.total_seconds(), text) for t, [text] in zip(batch.column("job").to_pylist(),
                                                                   batch.column("TextLog:text").to_pylist())]
    return sorted(rows)


def test_a_new_recorder_process_takes_over_and_the_old_one_ends_with_its_last_recording(tmp_path):
    """Rerun never frees a recording's threads: a recorder process makes a bounded number of
    recordings. One open across the change stays whole in the old process."""
    paths = {job: tmp_path / f"{job}.rrd" for job in ("j1", "j2", "j3", "j4", "j5")}
    recorder = Recorder(n_points=100, recordings_per_process=2)
    recorder.start()
    try:
        for job in ("j1", "j2", "j3"):  # j3 is the first of a second process; j1 and j2 stay in the first
            recorder.open(job, paths[job])
            recorder.call(job, 0.5, "log_text", f"{job} opened", "INFO")
        wait_until(lambda: len(multiprocessing.active_children()) == 2, timeout=30, interval=0.05,
                   what="a second recorder process for the third recording")
        for job in ("j1", "j2"):
            recorder.call(job, 1.5, "log_text", f"{job} after the change", "INFO")
            recorder.close(job)
        wait_until(lambda: len(multiprocessing.active_children()) == 1, timeout=30, interval=0.05,
                   what="the first recorder process to end once its recordings were closed")
        for job in ("j4", "j5"):  # j5 is the first of a third process
            recorder.open(job, paths[job])
            recorder.call(job, 0.5, "log_text", f"{job} opened", "INFO")
        # Their verdicts are awaited before stop(), which gives a process still importing Rerun
        # only seconds: the rotation is tested here, not how long a busy machine takes to start one.
        verdicts = [recorder.finish(job) for job in ("j3", "j4", "j5")]
        assert [verdict.result(timeout=120) for verdict in verdicts] == [None, None, None]
    finally:
        recorder.stop()
    assert multiprocessing.active_children() == []
    for job in ("j1", "j2"):
        assert _texts(paths[job]) == [(0.5, f"{job} opened"), (1.5, f"{job} after the change")]
    for job in ("j3", "j4", "j5"):
        assert _texts(paths[job]) == [(0.5, f"{job} opened")]
