"""Bounded disk (``cell/retention.py``): a real run directory and a real job store, times set by hand."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from robocell.cell.retention import GRACE_S, apply_retention, disk_usage
from robocell.cell.store import JobStore
from robocell.wire.config import RetentionConfig, load_config
from robocell.wire.messages import JobEvent, JobState, ScanRequest

DAY = 86400.0
NOW = 1_800_000_000.0
MB = 1024 * 1024


class RunDir:
    """A run directory: a store with jobs, and their recordings and pictures, written at given times."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.store = JobStore(root / "jobs.sqlite")

    def job(self, *, age_days: float, state: JobState = JobState.SUCCEEDED, recording_mb: float = 0.0,
            pictures: bool = False) -> str:
        when = NOW - age_days * DAY
        status, _ = self.store.add(ScanRequest(target=[0.6, 0.0, 0.05]), n_views=3, now=when)
        if state is not JobState.QUEUED:
            self.store.change(JobEvent(job_id=status.job_id, state=JobState.MOVING, message="moving", time=when))
            if state is not JobState.MOVING:
                self.store.change(JobEvent(job_id=status.job_id, state=state, time=when,
                                           message="x" if state is JobState.FAILED else state.value))
        if recording_mb:
            self._write(self.root / f"{status.job_id}.rrd", recording_mb, when)
        if pictures:
            directory = self.root / "pictures" / status.job_id
            directory.mkdir(parents=True)
            self._write(directory / "view0.jpg", 0.1, when)
            os.utime(directory, (when, when))
        return status.job_id

    @staticmethod
    def _write(path: Path, mb: float, when: float) -> None:
        path.write_bytes(b"\0" * int(mb * MB))
        os.utime(path, (when, when))

    def recordings(self) -> set[str]:
        return {p.stem for p in self.root.glob("*.rrd")}

    def pictures(self) -> set[str]:
        return {p.name for p in (self.root / "pictures").iterdir()}


@pytest.fixture
def run_dir(tmp_path):
    made = RunDir(tmp_path)
    try:
        yield made
    finally:
        made.store.close()


def test_the_oldest_recordings_past_the_size_limit_go_first(run_dir):
    jobs = [run_dir.job(age_days=10 - day, recording_mb=1.0) for day in range(6)]   # oldest first
    policy = RetentionConfig(recordings_max_mb=3.5, recordings_max_age_days=365)
    report = apply_retention(run_dir.root, run_dir.store, policy, NOW)
    assert run_dir.recordings() == set(jobs[3:])
    assert (report.recordings_deleted, report.recording_bytes_freed) == (3, 3 * MB)


def test_recordings_past_the_age_limit_go_whatever_their_size(run_dir):
    old = run_dir.job(age_days=40, recording_mb=0.01)
    young = run_dir.job(age_days=20, recording_mb=0.01)
    apply_retention(run_dir.root, run_dir.store, RetentionConfig(recordings_max_age_days=30), NOW)
    assert run_dir.recordings() == {young} and old not in run_dir.recordings()


def test_a_running_jobs_files_are_never_deleted(run_dir):
    """Old and big as they may be: a job that has not ended keeps its recording, pictures and row."""
    running = run_dir.job(age_days=50, state=JobState.MOVING, recording_mb=2.0, pictures=True)
    queued = run_dir.job(age_days=50, state=JobState.QUEUED, recording_mb=2.0)
    ended = run_dir.job(age_days=50, recording_mb=2.0, pictures=True)
    not_stored_yet = "20270115-999999"      # the daemon runs it; the store does not have it yet
    RunDir._write(run_dir.root / f"{not_stored_yet}.rrd", 1.0, NOW - 2 * DAY)
    last = run_dir.job(age_days=0)
    policy = RetentionConfig(recordings_max_mb=0.5, recordings_max_age_days=1, pictures_max_age_days=1,
                             jobs_max_age_days=1)
    report = apply_retention(run_dir.root, run_dir.store, policy, NOW, active=[not_stored_yet])
    assert run_dir.recordings() == {running, queued, not_stored_yet}
    assert run_dir.pictures() == {running}
    assert run_dir.store.get(running).state is JobState.MOVING and run_dir.store.get(queued) is not None
    assert run_dir.store.get(ended) is None and report.jobs_pruned == 1
    assert run_dir.store.get(last) is not None


def test_a_recording_written_just_now_is_kept(run_dir):
    """A job's recording is completed a moment after its end: within the grace it stays."""
    just_ended = run_dir.job(age_days=GRACE_S / 2 / DAY, recording_mb=2.0)
    run_dir.job(age_days=0)
    apply_retention(run_dir.root, run_dir.store, RetentionConfig(recordings_max_mb=1.0), NOW)
    assert run_dir.recordings() == {just_ended}


def test_ended_jobs_leave_the_store_by_age_and_count_and_the_newest_stays(run_dir):
    old = [run_dir.job(age_days=100, state=state) for state in (JobState.SUCCEEDED, JobState.FAILED)]
    recent = [run_dir.job(age_days=5 - k) for k in range(4)]
    report = apply_retention(run_dir.root, run_dir.store, RetentionConfig(jobs_max_age_days=90, jobs_max_count=3),
                             NOW)
    assert [run_dir.store.get(job) is not None for job in old + recent] == [False, False, False, True, True, True]
    assert report.jobs_pruned == 3 and run_dir.store.events(old[0]) == []
    assert run_dir.store.last_seq() == 6       # the next job's number does not go back
    assert not Path(f"{run_dir.store.path}-wal").exists() or Path(f"{run_dir.store.path}-wal").stat().st_size == 0
    # Even past every limit, the newest job of all stays: the next job's number follows it.
    apply_retention(run_dir.root, run_dir.store, RetentionConfig(jobs_max_age_days=1e-9, jobs_max_count=1),
                    NOW + 10 * DAY)
    assert [status.job_id for status in run_dir.store.list()] == [recent[-1]]


def test_disk_usage_says_what_retention_will_free(run_dir):
    run_dir.job(age_days=40, recording_mb=1.0, pictures=True)
    keep = run_dir.job(age_days=1, recording_mb=1.0)
    policy = RetentionConfig(recordings_max_age_days=30, pictures_max_age_days=1)
    usage = disk_usage(run_dir.root, policy, now=NOW)
    assert (usage.recordings, usage.recordings_to_free) == (2 * MB, MB)
    assert usage.pictures == usage.pictures_to_free == int(0.1 * MB) and usage.jobs_to_prune == 0
    assert usage.store > 0 and usage.free_on_disk is not None
    report = apply_retention(run_dir.root, run_dir.store, policy, NOW)
    after = disk_usage(run_dir.root, policy, now=NOW)
    assert report.recording_bytes_freed == usage.recordings_to_free and run_dir.recordings() == {keep}
    assert (after.recordings_to_free, after.pictures_to_free, after.pictures) == (0, 0, 0)


def test_the_retention_section_is_one_part_of_the_cell_configuration(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text("[retention]\nrecordings_max_mb = 500\njobs_max_age_days = 30\n")
    config = load_config(path)
    assert (config.retention.recordings_max_mb, config.retention.jobs_max_age_days) == (500, 30)
    assert config.retention.recordings_max_age_days == RetentionConfig().recordings_max_age_days
    path.write_text("[retention]\nrecordings_max_mb = -1\n")
    with pytest.raises(Exception, match="retention.recordings_max_mb: Input should be greater than 0"):
        load_config(path)
