"""One Rerun recording per scan job: images, poses, silhouettes, points, meshes, log.

Each job is written as it happens to ``<run dir>/<job id>.rrd``, on the
timeline ``"job"`` (seconds since the job started). World frame: the robot
base, z up, metres. Entities::

    world                            ViewCoordinates RIGHT_HAND_Z_UP, AnnotationContext (static)
    world/robot/flange               Transform3D, TransformAxes3D
    world/camera{i}                  Transform3D (camera-to-world), Pinhole (RDF)
    world/camera{i}/image            EncodedImage (image/jpeg)
    world/camera{i}/silhouette       SegmentationImage (0 background, 1 object)
    world/points/{name}              Points3D ("sphere", "carved")
    world/{name}                     Mesh3D ("fit", "truth")
    world/grasps/{i|chosen}          Transform3D, Boxes3D (the grippers of the planned grasps)
    log                              TextLog
"""

from __future__ import annotations

import logging
import os
import shutil
import sys
import threading
import warnings
from pathlib import Path

import numpy as np
import rerun as rr
from rerun.chunk import RrdReader
from rerun.error_utils import RerunWarning

from robocell.core_cy.meshes import vertex_normals
from robocell.wire import keys
from robocell.core_cy.superquadric import Superquadric, mesh

__all__ = ["JobRecording", "find_recording", "recording_summary", "replay_command", "shared_parts"]

_log = logging.getLogger(__name__)

TIMELINE = "job"
_OBJECT_CLASSES = rr.AnnotationContext([(0, "background", (0, 0, 0, 0)), (1, "object", (255, 64, 0, 110))])
_FLANGE_AXIS_LENGTH = 0.1  # metres
# Rerun's level names; "WARNING" is Python's spelling of its "WARN".
_LEVELS = {"WARNING": "WARN", "FATAL": "CRITICAL"}


def _transform(T) -> rr.Transform3D:
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"a pose must be a 4x4 matrix, got shape {T.shape}")
    return rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3], relation=rr.TransformRelation.ParentFromChild)


