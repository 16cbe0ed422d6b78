"""One Rerun recording per scan job: images, poses, silhouettes, points, meshes, log.

Each job is written as it happens to ``<run dir>/<job id>.rrd``, on the
timeline ``"job"`` (seconds since the job started). World frame: the robot
base, z up, metres. Entities::

    world                            ViewCoordinates RIGHT_HAND_Z_UP (static)
    world/robot/flange               Transform3D, TransformAxes3D
    world/camera{i}                  Transform3D (camera-to-world), Pinhole (RDF)
    world/camera{i}/image            EncodedImage (image/jpeg)
    world/camera{i}/silhouette       EncodedImage (image/png as the worker sent it: white = object)
    world/camera{i}/outline          LineStrips2D (the model's projected outline: the union of its parts)
    world/points/{name}              Points3D ("sphere", "carved")
    world/{name}                     Mesh3D ("fit": each part in its own colour; "truth")
    world/grasps/{i|chosen}          Transform3D, Boxes3D (the grippers of the planned grasps)
    log                              TextLog

A recording is complete when it reads back with its footer: :meth:`JobRecording.close`
says what is wrong with one that does not (a full disk, a file cut short, 0 bytes), and
:func:`recording_problem` checks any file so.

A recording may also stream, as it is written, to a Rerun viewer (``live``: the gRPC URL of a
viewer, ``rerun+http://127.0.0.1:9876/proxy`` for the one ``rerun`` opens by default): a second
stream with the same recording id, whose failures never touch the file.
"""

from __future__ import annotations

import logging
import os
import shutil
import stat
import threading
import warnings
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
import rerun as rr
import rerun_bindings
from rerun.chunk import RrdReader
from rerun.error_utils import RerunWarning

from robocell.core_cy.camera import Camera
from robocell.core_cy.images import checked_size, png_size
from robocell.core_cy.meshes import vertex_normals
from robocell.core_cy.quality import projected_outline
from robocell.wire import keys
from robocell.core_cy.superquadric import Superquadric, mesh

__all__ = ["JobRecording", "recording_problem", "union_outline", "PART_COLOURS"]

_log = logging.getLogger(__name__)

TIMELINE = "job"
_FLANGE_AXIS_LENGTH = 0.1  # metres
# Rerun's level names; "WARNING" is Python's spelling of its "WARN".
_LEVELS = {"WARNING": "WARN", "FATAL": "CRITICAL"}
#: The colours of a model's parts, in order (RGBA): told apart at a glance.
PART_COLOURS = ((60, 200, 90, 200), (70, 130, 250, 200), (240, 200, 40, 200), (200, 80, 220, 200),
                (40, 210, 220, 200), (250, 110, 110, 200))
