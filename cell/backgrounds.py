"""The backgrounds a cell keeps: pictures of the empty workspace, one per camera pose, for later scans.

A job of ``kind: backgrounds`` (``ScanRequest.kind``, ``robocell background``) moves to a
scan's poses before the object is put there, and its last step
(:class:`cell.steps.KeepBackgrounds`) keeps each picture here, with the camera's pose and
calibration. A later scan asks :meth:`Backgrounds.find` for each of its views: the newest
background taken from a camera pose within :data:`~wire.messages.BACKGROUND_POSE_TOLERANCE`
of the view's, by the same camera (its K, distortion and picture size), goes with the view
to the reconstruction as its ``background`` (DESIGN.md §1.10, §3).

On disk, in ``<run dir>/backgrounds/``: ``<job id>-<view>.jpg`` as the camera gave it, and
``<job id>-<view>.json`` beside it (:class:`Background`), written last, so that a background
whose description is there is whole. Keeping one replaces those kept from the same pose: one
background per pose. Retention (``cell/retention.py``) deletes them by age and total size.

Plain files and arrays, no clock: the daemon calls these in a thread.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocell.core_cy.images import checked_size
from robocell.wire.messages import BACKGROUND_POSE_TOLERANCE

__all__ = ["Background", "Backgrounds", "pose_distance"]

#: The directory of the run directory that holds them.
DIRECTORY = "backgrounds"


def pose_distance(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(metres between the origins, degrees of the rotation between) two 4x4 rigid poses.

    >>> turned = np.eye(4); turned[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]; turned[0, 3] = 0.003
    >>> [round(v, 6) for v in pose_distance(np.eye(4), turned)]
    [0.003, 90.0]
    """
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    cos = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1) / 2
    return float(np.linalg.norm(a[:3, 3] - b[:3, 3])), float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


@dataclass(frozen=True)
class Background:
    """One kept background: its picture's file, where the camera stood (``T_base_cam``), which
    camera (``K``, ``dist``, ``size`` as width, height), the job that took it and when (unix time)."""

    path: Path
    T_base_cam: np.ndarray
    K: np.ndarray
    dist: tuple[float, ...]
    size: tuple[int, int]
    job_id: str
    time: float

    @property
    def description(self) -> Path:
        return self.path.with_suffix(".json")

    def same_camera(self, K: Sequence[Sequence[float]], dist: Sequence[float] | None, size: tuple[int, int]) -> bool:
        """Whether a camera of calibration ``K``, ``dist`` taking pictures of ``size`` took it."""
        return (self.size == tuple(size) and np.allclose(self.K, np.asarray(K, dtype=np.float64), atol=1e-9)
                and np.allclose(self.dist, _dist(dist), atol=1e-12))

    def near(self, T_base_cam: np.ndarray) -> bool:
        """Whether a camera at ``T_base_cam`` stands where it was taken (:data:`BACKGROUND_POSE_TOLERANCE`)."""
        metres, degrees = pose_distance(self.T_base_cam, T_base_cam)
        return metres <= BACKGROUND_POSE_TOLERANCE[0] and degrees <= BACKGROUND_POSE_TOLERANCE[1]


def _dist(dist: Sequence[float] | None) -> tuple[float, ...]:
    """Distortion coefficients as five or more numbers (none: zeros), for comparing."""
    values = [float(v) for v in (dist or [])]
    return tuple(values + [0.0] * (5 - len(values)))


class Backgrounds:
    """The backgrounds kept in ``run_dir``'s :data:`DIRECTORY`."""

    def __init__(self, run_dir: Path) -> None:
        self.root = Path(run_dir) / DIRECTORY

    def keep(self, job_id: str, view: int, jpeg: bytes, T_base_cam: np.ndarray, *, K: Sequence[Sequence[float]],
             dist: Sequence[float] | None, now: float) -> Background:
        """Keep the picture of ``job_id``'s ``view``, taken by a camera at ``T_base_cam``; those kept
        before from the same pose, by the same camera, are deleted.

        Raises
        ------
        OSError
            If it cannot be written.
        core_cy.errors.ImageError
            If ``jpeg`` is no picture.
        """
        size = checked_size(jpeg, what="the background", view=view)
        self.root.mkdir(parents=True, exist_ok=True)
        kept = Background(self.root / f"{job_id}-{view}.jpg", np.asarray(T_base_cam, dtype=np.float64),
                          np.asarray(K, dtype=np.float64), _dist(dist), size, job_id, now)
        _write(kept.path, jpeg)
        _write(kept.description, json.dumps({
            "T_base_cam": kept.T_base_cam.tolist(), "K": kept.K.tolist(), "dist": list(kept.dist),
            "size": list(size), "job_id": job_id, "time": now}).encode())
        for other in self.all():
            if other.path != kept.path and other.near(kept.T_base_cam) and other.same_camera(K, dist, size):
                remove(other)
        return kept

    def find(self, T_base_cam: np.ndarray, *, K: Sequence[Sequence[float]], dist: Sequence[float] | None,
             size: tuple[int, int]) -> Background | None:
        """The newest background a camera of ``K``, ``dist`` and picture ``size`` took at
        ``T_base_cam`` (within :data:`BACKGROUND_POSE_TOLERANCE`), or None."""
        found = [b for b in self.all() if b.same_camera(K, dist, size) and b.near(T_base_cam)]
        return max(found, key=lambda b: (b.time, b.path.name), default=None)

    def all(self) -> list[Background]:
        """Every whole background kept (one whose description cannot be read is skipped)."""
        kept = []
        with contextlib.suppress(FileNotFoundError):
            for item in os.scandir(self.root):
                if not item.name.endswith(".json") or not item.is_file(follow_symlinks=False):
                    continue
                path = Path(item.path).with_suffix(".jpg")
                try:
                    data = json.loads(Path(item.path).read_bytes())
                    background = Background(path, np.asarray(data["T_base_cam"], dtype=np.float64).reshape(4, 4),
                                            np.asarray(data["K"], dtype=np.float64).reshape(3, 3),
                                            _dist(data["dist"]), (int(data["size"][0]), int(data["size"][1])),
                                            str(data["job_id"]), float(data["time"]))
                except (OSError, ValueError, KeyError, TypeError, IndexError):
                    continue
                if path.is_file():
                    kept.append(background)
        return kept


def remove(background: Background) -> None:
    """Delete a background: its description first (without it, the picture is no background)."""
    for path in (background.description, background.path):
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


def _write(path: Path, data: bytes) -> None:
    """Write ``path`` whole or not at all (a temporary file renamed)."""
    temporary = path.with_name(f".{path.name}.tmp")
    with open(temporary, "wb") as file:
        file.write(data)
        file.flush()
        os.fsync(file.fileno())
    os.replace(temporary, path)
