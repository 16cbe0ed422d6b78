"""A job's pictures on disk, so that a daemon that stops after taking them need not take them again.

``<run dir>/pictures/<job id>/view<i>.jpg``, and beside each ``view<i>.json``
with where the robot and the camera stood. Written in the store's thread as each is
taken, read back by a restarted daemon, removed
when the job ends (the job's recording keeps them).
"""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import numpy as np

from .job import Picture

__all__ = ["Pictures"]

log = logging.getLogger(__name__)


class Pictures:
    """The pictures of the jobs of one run directory."""

    def __init__(self, run_dir: Path) -> None:
        self.root = Path(run_dir) / "pictures"

    def add(self, job_id: str, view: int, picture: Picture) -> None:
        """Keep the job's picture of ``view`` (replacing one kept before); its pose is written
        last, so a picture whose pose is there is whole."""
        directory = self.root / job_id
        directory.mkdir(parents=True, exist_ok=True)
        (directory / f"view{view}.jpg").write_bytes(picture.jpeg)
        where = {"T_base_flange": picture.T_base_flange.tolist(), "T_base_cam": picture.T_base_cam.tolist()}
        (directory / f"view{view}.json").write_text(json.dumps(where))

    def load(self, job_id: str, n_views: int) -> list[Picture] | None:
        """The job's ``n_views`` pictures, or None unless every one of them is there whole."""
        directory = self.root / job_id
        try:
            pictures = []
            for view in range(n_views):
                where = json.loads((directory / f"view{view}.json").read_text())
                pictures.append(Picture((directory / f"view{view}.jpg").read_bytes(),
                                        np.asarray(where["T_base_flange"], dtype=np.float64),
                                        np.asarray(where["T_base_cam"], dtype=np.float64)))
        except (OSError, ValueError, KeyError) as exc:
            log.warning("job %s: its pictures cannot be read back (%s): its views are taken again", job_id, exc)
            return None
        return pictures

    def drop(self, job_id: str) -> None:
        """Forget the job's pictures."""
        shutil.rmtree(self.root / job_id, ignore_errors=True)
