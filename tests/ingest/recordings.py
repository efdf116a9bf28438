"""Recordings the ingest tests write from the real 7-Scenes kitchen frames: a folder in its own
layout with per-frame instance PNGs, and a ROS 2 bag (depth, camera info, /tf, a label image).

The instances are ours: the real surfaces inside fixed world boxes (objects: 20 cm cubes around
points frame 0 sees; a fixture: a larger box under them), so every frame's masks agree with its
depth and pose, as a real segmenter's would.
"""

from __future__ import annotations

import functools
import json
import shutil
import struct
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from PIL import Image
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from ingest.transforms import invert, quaternion_of, rigid

FX = FY = 585.0
CX, CY = 320.0, 240.0
WIDTH, HEIGHT = 640, 480
T0_NS = 1_700_000_000 * 10**9
PERIOD_NS = 33_333_333  # 30 Hz
# Pixels of frame 0 whose surfaces become the objects: (id, label, kind, u, v, half size m).
INSTANCES = (
    (1, "mug", "object", 300, 250, 0.10),
    (2, "bowl", "object", 380, 300, 0.10),
    (3, "book", "object", 220, 330, 0.10),
    (10, "table", "fixture", 320, 300, 0.45),
)
LABEL_MAP = {
    "1": "mug",
    "2": "bowl",
    "3": {"label": "book", "score": 0.9},
    "10": {"label": "table", "kind": "fixture"},
}
# The bag's fixed transforms: map -> odom (static) and base_link -> camera (static); /tf holds
# odom -> base_link, chosen so that map -> odom -> base_link -> camera is each pose file's.
MAP_TO_ODOM = rigid((0.5, -0.2, 0.0), (0.0, 0.0, np.sin(0.15), np.cos(0.15)))
BASE_TO_CAMERA = rigid((0.1, 0.0, 0.3), (-0.5, 0.5, -0.5, 0.5))  # optical axes in a x-forward base


def load_frame(kitchen: Path, index: int) -> tuple[npt.NDArray[np.uint16], npt.NDArray[np.float64]]:
    """Depth (mm) and camera-to-world pose of one real frame."""
    with Image.open(kitchen / f"frame-{index:06d}.depth.png") as image:
        depth = np.asarray(image).astype(np.uint16)
    return depth, np.loadtxt(kitchen / f"frame-{index:06d}.pose.txt")


def world_points(depth: npt.NDArray[np.uint16], pose: npt.NDArray[np.float64]) -> Any:
    """World coordinates of every pixel (invalid pixels far away)."""
    rows, cols = np.mgrid[0:HEIGHT, 0:WIDTH]
    z = depth.astype(np.float64) / 1000.0
    camera = np.stack([(cols - CX) / FX * z, (rows - CY) / FY * z, z], axis=-1)
    world = camera @ pose[:3, :3].T + pose[:3, 3]
    world[depth == 0] = 1e6
    return world


@dataclass(frozen=True)
class Box:
    """One instance's world box."""

    instance_id: int
    center: npt.NDArray[np.float64]
    half: float


@functools.cache
def boxes(kitchen: Path) -> list[Box]:
    """The instance boxes, anchored on frame 0's surfaces."""
    depth, pose = load_frame(kitchen, 0)
    world = world_points(depth, pose)
    return [Box(i, world[v, u].copy(), half) for i, _, _, u, v, half in INSTANCES]


def instance_image(
    depth: npt.NDArray[np.uint16], pose: npt.NDArray[np.float64], instance_boxes: list[Box]
) -> npt.NDArray[np.uint16]:
    """Instance ids of the pixels inside each box (larger boxes first, so objects win)."""
    world = world_points(depth, pose)
    ids = np.zeros(depth.shape, dtype=np.uint16)
    for box in sorted(instance_boxes, key=lambda b: -b.half):
        inside = (np.abs(world - box.center) <= box.half).all(axis=-1)
        ids[inside] = box.instance_id
    return ids


@functools.cache
def frame_instances(kitchen: Path, index: int) -> npt.NDArray[np.uint16]:
    """The instance image of a real frame (computed once for all recordings)."""
    depth, pose = load_frame(kitchen, index)
    return instance_image(depth, pose, boxes(kitchen))


def write_label_map(path: Path) -> Path:
    """The test label map (JSON)."""
    path.write_text(json.dumps(LABEL_MAP))
    return path


