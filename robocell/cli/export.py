"""``robocell export JOB_OR_BUNDLE --format ...``: the model out of robocell, for MoveIt, simulators and ROS.

What is exported is a :class:`Model`: the object's parts (superquadrics; one for an object that
is one), its grasps, and, where known, the views (pictures, cameras, flange poses) and the carved
point cloud. A scan bundle is reconstructed here, with grasps; a job's result is read from the cell.

Formats:

- ``stl``, ``obj``, ``ply``, ``glb``: the surface of every part as a triangle mesh (trimesh
  writes them), in the world (robot base) frame, metres. ``obj`` and ``glb`` keep each part
  a geometry of its own; ``glb`` also carries the grasps as empty nodes.
- ``urdf``, ``sdf``, ``mjcf``: a scene file that places each part's mesh (an STL beside it,
  in the part's own frame) at its pose, and the grasps as frames (URDF links on fixed joints,
  SDFormat ``<frame>``, MuJoCo sites). Mesh paths are relative to the scene file.
- ``rosbag``: a ROS 2 bag (MCAP, rosbags writes it): the pictures and camera info, the flange
  and camera transforms on ``/tf``, the point cloud, the model as a mesh marker, the grasps as
  poses; Foxglove opens it, ``ros2 bag play`` plays it to RViz.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import sys
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .command import Commands

if TYPE_CHECKING:
    from robocell.core_cy.superquadric import Superquadric
    from robocell.wire.config import CellConfig

__all__ = ["register", "FORMATS", "Model", "View", "GraspFrame", "model_from_result", "model_from_bundle",
           "model_from_job", "write_model", "part_mesh"]

MESH_FORMATS = ("stl", "obj", "ply", "glb")
SCENE_FORMATS = ("urdf", "sdf", "mjcf")
FORMATS = (*MESH_FORMATS, *SCENE_FORMATS, "rosbag")
_SUFFIX = {"stl": ".stl", "obj": ".obj", "ply": ".ply", "glb": ".glb", "urdf": ".urdf", "sdf": ".sdf",
           "mjcf": ".xml", "rosbag": ""}
#: The robot base frame, which the cell calls the world.
WORLD = "world"
#: Rings and points per ring of each part's mesh: about 3,000 triangles a part.
_MESH_RINGS, _MESH_RING_POINTS = 32, 48


@dataclass(frozen=True)
class GraspFrame:
    """A grasp (DESIGN.md §3): grasp-to-world pose, the width between the pads, its score."""

    T_world_grasp: np.ndarray
    width: float
    score: float
    approach: str = "top"


@dataclass(frozen=True)
class View:
    """One picture: its encoded bytes (``None``: not at hand), the camera, and where it stood.

    ``T_world_flange`` is known for a cell's job (from the camera pose and the hand-eye
    calibration), not for a bundle.
    """

    image: bytes | None
    K: np.ndarray
    T_world_cam: np.ndarray
    width: int
    height: int
    dist: np.ndarray | None = None
    T_world_flange: np.ndarray | None = None
    time: float = 0.0


@dataclass(frozen=True)
class Model:
    """What an export writes; ``name`` names the files and the model in the scene files."""

    name: str
    parts: list[Superquadric]
    grasps: list[GraspFrame] = field(default_factory=list)
    views: list[View] = field(default_factory=list)
    points: np.ndarray | None = None
    T_flange_cam: np.ndarray | None = None


def register(commands: Commands) -> None:
    parser = commands.add(
        "export", _run, help="write a job's or a bundle's model as a mesh, a scene file or a ROS 2 bag",
        description="Write the model of a job (its id; the result is read from the cell) or of a scan bundle "
                    "(a directory with scan.json; reconstructed here, with grasps) as a mesh (stl, obj, ply, "
                    "glb: every part, world frame, metres), as a scene file that places it and its grasps "
                    "(urdf, sdf, mjcf; the meshes beside it), or as a ROS 2 bag (rosbag: pictures, camera "
                    "info, tf, point cloud, mesh marker, grasp poses).")
    parser.add_argument("source", metavar="JOB_OR_BUNDLE")
    parser.add_argument("--format", required=True, choices=FORMATS)
    parser.add_argument("--out", metavar="PATH",
                        help="the file to write (a directory for rosbag); default: the job's or bundle's name "
                             "and the format's suffix, here")
    parser.add_argument("--gripper", metavar="GRIPPER.json",
                        help="for a bundle: the gripper its grasps are planned for (default: the built-in one)")
    parser.add_argument("--timeout", type=float, default=10.0, help="for a job: seconds to wait for the cell")


# --- the model ---------------------------------------------------------------------------------

def _superquadric(data: dict) -> Superquadric:
    from robocell.core_cy.superquadric import Superquadric

    return Superquadric(np.asarray(data["size"], float), np.asarray(data["shape"], float),
                        np.asarray(data["T_world_object"], float))


def model_from_result(name: str, result: dict) -> Model:
    """The parts and grasps of a result (``robocell reconstruct``'s line, or a job's ``ScanResult``
    as a dict): its ``parts`` when it has them, else its one ``superquadric``."""
    parts = result.get("parts") or [result["superquadric"]]
    grasps = [GraspFrame(np.asarray(g["T_world_grasp"], float), float(g["width"]), float(g["score"]),
                         g.get("approach", "top")) for g in result.get("grasps", [])]
    return Model(name, [_superquadric(p) for p in parts], grasps)


def _image_size(data: bytes, view: int) -> tuple[int, int]:
    from robocell.core_cy.images import checked_size

    return checked_size(data, view=view)


def model_from_bundle(directory: str | Path, gripper_path: str | None = None) -> Model:
    """Reconstruct a scan bundle with grasps, as ``robocell reconstruct --grasps`` does.

    Raises
    ------
    BundleError, CoreError
        A bad bundle or gripper file (the message names what is wrong).
    """
    from robocell.core_cy.reconstruct import reconstruct
    from robocell.wire.bundle import load_bundle

    from .reconstruct import _gripper, _with_grasps

    bundle = load_bundle(directory)
    gripper = _gripper(gripper_path)
    result = reconstruct(bundle.views, segmentation=bundle.segmentation, support_plane=bundle.support_plane)
    line = _with_grasps(result.to_dict(), result, bundle, gripper)
    model = model_from_result(Path(directory).resolve().name, line)
    views = []
    for index, view in enumerate(bundle.views):
        picture = view.image if isinstance(view.image, bytes) else view.mask if isinstance(view.mask, bytes) else None
        width, height = _image_size(picture, index) if picture is not None else (0, 0)
        views.append(View(picture, view.camera.K, view.camera.T_world_cam, width, height, view.camera.dist,
                          time=float(index)))
    return Model(model.name, model.parts, model.grasps, views, np.asarray(result.points, float))


def _recorded(path: Path) -> tuple[dict[int, bytes], np.ndarray | None]:
    """The pictures (by view) and the carved points of a job's Rerun recording."""
    import warnings

    from rerun.chunk import RrdReader
    from rerun.error_utils import RerunWarning

    images: dict[int, bytes] = {}
    points = None
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*no footer", category=RerunWarning)
        for chunk in RrdReader(str(path)).stream():
            entity = chunk.entity_path
            batch = chunk.to_record_batch()
            if entity.startswith("/world/camera") and entity.endswith("/image"):
                column = next((c for c in batch.schema.names if c.endswith(":blob")), None)
                if column is not None:
                    blobs = batch.column(column).to_pylist()
                    if blobs and blobs[-1]:
                        images[int(entity[len("/world/camera"):-len("/image")])] = bytes(blobs[-1][0])
            elif entity == "/world/points/carved":
                column = next((c for c in batch.schema.names if c.endswith(":positions")), None)
                if column is not None:
                    rows = batch.column(column).to_pylist()
                    if rows and rows[-1]:
                        points = np.asarray(rows[-1], float).reshape(-1, 3)
    return images, points