_OUTLINE_COLOUR = (255, 255, 0)
_SILHOUETTE_OPACITY = 0.4  # the picture stays readable under the silhouette
# A write of a recording waits at most this long (a disk that hangs must not hold the recorder; once
# Rerun's file writer has stopped, a flush waits this long before it says so). The recorder writes as
# it goes, so a close has little left to write.
_FLUSH_TIMEOUT_S = 5.0
_DISCONNECT_WAIT_S = 5.0  # a live viewer that went away takes Rerun up to 5 s


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
    live : str, optional
        A Rerun viewer's gRPC URL to stream the recording to as well, as it is written.

    Examples
    --------
    >>> import tempfile
    >>> from robocell.cell.recording_files import recording_summary
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     with JobRecording(Path(tmp) / "j1.rrd", "j1") as rec:
    ...         rec.set_time(0.25)
    ...         rec.log_text("moving")
    ...     recording_summary(Path(tmp) / "j1.rrd")["/log"]
    ['TextLog']
    """

    def __init__(self, path: Path, job_id: str, *, application_id: str = keys.RECORDING_APPLICATION_ID,
                 live: str | None = None) -> None:
        self.path = Path(path)
        self.job_id = job_id
        self.live = live
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._time = 0.0
        self._closed = False
        self._problem: str | None = None
        self._sweep = False  # ended, the stream awaits Rerun's sweep (release)
        self._write_failure: str | None = None  # why a flush failed, if one did
        self._cameras: dict[int, tuple[np.ndarray, np.ndarray, tuple[int, int]]] = {}  # K, T_world_cam, (w, h)
        self._silhouettes: set[int] = set()  # the views whose silhouettes were drawn
        # Not the global recording: several jobs are recorded at once in one process.
        self._rec = rr.RecordingStream(application_id, recording_id=job_id)
        self._rec.save(self.path)
        self._streams = [self._rec]
        self._live: rr.RecordingStream | None = None
        if live is not None:
            # A stream of its own: a viewer that is gone must not fail, nor slow, the file's.
            self._live = rr.RecordingStream(application_id, recording_id=job_id)
            self._live.connect_grpc(live)
            self._streams.append(self._live)
        for stream in self._streams:
            stream.send_recording_name(f"job {job_id}")
            stream.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

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
            for stream in self._streams:
                stream.set_time(TIMELINE, duration=self._time)
                for archetype in archetypes:
                    stream.log(entity, archetype)

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
        self._cameras[index] = (np.asarray(K, dtype=np.float64), np.asarray(T_world_cam, dtype=np.float64),
                                (int(resolution[0]), int(resolution[1])))
        pinhole = rr.Pinhole(image_from_camera=np.asarray(K, dtype=np.float64), resolution=list(resolution),
                             camera_xyz=rr.ViewCoordinates.RDF)
        self._log(camera, _transform(T_world_cam), pinhole)
        self._log(f"{camera}/image", rr.EncodedImage(contents=bytes(jpeg), media_type="image/jpeg"))

    def log_silhouette(self, index: int, png: bytes) -> None:
        """View ``index``'s silhouette as a worker sends it: a PNG of the view's size, white where
        the object is; drawn over its image, partly transparent. It is logged as it came, never
        decoded here (the viewer decodes it): decoding a scan's silhouettes was about half of the
        drawing of its model, which a success waits for. Only its header is read: a PNG that
        declares another size than the view's image, or more pixels than may be decoded, is
        refused (``ValueError``)."""
        png = bytes(png)
        size = png_size(png)
        if size is None:
            raise ValueError(f"view {index}'s silhouette is not a PNG ({len(png)} bytes)")
        checked_size(png, what="the silhouette", view=index)
        if index in self._cameras and size != self._cameras[index][2]:
            width, height = self._cameras[index][2]
            raise ValueError(f"view {index}'s silhouette is {size[0]}x{size[1]} pixels, its image {width}x{height}")
        self._log(f"world/camera{index}/silhouette", rr.EncodedImage(contents=png, media_type="image/png",
                                                                     opacity=_SILHOUETTE_OPACITY))
        self._silhouettes.add(index)

    def clear_reconstruction(self) -> None:
        """Take the reconstruction drawn last out of the recording from now on (an answer the daemon
        refused): its points, its model, and each view's silhouette and outline."""
        views = sorted(self._silhouettes | set(self._cameras))
        for entity in ["world/points", "world/fit", *(f"world/camera{index}/{layer}" for index in views
                                                     for layer in ("silhouette", "outline"))]:
            self._log(entity, rr.Clear(recursive=True))

    def log_points(self, name: str, points: np.ndarray, colour=(0, 160, 255)) -> None:
        """A point cloud, (N, 3) world, e.g. ``"sphere"`` before carving and ``"carved"`` after."""
        points = np.asarray(points, dtype=np.float32)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must have shape (N, 3), got {points.shape}")
        self._log(f"world/points/{name}", rr.Points3D(points, colors=colour))

    def log_superquadric(self, name: str, sq: Superquadric, colour=(60, 200, 90, 200)) -> None:
        """A superquadric as a mesh, e.g. the fit as ``"fit"``."""
        self.log_mesh(name, *mesh(sq), colour=colour)

    def log_parts(self, name: str, parts: Sequence[Superquadric]) -> None:
        """A model made of parts (their union is the object) as one mesh, each part in its own colour
        (:data:`PART_COLOURS`), and its projected outline over every view's image logged so far."""
        if not parts:
            raise ValueError("a model has at least one part")
        vertices, triangles, colours = [], [], []
        offset = 0
        for index, part in enumerate(parts):
            part_vertices, part_triangles = mesh(part)
            vertices.append(part_vertices)
            triangles.append(np.asarray(part_triangles, dtype=np.int64) + offset)
            colours.append(np.tile(PART_COLOURS[index % len(PART_COLOURS)], (len(part_vertices), 1)))
            offset += len(part_vertices)
        all_vertices, all_triangles = np.concatenate(vertices), np.concatenate(triangles)
        self._log(f"world/{name}", rr.Mesh3D(vertex_positions=all_vertices, triangle_indices=all_triangles,
                                              vertex_normals=vertex_normals(all_vertices, all_triangles),
                                              vertex_colors=np.concatenate(colours).astype(np.uint8)))
        for index, (K, T_world_cam, (width, height)) in sorted(self._cameras.items()):
            strips = union_outline(parts, K, T_world_cam, (width, height), vertices)  # one sampling of each part
            if strips:
                self._log(f"world/camera{index}/outline", rr.LineStrips2D(strips, colors=_OUTLINE_COLOUR))

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

    def flush(self) -> None:
        """Write what was logged so far to the file (its close then has only the rest to write). A
        write that fails is left to :meth:`close` to report; the file is not flushed again before it."""
        with self._lock:
            if self._closed or self._write_failure is not None:
                return
            try:
                self._rec.flush(timeout_sec=_FLUSH_TIMEOUT_S)
            except Exception as exc:  # Rerun's file writer stopped: a full disk, say
                self._write_failure = str(exc) or type(exc).__name__
                _log.warning("job %s: the recording could not be written: %s", self.job_id, exc)

    def close(self) -> str | None:
        """Flush and write the file's footer (:meth:`end`), then free the stream (:meth:`release`).
        Idempotent. None when the file is complete (it reads back with its footer); else what is
        wrong with it, as :func:`recording_problem` says (a failed write comes first)."""
        problem = self.end()
        self.release()
        return problem

    def end(self) -> str | None:
        """:meth:`close`'s verdict, the stream not yet freed: the sweep that frees it says nothing of the file."""
        with self._lock:
            if self._closed:
                return self._problem
            self._closed = True
            failure = self._write_failure
            try:
                if failure is None:  # after a failed write a flush only waits for its timeout
                    self._rec.flush(timeout_sec=_FLUSH_TIMEOUT_S)
            except Exception as exc:  # Rerun's file writer stopped: a full disk, say
                failure = str(exc) or type(exc).__name__
            finally:
                # Disconnected whatever happened (a stream left connected keeps what it was given),
                # in a thread of its own: after a write failed midway, Rerun 0.41's disconnect never
                # returns; the thread is then left to it.
                ended = True
                for stream in self._streams:
                    ending = threading.Thread(target=stream.disconnect, name=f"rerun-disconnect-{self.job_id}",
                                              daemon=True)
                    ending.start()
                    ending.join(_DISCONNECT_WAIT_S)
                    if ending.is_alive():
                        ended = False
                        _log.warning("job %s: Rerun did not close a stream of the recording in %g s: left to it",
                                     self.job_id, _DISCONNECT_WAIT_S)
                self._streams.clear()
                del self._rec
                # Not after a failed write: the sweep then waits on the writer that never ends.
                self._sweep = ended and failure is None
            self._problem = recording_problem(self.path, write_failure=failure)
            return self._problem

    def release(self) -> None:
        """After :meth:`end`: Rerun's SDK keeps every stream, and its two threads, until the last reference is
        gone and orphans are swept (rerun-io/rerun#2116): else two threads more for every job."""
        with self._lock:
            sweep, self._sweep = self._sweep, False
        if sweep:
            rerun_bindings.flush_and_cleanup_orphaned_recordings()