def write_folder(kitchen: Path, out: Path, frames: int) -> Path:
    """The first `frames` frames in the 7-Scenes layout (copied: `pbdag ingest` refuses links
    out of the folder), and `out/masks` with one instance PNG per frame."""
    out.mkdir(parents=True)
    masks = out / "masks"
    masks.mkdir()
    shutil.copy(kitchen / "camera-intrinsics.txt", out / "camera-intrinsics.txt")
    for index in range(frames):
        stem = f"frame-{index:06d}"
        for suffix in (".depth.png", ".pose.txt"):
            shutil.copy(kitchen / f"{stem}{suffix}", out / f"{stem}{suffix}")
        Image.fromarray(frame_instances(kitchen, index)).save(masks / f"{stem}.png")
    return out


def _stamp(typestore: Any, ns: int) -> Any:
    time_type = typestore.types["builtin_interfaces/msg/Time"]
    return time_type(sec=ns // 10**9, nanosec=ns % 10**9)


def _header(typestore: Any, ns: int, frame_id: str) -> Any:
    return typestore.types["std_msgs/msg/Header"](stamp=_stamp(typestore, ns), frame_id=frame_id)


def _image(typestore: Any, ns: int, pixels: npt.NDArray[Any], encoding: str) -> Any:
    data = np.ascontiguousarray(pixels).astype(pixels.dtype.newbyteorder("<")).view(np.uint8)
    return typestore.types["sensor_msgs/msg/Image"](
        header=_header(typestore, ns, "camera_optical"),
        height=pixels.shape[0],
        width=pixels.shape[1],
        encoding=encoding,
        is_bigendian=0,
        step=pixels.shape[1] * pixels.dtype.itemsize,
        data=data.reshape(-1),
    )


def _transform(typestore: Any, ns: int, parent: str, child: str, matrix: Any) -> Any:
    types = typestore.types
    x, y, z = (float(v) for v in matrix[:3, 3])
    qx, qy, qz, qw = quaternion_of(matrix[:3, :3])
    return types["geometry_msgs/msg/TransformStamped"](
        header=_header(typestore, ns, parent),
        child_frame_id=child,
        transform=types["geometry_msgs/msg/Transform"](
            translation=types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
            rotation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
        ),
    )


def _camera_info(typestore: Any, ns: int, fx: float = FX) -> Any:
    types = typestore.types
    return types["sensor_msgs/msg/CameraInfo"](
        header=_header(typestore, ns, "camera_optical"),
        height=HEIGHT,
        width=WIDTH,
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=np.array([fx, 0, CX, 0, FY, CY, 0, 0, 1], dtype=np.float64),
        r=np.eye(3).reshape(-1),
        p=np.array([fx, 0, CX, 0, 0, FY, CY, 0, 0, 0, 1, 0], dtype=np.float64),
        binning_x=0,
        binning_y=0,
        roi=types["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        ),
    )


def _odometry(typestore: Any, ns: int, matrix: Any) -> Any:
    types = typestore.types
    x, y, z = (float(v) for v in matrix[:3, 3])
    qx, qy, qz, qw = quaternion_of(matrix[:3, :3])
    pose = types["geometry_msgs/msg/Pose"](
        position=types["geometry_msgs/msg/Point"](x=x, y=y, z=z),
        orientation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
    )
    zero = types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return types["nav_msgs/msg/Odometry"](
        header=_header(typestore, ns, "odom"),
        child_frame_id="base_link",
        pose=types["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=types["geometry_msgs/msg/TwistWithCovariance"](
            twist=types["geometry_msgs/msg/Twist"](linear=zero, angular=zero),
            covariance=np.zeros(36),
        ),
    )


def _break(transform: Any, how: str | None) -> None:
    """Break a geometry_msgs/Transform: "nan" (a NaN translation), "zero-quaternion"."""
    if how == "nan":
        transform.translation.x = float("nan")
    elif how == "zero-quaternion":
        rotation = transform.rotation
        rotation.x = rotation.y = rotation.z = rotation.w = 0.0
    elif how is not None:
        raise ValueError(f"unknown way to break a transform: {how}")


def frame_stamp(index: int) -> int:
    """The header stamp (ns) of frame `index` in the bag."""
    return T0_NS + index * PERIOD_NS


def write_bag(
    kitchen: Path,
    out: Path,
    frames: int,
    *,
    without_tf: frozenset[int] = frozenset(),
    without_labels: frozenset[int] = frozenset(),
    float_depth: bool = False,
    mcap: bool = False,
    camera_info_once: bool = False,
    bad_tf: Mapping[int, str] | None = None,
    garbage_depth: frozenset[int] = frozenset(),
    fx: float = FX,
) -> Path:
    """A ROS 2 bag of the first `frames` frames: /camera/depth (16UC1 mm, or 32FC1 m),
    /camera/camera_info, /camera/instances (16UC1 ids), /tf, /tf_static and /odom.

    /tf and /odom are stamped 4 ms after each depth image (inside the pose tolerance); frames
    in `without_tf` have neither, frames in `without_labels` no label image. With
    `camera_info_once` the camera info is published with the first frame only (latched). The
    /tf of a frame in `bad_tf` is broken as `_break` says, the depth message of a frame in
    `garbage_depth` is bytes that no decoder reads; `fx` is the camera info's."""
    bad_tf = bad_tf or {}
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    odom_to_map = invert(MAP_TO_ODOM)
    camera_to_base = invert(BASE_TO_CAMERA)
    storage = StoragePlugin.MCAP if mcap else StoragePlugin.SQLITE3
    with Writer(out, version=9, storage_plugin=storage) as writer:
        add = writer.add_connection
        depth_topic = add("/camera/depth", "sensor_msgs/msg/Image", typestore=typestore)
        info_topic = add("/camera/camera_info", "sensor_msgs/msg/CameraInfo", typestore=typestore)
        label_topic = add("/camera/instances", "sensor_msgs/msg/Image", typestore=typestore)
        tf_topic = add("/tf", "tf2_msgs/msg/TFMessage", typestore=typestore)
        static_topic = add("/tf_static", "tf2_msgs/msg/TFMessage", typestore=typestore)
        odom_topic = add("/odom", "nav_msgs/msg/Odometry", typestore=typestore)
        tf_message = typestore.types["tf2_msgs/msg/TFMessage"]

        def write(connection: Any, ns: int, message: Any) -> None:
            writer.write(connection, ns, typestore.serialize_cdr(message, connection.msgtype))

        static = tf_message(
            transforms=[
                _transform(typestore, T0_NS, "map", "odom", MAP_TO_ODOM),
                _transform(typestore, T0_NS, "base_link", "camera_optical", BASE_TO_CAMERA),
            ]
        )
        write(static_topic, T0_NS, static)
        for index in range(frames):
            ns = frame_stamp(index)
            depth, pose = load_frame(kitchen, index)
            odom_to_base = odom_to_map @ pose @ camera_to_base
            if index not in without_tf:
                odom_tf = _transform(typestore, ns + 4_000_000, "odom", "base_link", odom_to_base)
                _break(odom_tf.transform, bad_tf.get(index))
                write(tf_topic, ns + 4_000_000, tf_message(transforms=[odom_tf]))
                write(
                    odom_topic, ns + 4_000_000, _odometry(typestore, ns + 4_000_000, odom_to_base)
                )
            pixels: npt.NDArray[Any] = depth
            encoding = "16UC1"
            if float_depth:
                pixels = depth.astype(np.float32) / 1000.0
                pixels[depth == 0] = np.nan
                encoding = "32FC1"
            if index == 0 or not camera_info_once:
                write(info_topic, ns, _camera_info(typestore, ns, fx))
            if index in garbage_depth:  # bytes that are no CDR message
                writer.write(depth_topic, ns, b"\x00\x01\x00\x00SECRET-TOKEN")
            else:
                write(depth_topic, ns, _image(typestore, ns, pixels, encoding))
            if index not in without_labels:  # recorded a moment after the depth, same stamp
                ids = frame_instances(kitchen, index)
                write(label_topic, ns + 1, _image(typestore, ns, ids, "16UC1"))
    return out


def _chunk(kind: bytes, data: bytes) -> bytes:
    """One PNG chunk: length, type, data, CRC of type and data."""
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _png_start(width: int, height: int, bit_depth: int) -> bytes:
    """The PNG signature and the header of a greyscale image."""
    header = struct.pack(">IIBBBBB", width, height, bit_depth, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header)


def write_zero_png(path: Path, width: int, height: int, bit_depth: int = 16) -> Path:
    """A complete greyscale PNG of zeros, compressed row block by row block: a large one is a
    decompression bomb (13000 x 13000 at 16 bits: 338 MB of pixels in a file of 329 KB) that is
    never held in memory while written."""
    row = bytes(1 + width * bit_depth // 8)  # the filter byte, then the pixels
    compressor = zlib.compressobj()
    with path.open("wb") as file:
        file.write(_png_start(width, height, bit_depth))
        for first in range(0, height, 256):
            piece = compressor.compress(row * min(256, height - first))
            if piece:
                file.write(_chunk(b"IDAT", piece))
        file.write(_chunk(b"IDAT", compressor.flush()))
        file.write(_chunk(b"IEND", b""))
    return path


def write_png_header(
    path: Path, width: int, height: int, data: bytes = b"", bit_depth: int = 16
) -> Path:
    """A PNG whose header says `width` x `height` and whose one IDAT chunk holds `data` (not
    necessarily a zlib stream), every checksum valid."""
    path.write_bytes(
        _png_start(width, height, bit_depth) + _chunk(b"IDAT", data) + _chunk(b"IEND", b"")
    )
    return path