async def _fetch_job(job_id: str, config: CellConfig, timeout: float):
    from robocell.wire.client import AsyncCellClient

    async with await AsyncCellClient.connect(config.zenoh.router, config.cell_id,
                                             settings=config.zenoh.client_settings(), timeout=timeout) as client:
        return await client.status(job_id), await client.result(job_id)


def model_from_job(job_id: str, config: CellConfig, *, timeout: float = 10.0) -> tuple[Model, str | None]:
    """A finished job's model, read from its cell (as ``robocell job ID`` reads it); with the
    pictures and points of its recording where that is on this machine. Also says, if so, why
    the pictures are missing."""
    status, result = asyncio.run(_fetch_job(job_id, config, timeout))
    model = model_from_result(job_id, result.model_dump())
    hand_eye = config.hand_eye
    camera = config.camera
    images: dict[int, bytes] = {}
    points = None
    missing = None
    if result.recording is None:
        missing = f"job {job_id} has no recording ({result.recording_error}): the bag has no pictures"
    elif not Path(result.recording).is_file():
        missing = f"the recording {result.recording} is not on this machine: the bag has no pictures"
    else:
        images, points = _recorded(Path(result.recording))
    # Each view at the time its capture ended, as the job's durations tell.
    clock, views = status.created, []
    for index, T_world_cam in enumerate(result.T_base_cam):
        clock += result.durations_s.get(f"move{index}", 0.0) + result.durations_s.get(f"capture{index}", 0.0)
        T = np.asarray(T_world_cam, float)
        views.append(View(images.get(index), np.asarray(camera.K, float), T, *camera.resolution,
                          None if camera.dist is None else np.asarray(camera.dist, float),
                          T_world_flange=T @ np.linalg.inv(hand_eye), time=clock))
    return Model(job_id, model.parts, model.grasps, views, points, hand_eye), missing


