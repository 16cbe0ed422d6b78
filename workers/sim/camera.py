"""The simulated camera: the ``[sim]`` scene rendered from where the camera stands.

:class:`SceneCamera` turns a camera pose into a JPEG of the scene (the
simulated Axis camera's HTTP server serves these); :class:`SimCamera` is a
``Camera`` backend that renders in the camera worker's own process, posed by
the cell's robot, for a simulated cell with no HTTP camera at all.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Awaitable, Callable, Sequence

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocell.wire.errors import CameraError
from robocell.workers.camera.backend import Camera, Snapshot

from .objects import SimObject
from .render import remembered, render
from .scene import surroundings

__all__ = ["SceneCamera", "SimCamera", "scaled_K"]


def scaled_K(K: ArrayLike, image_size: tuple[int, int], size: tuple[int, int]) -> NDArray[np.float64]:
    """K for the same camera at another resolution ``size``; pixel centres on integers.

    Examples
    --------
    >>> scaled_K([[600, 0, 319.5], [0, 600, 239.5], [0, 0, 1]], (640, 480), (320, 240))[:2].tolist()
    [[300.0, 0.0, 159.5], [0.0, 300.0, 119.5]]
    """
    K2 = np.array(K, dtype=np.float64)
    for row, (new, old) in enumerate(zip(size, image_size)):
        s = new / old
        K2[row, :2] *= s
        K2[row, 2] = s * (K2[row, 2] + 0.5) - 0.5  # u' + 0.5 = s (u + 0.5): pixel edges scale, not centres
    return K2


class SceneCamera:
    """Renders ``scene_objects`` on the table as a camera at a pose sees them; thread-safe.

    The table and the lamp are :func:`workers.sim.scene.surroundings` of the objects and
    ``seed`` (printed objects stand on oak under a lamp that casts their shadow); the sensor
    noise comes from ``seed`` and the picture's number, so no two pictures are alike and a
    run repeats exactly. With :attr:`object_present` False (or ``jpeg(..., empty=True)``) it
    photographs the empty workspace: the same table under the same lamp, no object, no shadow.
    """

    def __init__(self, scene_objects: Sequence[SimObject], *, K: ArrayLike, image_size: tuple[int, int],
                 dist: ArrayLike | None = None, seed: int = 0, jpeg_quality: int = 90) -> None:
        self._objects = list(scene_objects)
        self.K = np.asarray(K, dtype=np.float64).reshape(3, 3)
        self.image_size = (int(image_size[0]), int(image_size[1]))
        self._dist = None if dist is None else np.asarray(dist, dtype=np.float64)
        self._seed, self.jpeg_quality = int(seed), int(jpeg_quality)
        table, self._light = surroundings(self._objects, self._seed)
        self._table = remembered(table)
        self._lock = threading.Lock()  # one render at a time bounds memory
        self._count = 0
        #: Whether the object stands on the table; False: pictures of the empty workspace.
        self.object_present = True

    def jpeg(self, T_world_cam: ArrayLike, *, size: tuple[int, int] | None = None,
             quality: int | None = None, empty: bool | None = None) -> bytes:
        """The JPEG the camera takes at ``T_world_cam`` (camera-to-world, OpenCV axes).

        ``empty``: True for the empty workspace, False with the object; None (the default)
        as :attr:`object_present` has it.

        Raises
        ------
        ValueError
            If the pose is not a finite 4x4 matrix.
        """
        T = np.asarray(T_world_cam, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError(f"the camera pose must be a finite 4x4 matrix, got shape {T.shape}")
        size = self.image_size if size is None else size
        K = self.K if size == self.image_size else scaled_K(self.K, self.image_size, size)
        empty = not self.object_present if empty is None else empty
        with self._lock:
            self._count += 1
            bgr, _ = render([] if empty else self._objects, T, K, self._dist, size,
                            rng=np.random.default_rng([self._seed, self._count]), table=self._table,
                            light=self._light)
        ok, encoded = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality or self.jpeg_quality])
        if not ok:
            raise ValueError("JPEG encoding failed")
        return encoded.tobytes()


#: The camera's pose now (camera-to-world), or None while it is unknown.
PoseSource = Callable[[], Awaitable["NDArray[np.float64] | None"]]


class SimCamera(Camera):
    """A ``Camera`` that renders the scene from ``pose_source()``, in a thread."""

    def __init__(self, scene: SceneCamera, pose_source: PoseSource) -> None:
        self._scene = scene
        self._pose_source = pose_source

    @property
    def source(self) -> str:
        return "simulated camera"

    async def snapshot(self) -> Snapshot:
        pose = await self._pose_source()
        if pose is None:
            raise CameraError("the simulated camera does not know where it is: no robot answers", source=self.source)
        data = await asyncio.to_thread(self._scene.jpeg, pose)
        return Snapshot(data, *self._scene.image_size)
