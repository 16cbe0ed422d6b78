"""``robocell sim camera``: the simulated Axis camera, posed by the cell's robot.

For each snapshot it asks the robot worker where the flange is (a Zenoh
query, so the picture is taken exactly where the robot stands) and renders
the configured scene from ``T_base_flange @ T_flange_cam``.
"""

from __future__ import annotations

import logging
import signal
import threading
from urllib.parse import urlsplit

import numpy as np
import zenoh

from robocell.wire import keys
from robocell.wire.config import CellConfig
from robocell.wire.errors import ConfigError, TransportError
from robocell.wire.messages import RobotState
from robocell.wire.transport import session_config

from .scene import scene_from_config

from .axis import SimCameraServer
from .truth_log import TruthLog

__all__ = ["main", "robot_camera_pose"]

log = logging.getLogger(__name__)
_STATE_TIMEOUT_S = 2.0


def robot_camera_pose(session: zenoh.Session, config: CellConfig) -> np.ndarray | None:
    """The camera's pose now, from the robot worker's state; None if no robot answers."""
    for reply in session.get(keys.robot_state(config.cell_id), timeout=_STATE_TIMEOUT_S):
        if reply.ok is not None:
            state = RobotState.model_validate_json(reply.ok.payload.to_bytes())
            return np.asarray(state.T_base_flange) @ config.hand_eye
    return None


def main(config: CellConfig) -> int:
    """Serve until SIGINT/SIGTERM.

    Raises
    ------
    CellError
        If the router cannot be reached, the camera's address cannot be served, or a user
        has no password (each named).
    """
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    camera = config.camera
    username, password = camera.credentials()
    address = urlsplit(camera.url)  # the simulated camera serves where the camera worker looks
    host, port = address.hostname or "127.0.0.1", address.port or 80
    try:
        session = zenoh.open(session_config(config.zenoh.router, settings=config.zenoh.client_settings(),
                                            connect_timeout_ms=10_000))
    except zenoh.ZError as exc:
        raise TransportError(f"cannot reach the Zenoh router at {config.zenoh.router}: {exc}") from None
    try:
        scene = scene_from_config(config.sim)
        truth = TruthLog(config.run_dir, scene)  # into each job's recording, as the simulator knows it
        session.declare_subscriber(keys.events(config.cell_id), lambda sample: truth.heard(sample.payload.to_bytes()))
        server = SimCameraServer(
            scene, K=np.asarray(camera.K), image_size=tuple(camera.resolution),
            dist=camera.dist, pose_provider=lambda: robot_camera_pose(session, config), host=host, port=port,
            username=username, password=password, auth=camera.auth if username else None, seed=config.sim.seed)
        try:
            server.start()
        except OSError as exc:
            raise ConfigError(f"the simulated camera cannot serve camera.url at {host}:{port}: "
                              f"{exc.strerror or exc}") from None
        try:
            log.info("simulated camera serving %s", server.url)
            stop.wait()
        finally:
            server.stop()
    finally:
        session.close()
    return 0