# --- meshes ------------------------------------------------------------------------------------

def part_mesh(part: Superquadric, *, world: bool):
    """A part's surface as a ``trimesh.Trimesh``: in the world, or in the part's own frame."""
    import trimesh

    from robocell.core_cy.superquadric import Superquadric, mesh

    placed = part if world else Superquadric(part.size, part.shape, np.eye(4))
    vertices, triangles = mesh(placed, _MESH_RINGS, _MESH_RING_POINTS)
    return trimesh.Trimesh(vertices, triangles, process=False)


def _write_mesh(model: Model, fmt: str, out: Path) -> list[Path]:
    import trimesh

    if fmt in ("stl", "ply"):  # one mesh: the parts' surfaces side by side
        trimesh.util.concatenate([part_mesh(p, world=True) for p in model.parts]).export(out, file_type=fmt)
        return [out]
    scene = trimesh.Scene(base_frame=WORLD)
    for index, part in enumerate(model.parts):
        scene.add_geometry(part_mesh(part, world=False), geom_name=f"part{index}", node_name=f"part{index}",
                           transform=part.T_world_object)
    if fmt == "glb":
        for index, grasp in enumerate(model.grasps):
            scene.graph.update(frame_from=WORLD, frame_to=f"grasp{index}", matrix=grasp.T_world_grasp)
    scene.export(out, file_type=fmt)
    return [out]


# --- scene files -------------------------------------------------------------------------------

def _rpy(T: np.ndarray) -> list[float]:
    """Roll, pitch, yaw about the fixed x, y, z axes (URDF's and SDFormat's convention)."""
    import warnings

    from scipy.spatial.transform import Rotation

    with warnings.catch_warnings():
        # A side grasp's pitch is +-90 degrees: the angles then still give the rotation exactly,
        # with the yaw folded into the roll, which is what the warning says.
        warnings.filterwarnings("ignore", message="Gimbal lock detected", category=UserWarning)
        return Rotation.from_matrix(T[:3, :3]).as_euler("xyz").tolist()


def _numbers(values) -> str:
    return " ".join(f"{float(v):.9g}" for v in values)


def _write_part_meshes(model: Model, out: Path) -> list[Path]:
    paths = []
    for index, part in enumerate(model.parts):
        path = out.with_name(f"{out.stem}_part{index}.stl")
        part_mesh(part, world=False).export(path, file_type="stl")
        paths.append(path)
    return paths


def _xml(root: ET.Element, out: Path) -> None:
    ET.indent(root)
    ET.ElementTree(root).write(out, encoding="utf-8", xml_declaration=True)