class JobRecording:
    """One job's Rerun recording, written to a file as it happens.

    Every method may be called from any thread. Rerun's ``set_time`` is
    thread-local, so the job time set with :meth:`set_time` is stored here and
    re-applied by each log call in the calling thread; a lock makes the pair
    atomic against :meth:`close`. Logging after :meth:`close` is dropped (a
    closed Rerun stream would otherwise buffer it in memory for ever).

    Parameters
    ----------
    path : Path
        The ``.rrd`` file; its directory is created if missing.
    job_id : str
        Becomes the recording id and, as ``"job <id>"``, its name.
    application_id : str
        Rerun's application id; recordings with the same one share a viewer blueprint.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     with JobRecording(Path(tmp) / "j1.rrd", "j1") as rec:
    ...         rec.set_time(0.25)
    ...         rec.log_text("moving")
    ...     recording_summary(Path(tmp) / "j1.rrd")["/log"]
    ['TextLog']
    """

    def __init__(self, path: Path, job_id: str, *, application_id: str = keys.RECORDING_APPLICATION_ID) -> None:
        self.path = Path(path)
        self.job_id = job_id
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._time = 0.0
        self._closed = False
        # Not the global recording: several jobs are recorded at once in one process.
        self._rec = rr.RecordingStream(application_id, recording_id=job_id)
        self._rec.save(self.path)
        self._rec.send_recording_name(f"job {job_id}")
        self._rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        # On "world", the annotation context applies to every silhouette below it.
        self._rec.log("world", _OBJECT_CLASSES, static=True)

    def __enter__(self) -> JobRecording:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc is not None:
            self.log_text(f"recording closed by {exc_type.__name__}: {exc}", "ERROR")
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    def set_time(self, seconds_since_job_start: float) -> None:
        """Set the job time (seconds) of everything logged from now on, from any thread."""
        self._time = float(seconds_since_job_start)

    def _log(self, entity: str, *archetypes) -> None:
        with self._lock:
            if self._closed:
                _log.debug("job %s: %s logged after close, dropped", self.job_id, entity)
                return
            self._rec.set_time(TIMELINE, duration=self._time)
            for archetype in archetypes:
                self._rec.log(entity, archetype)

    def log_text(self, message: str, level: str = "INFO") -> None:
        """A line of the job's log; ``level`` is DEBUG, INFO, WARN(ING), ERROR or CRITICAL."""
        level = level.upper()
        self._log("log", rr.TextLog(message, level=_LEVELS.get(level, level)))

    def log_robot_pose(self, T_base_flange) -> None:
        """The flange pose, (4, 4) flange-to-base, drawn as axes."""
        self._log("world/robot/flange", _transform(T_base_flange), rr.TransformAxes3D(_FLANGE_AXIS_LENGTH))

    def log_view(self, index: int, jpeg: bytes, K, T_world_cam, resolution: tuple[int, int]) -> None:
        """A photograph with its camera: ``K`` (3, 3), ``T_world_cam`` (4, 4) camera-to-world
        in OpenCV axes, ``resolution`` (width, height) in pixels."""
        camera = f"world/camera{index}"
        pinhole = rr.Pinhole(image_from_camera=np.asarray(K, dtype=np.float64), resolution=list(resolution),
                             camera_xyz=rr.ViewCoordinates.RDF)
        self._log(camera, _transform(T_world_cam), pinhole)
        self._log(f"{camera}/image", rr.EncodedImage(contents=bytes(jpeg), media_type="image/jpeg"))

    def log_silhouette(self, index: int, mask: np.ndarray) -> None:
        """View ``index``'s silhouette, (H, W), nonzero = object; drawn over its image."""
        mask = np.asarray(mask)
        if mask.ndim != 2:
            raise ValueError(f"a silhouette must be a 2-D mask, got shape {mask.shape}")
        self._log(f"world/camera{index}/silhouette", rr.SegmentationImage((mask != 0).astype(np.uint8)))

    def log_points(self, name: str, points: np.ndarray, colour=(0, 160, 255)) -> None:
        """A point cloud, (N, 3) world, e.g. ``"sphere"`` before carving and ``"carved"`` after."""
        points = np.asarray(points, dtype=np.float32)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must have shape (N, 3), got {points.shape}")
        self._log(f"world/points/{name}", rr.Points3D(points, colors=colour))

    def log_superquadric(self, name: str, sq: Superquadric, colour=(60, 200, 90, 200)) -> None:
        """A superquadric as a mesh, e.g. the fit as ``"fit"``."""
        self.log_mesh(name, *mesh(sq), colour=colour)

    def log_mesh(self, name: str, vertices, triangles, colour=(200, 200, 200, 120)) -> None:
        """A triangle mesh, vertices (V, 3) world and triangles (F, 3), e.g. ``"truth"`` in simulation."""
        vertices = np.asarray(vertices, dtype=np.float64)
        triangles = np.asarray(triangles, dtype=np.int64)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or triangles.ndim != 2 or triangles.shape[1] != 3:
            raise ValueError(f"need vertices (V, 3) and triangles (F, 3), got {vertices.shape} "
                             f"and {triangles.shape}")
        self._log(f"world/{name}", rr.Mesh3D(vertex_positions=vertices, triangle_indices=triangles,
                                              vertex_normals=vertex_normals(vertices, triangles),
                                              albedo_factor=colour))

    def log_grasps(self, grasps, widths, chosen: int | None, gripper: dict) -> None:
        """Grasps as grippers (two fingers and the palm, as boxes), each closed to the width its
        grasp expects: ``grasps`` (G, 4, 4) grasp-to-world, ``chosen`` highlighted."""
        finger_half = [gripper["finger_width"] / 2, gripper["finger_thickness"] / 2, gripper["finger_length"] / 2]
        palm_half = [gripper["palm_width"] / 2, 0.0, 0.003]
        tip = gripper["pad_length"] / 2
        for index, (T, width) in enumerate(zip(grasps, widths)):
            T = np.asarray(T, dtype=np.float64)
            gap = width / 2 + gripper["finger_thickness"] / 2
            centres = [[0.0, side * gap, tip - gripper["finger_length"] / 2] for side in (-1.0, 1.0)]
            centres.append([0.0, 0.0, tip - gripper["finger_length"]])
            halves = [finger_half, finger_half, [palm_half[0], gap + finger_half[1], palm_half[2]]]
            colour = (255, 140, 0) if index == chosen else (150, 150, 150)
            entity = f"world/grasps/{'chosen' if index == chosen else index}"
            self._log(entity, _transform(T), rr.Boxes3D(centers=centres, half_sizes=halves, colors=colour))

    def close(self) -> None:
        """Flush and write the file's footer; the file is then complete. Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._rec.flush()
            self._rec.disconnect()


def recording_summary(path) -> dict[str, list[str]]:
    """Entity paths of a recording and the archetypes logged on each.

    Works on a recording still being written (no footer yet): it is then
    read by a whole-file scan, whose warning about that is silenced.

    Returns
    -------
    dict of str to list of str
        e.g. ``{"/world/camera0/image": ["EncodedImage"], ...}``, names sorted.
    """
    found: dict[str, set[str]] = {}
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*no footer", category=RerunWarning)
        for chunk in RrdReader(str(path)).stream():
            names = found.setdefault(chunk.entity_path, set())
            for field in chunk.to_record_batch().schema:
                archetype = (field.metadata or {}).get(b"rerun:archetype")
                if archetype:
                    names.add(archetype.decode().rpartition(".")[2])
    return {entity: sorted(names) for entity, names in sorted(found.items())}


def find_recording(job_id_or_file: str, run_dir: Path) -> Path:
    """The ``.rrd`` file of a job: an existing ``.rrd`` path, or ``<run_dir>/<job id>.rrd``.

    Raises
    ------
    FileNotFoundError
        If none exists; the message lists the paths tried.
    """
    given, run_dir = Path(job_id_or_file).expanduser(), Path(run_dir)
    if given.suffix == ".rrd":
        candidates = [given]
        if not given.is_absolute() and len(given.parts) == 1:
            candidates.append(run_dir / given)
    else:
        candidates = [run_dir / f"{job_id_or_file}.rrd"]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(f"no recording for {job_id_or_file!r}: looked for "
                            + ", ".join(str(c) for c in candidates))


def _rerun_executable() -> str:
    # The viewer binary that came with the installed SDK (so the versions match), run directly: the
    # venv's `rerun` script is a Python wrapper that runs it as a child of its own and, at a Ctrl-C,
    # returns at once, leaving the viewer running behind it. One on PATH may be another version.
    try:
        import rerun_cli

        bundled = Path(rerun_cli.__file__).with_name("rerun")
        if bundled.is_file() and os.access(bundled, os.X_OK):
            return str(bundled)
    except ImportError:
        pass
    beside = shutil.which("rerun", path=str(Path(sys.executable).parent))
    found = beside or shutil.which("rerun")
    if found is None:
        raise FileNotFoundError(f"no 'rerun' executable next to {sys.executable} or on PATH "
                                "(it comes with the rerun-sdk package)")
    return found


def shared_parts(path: Path) -> list[Path]:
    """The other files of the recording at ``path`` (``<job id>.<part>.rrd``, made by other
    processes with the same recording id: the simulator's truth, say), which a viewer shows with it."""
    path = Path(path)
    return sorted(path.parent.glob(f"{path.stem}.*.rrd"))


def replay_command(path: Path, *, web: bool = False, bind: str = "127.0.0.1", web_port: int = 9090,
                   grpc_port: int = 9876) -> list[str]:
    """The argv that opens a recording (with its :func:`shared_parts`) in the native viewer, or serves
    it to a browser.

    The viewer's servers listen on ``bind``, loopback by default (rerun's own default is
    0.0.0.0). With ``web`` the recording is served over gRPC on ``grpc_port`` and the web
    viewer on ``web_port``, and no browser is opened.
    """
    argv = [_rerun_executable(), str(path), *map(str, shared_parts(path)), "--bind", bind]
    if web:
        argv += ["--serve-web", "--port", str(grpc_port), "--web-viewer-port", str(web_port)]
    return argv