def recording_problem(path, *, write_failure: str | None = None) -> str | None:
    """What is wrong with the recording at ``path``, or None when it is complete (it reads back
    with its footer).

    ``write_failure``: the error its writer met, if any; it is named first, with the free space
    of the disk the file is on.

    Examples
    --------
    >>> import tempfile
    >>> from robocell.cell.recording_files import recording_summary
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     (Path(tmp) / "j1.rrd").write_bytes(b"")
    ...     recording_problem(Path(tmp) / "j1.rrd").endswith("is empty (0 bytes)")
    0
    True
    """
    path = Path(path)
    try:
        status = os.stat(path)
    except OSError as exc:
        return f"the recording {path} is missing ({exc.strerror or exc})"
    if write_failure is not None:
        try:
            free = f"; {shutil.disk_usage(path.parent).free / 1e6:.1f} MB free on its disk"
        except OSError:
            free = ""
        return (f"the recording {path} could not be written ({write_failure}): it is incomplete "
                f"({status.st_size} bytes{free})")
    if not stat.S_ISREG(status.st_mode):
        return f"the recording {path} is not a regular file"
    if status.st_size == 0:
        return f"the recording {path} is empty (0 bytes)"
    with warnings.catch_warnings():
        # The reader warns of a file with no footer, and reads it by a scan: here that is the fault.
        warnings.simplefilter("error", RerunWarning)
        try:
            RrdReader(str(path))
        except RerunWarning:
            return f"the recording {path} is cut short ({status.st_size} bytes, no footer)"
        except (RuntimeError, OSError, ValueError) as exc:
            return f"the recording {path} cannot be read ({status.st_size} bytes): {exc}"
    return None


def union_outline(parts: Sequence[Superquadric], K, T_world_cam, resolution: tuple[int, int],
                  surfaces: Sequence[np.ndarray] | None = None) -> list[np.ndarray]:
    """The outline of a union of parts projected into a view: closed pixel polylines (each (M, 2), float32), the
    outer contours of the union of each part's convex projection, within the image. ``surfaces``: each part's
    surface points, if already taken (the vertices of its mesh)."""
    width, height = resolution
    camera = Camera(K=K, T_world_cam=T_world_cam)
    cover = np.zeros((height, width), np.uint8)
    for index, part in enumerate(parts):
        uv = projected_outline(part, camera, None if surfaces is None else surfaces[index])
        if len(uv) < 3 or not np.all(np.isfinite(uv)):
            continue
        uv = np.clip(uv, -4.0 * max(width, height), 4.0 * max(width, height))  # far off-image stays drawable
        hull = cv2.convexHull(np.round(uv).astype(np.int32))
        cv2.fillConvexPoly(cover, hull, 1)
    contours, _ = cv2.findContours(cover, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    strips = []
    for contour in contours:
        points = contour.reshape(-1, 2).astype(np.float32)
        if len(points) >= 2:
            strips.append(np.vstack([points, points[:1]]))  # closed
    return strips