def _urdf(model: Model, meshes: list[Path]) -> ET.Element:
    robot = ET.Element("robot", name=model.name)
    ET.SubElement(robot, "link", name=WORLD)

    def fixed(child: str, T: np.ndarray) -> None:
        joint = ET.SubElement(robot, "joint", name=f"{WORLD}_to_{child}", type="fixed")
        ET.SubElement(joint, "parent", link=WORLD)
        ET.SubElement(joint, "child", link=child)
        ET.SubElement(joint, "origin", xyz=_numbers(T[:3, 3]), rpy=_numbers(_rpy(T)))

    for index, (part, path) in enumerate(zip(model.parts, meshes)):
        link = ET.SubElement(robot, "link", name=f"part{index}")
        for kind in ("visual", "collision"):
            element = ET.SubElement(link, kind)
            ET.SubElement(ET.SubElement(element, "geometry"), "mesh", filename=path.name)
        fixed(f"part{index}", part.T_world_object)
    for index, grasp in enumerate(model.grasps):
        ET.SubElement(robot, "link", name=f"grasp{index}")
        fixed(f"grasp{index}", grasp.T_world_grasp)
    return robot


def _sdf(model: Model, meshes: list[Path]) -> ET.Element:
    sdf = ET.Element("sdf", version="1.9")
    element = ET.SubElement(sdf, "model", name=model.name)
    ET.SubElement(element, "static").text = "true"
    for index, (part, path) in enumerate(zip(model.parts, meshes)):
        link = ET.SubElement(element, "link", name=f"part{index}")
        ET.SubElement(link, "pose").text = _numbers([*part.T_world_object[:3, 3], *_rpy(part.T_world_object)])
        for kind in ("visual", "collision"):
            shape = ET.SubElement(link, kind, name=kind)
            ET.SubElement(ET.SubElement(ET.SubElement(shape, "geometry"), "mesh"), "uri").text = path.name
    for index, grasp in enumerate(model.grasps):
        frame = ET.SubElement(element, "frame", name=f"grasp{index}")
        ET.SubElement(frame, "pose").text = _numbers([*grasp.T_world_grasp[:3, 3], *_rpy(grasp.T_world_grasp)])
    return sdf


def _quaternion_wxyz(T: np.ndarray) -> list[float]:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    return [w, x, y, z]


def _mjcf(model: Model, meshes: list[Path]) -> ET.Element:
    mujoco = ET.Element("mujoco", model=model.name)
    asset = ET.SubElement(mujoco, "asset")
    world = ET.SubElement(mujoco, "worldbody")
    body = ET.SubElement(world, "body", name="object")  # fixed to the world: add a freejoint to let it fall
    for index, (part, path) in enumerate(zip(model.parts, meshes)):
        ET.SubElement(asset, "mesh", name=f"part{index}", file=path.name)
        ET.SubElement(body, "geom", name=f"part{index}", type="mesh", mesh=f"part{index}",
                      pos=_numbers(part.T_world_object[:3, 3]), quat=_numbers(_quaternion_wxyz(part.T_world_object)))
    for index, grasp in enumerate(model.grasps):
        ET.SubElement(world, "site", name=f"grasp{index}", size="0.005",
                      pos=_numbers(grasp.T_world_grasp[:3, 3]), quat=_numbers(_quaternion_wxyz(grasp.T_world_grasp)))
    return mujoco


def _write_scene(model: Model, fmt: str, out: Path) -> list[Path]:
    meshes = _write_part_meshes(model, out)
    _xml({"urdf": _urdf, "sdf": _sdf, "mjcf": _mjcf}[fmt](model, meshes), out)
    return [out, *meshes]


# --- ROS 2 bag ---------------------------------------------------------------------------------

def _write_bag(model: Model, out: Path) -> list[Path]:
    from rosbags.interfaces import Connection
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    with Writer(out, version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP) as writer:
        connections: dict[str, Connection] = {}
        for topic, stamp, message in sorted(_bag_messages(model, store), key=lambda item: item[1]):
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, message.__msgtype__, typestore=store)
            writer.write(connections[topic], stamp, store.serialize_cdr(message, message.__msgtype__))
    return [out]


#: Topics of a bag (``rosbag`` format); the camera frame follows REP 103's optical convention.
TOPICS = {"tf": "/tf", "tf_static": "/tf_static", "image": "/robocell/camera/image/compressed",
          "camera_info": "/robocell/camera/camera_info", "points": "/robocell/points",
          "model": "/robocell/model", "grasps": "/robocell/grasps"}
CAMERA_FRAME, FLANGE_FRAME = "camera_optical", "flange"


def _bag_messages(model: Model, store):
    """(topic, nanoseconds, message) of the bag, in no particular order."""
    types = store.types
    Time = types["builtin_interfaces/msg/Time"]
    Header = types["std_msgs/msg/Header"]
    Vector3, Quaternion = types["geometry_msgs/msg/Vector3"], types["geometry_msgs/msg/Quaternion"]
    Point, Pose = types["geometry_msgs/msg/Point"], types["geometry_msgs/msg/Pose"]
    Transform, TransformStamped = types["geometry_msgs/msg/Transform"], types["geometry_msgs/msg/TransformStamped"]
    TFMessage = types["tf2_msgs/msg/TFMessage"]

    def header(seconds: float, frame: str):
        whole = math.floor(seconds)
        return Header(stamp=Time(sec=int(whole), nanosec=int(round((seconds - whole) * 1e9)) % 1_000_000_000),
                      frame_id=frame)

    def quaternion(T: np.ndarray):
        from scipy.spatial.transform import Rotation

        x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
        return Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))

    def pose(T: np.ndarray):
        return Pose(position=Point(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])), orientation=quaternion(T))

    def transform(seconds: float, parent: str, child: str, T: np.ndarray):
        return TransformStamped(header=header(seconds, parent), child_frame_id=child, transform=Transform(
            translation=Vector3(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])), rotation=quaternion(T)))

    start = model.views[0].time if model.views else time.time()
    end = model.views[-1].time if model.views else start
    nanoseconds = lambda seconds: int(round(seconds * 1e9))  # noqa: E731
    if model.T_flange_cam is not None:  # a cell's job: the flange moves, the camera rides on it
        yield TOPICS["tf_static"], nanoseconds(start), TFMessage(
            transforms=[transform(start, FLANGE_FRAME, CAMERA_FRAME, model.T_flange_cam)])
    for view in model.views:
        if view.T_world_flange is not None:
            moved = transform(view.time, WORLD, FLANGE_FRAME, view.T_world_flange)
        else:
            moved = transform(view.time, WORLD, CAMERA_FRAME, view.T_world_cam)
        yield TOPICS["tf"], nanoseconds(view.time), TFMessage(transforms=[moved])
        yield TOPICS["camera_info"], nanoseconds(view.time), _camera_info(types, header(view.time, CAMERA_FRAME), view)
        if view.image is not None:
            encoding = "png" if view.image[:4] == b"\x89PNG" else "jpeg"
            yield TOPICS["image"], nanoseconds(view.time), types["sensor_msgs/msg/CompressedImage"](
                header=header(view.time, CAMERA_FRAME), format=encoding,
                data=np.frombuffer(view.image, dtype=np.uint8))
    if model.points is not None and len(model.points):
        yield TOPICS["points"], nanoseconds(end), _point_cloud(types, header(end, WORLD), model.points)
    markers = [_mesh_marker(types, header(end, WORLD), index, part, pose) for index, part in enumerate(model.parts)]
    yield TOPICS["model"], nanoseconds(end), types["visualization_msgs/msg/MarkerArray"](markers=markers)
    yield TOPICS["grasps"], nanoseconds(end), types["geometry_msgs/msg/PoseArray"](
        header=header(end, WORLD), poses=[pose(g.T_world_grasp) for g in model.grasps])


def _camera_info(types, header, view: View):
    K = np.asarray(view.K, float)
    dist = np.zeros(5) if view.dist is None else np.asarray(view.dist, float)
    P = np.zeros((3, 4))
    P[:, :3] = K
    return types["sensor_msgs/msg/CameraInfo"](
        header=header, height=view.height, width=view.width,
        distortion_model="plumb_bob" if len(dist) == 5 else "rational_polynomial", d=dist,
        k=K.ravel(), r=np.eye(3).ravel(), p=P.ravel(), binning_x=0, binning_y=0,
        roi=types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))


def _point_cloud(types, header, points: np.ndarray):
    PointField = types["sensor_msgs/msg/PointField"]
    data = np.ascontiguousarray(points, dtype="<f4")
    fields = [PointField(name=axis, offset=4 * index, datatype=PointField.FLOAT32, count=1)
              for index, axis in enumerate("xyz")]
    return types["sensor_msgs/msg/PointCloud2"](
        header=header, height=1, width=len(data), fields=fields, is_bigendian=False, point_step=12,
        row_step=12 * len(data), data=data.view(np.uint8).ravel(), is_dense=True)


def _mesh_marker(types, header, index: int, part: Superquadric, pose):
    """A part as a TRIANGLE_LIST marker: its triangles in its own frame, placed at its pose
    (a marker that needs no mesh file, which a bag cannot carry for RViz)."""
    Marker = types["visualization_msgs/msg/Marker"]
    Point, Vector3 = types["geometry_msgs/msg/Point"], types["geometry_msgs/msg/Vector3"]
    ColorRGBA = types["std_msgs/msg/ColorRGBA"]
    surface = part_mesh(part, world=False)
    corners = surface.vertices[surface.faces.reshape(-1)]
    return Marker(
        header=header, ns="robocell/model", id=index, type=Marker.TRIANGLE_LIST, action=Marker.ADD,
        pose=pose(part.T_world_object), scale=Vector3(x=1.0, y=1.0, z=1.0),
        color=ColorRGBA(r=0.24, g=0.78, b=0.35, a=0.8),
        lifetime=types["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), frame_locked=False,
        points=[Point(x=float(x), y=float(y), z=float(z)) for x, y, z in corners], colors=[],
        texture_resource="", texture=types["sensor_msgs/msg/CompressedImage"](
            header=header, format="", data=np.zeros(0, np.uint8)),
        uv_coordinates=[], text="", mesh_resource="",
        mesh_file=types["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False)


def write_model(model: Model, fmt: str, out: Path) -> list[Path]:
    """Write ``model`` as ``fmt`` to ``out``; returns the files (or bag directory) written."""
    if fmt in MESH_FORMATS:
        return _write_mesh(model, fmt, out)
    if fmt in SCENE_FORMATS:
        return _write_scene(model, fmt, out)
    if fmt == "rosbag":
        return _write_bag(model, out)
    raise ValueError(f"--format {fmt}: not one of {', '.join(FORMATS)}")


def _is_bundle(source: str) -> bool:
    """A path (it exists, or is written as one) is a bundle; anything else a job id."""
    return Path(source).exists() or "/" in source or source in (".", "..")


def _run(args: argparse.Namespace) -> int:
    from robocell.wire.config import load_config

    out = Path(args.out) if args.out else Path(Path(args.source).resolve().name + _SUFFIX[args.format])
    if out.exists() and args.format == "rosbag":
        raise ValueError(f"--out {out}: exists already; a bag is written to a new directory")
    if _is_bundle(args.source):
        if not (Path(args.source) / "scan.json").is_file():
            raise ValueError(f"{args.source}: not a scan bundle (no scan.json in it), nor a job id")
        model = model_from_bundle(args.source, args.gripper)
    else:
        if args.gripper is not None:
            raise ValueError("--gripper is for a bundle: a job's grasps are those of its cell's gripper")
        model, missing = model_from_job(args.source, load_config(args.config), timeout=args.timeout)
        if missing and args.format == "rosbag":
            print(f"robocell export: {missing}", file=sys.stderr)
    out.parent.mkdir(parents=True, exist_ok=True)
    written = write_model(model, args.format, out)
    print(json.dumps({"source": args.source, "format": args.format, "parts": len(model.parts),
                      "grasps": len(model.grasps), "files": [str(p) for p in written]}))
    return 0
