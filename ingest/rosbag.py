"""Frames of a ROS 2 bag, read with the `rosbags` library (no ROS install needed).

A frame is a depth image (`sensor_msgs/Image`, 16UC1 / mono16 or 32FC1) with the intrinsics of
the nearest `sensor_msgs/CameraInfo` and a camera-to-map pose, either composed along the tf tree
(/tf and /tf_static) or taken from an odometry topic (`nav_msgs/Odometry`) times a fixed
camera-in-base transform. Poses and detector topics are matched to the depth image's header
stamp: the nearest message within a tolerance, otherwise the frame is skipped and counted.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Connection
from rosbags.typesys import Stores, get_typestore

from ingest.frames import (
    CameraIntrinsics,
    IngestError,
    SourceCounts,
    SourceFrame,
    check_reading_options,
    frame_window,
)
from ingest.transforms import (
    DisconnectedFrames,
    Matrix,
    TransformLookupError,
    TransformTree,
    nearest,
    rigid,
)

IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_TOPIC, TF_STATIC_TOPIC = "/tf", "/tf_static"
INT64_MAX = 2**63 - 1
# (depth stamp in ns, the depth image's frame_id) -> camera-to-map pose
Poser = Callable[[int, str], Matrix]


@dataclass(frozen=True)
class TfPose:
    """The camera pose from the tf tree: `map_frame` -> ... -> `camera_frame`.

    `camera_frame` must be the optical frame (z forward, x right, y down); None takes the depth
    image's header frame_id, which drivers set to the optical frame.
    """

    map_frame: str
    camera_frame: str | None = None


@dataclass(frozen=True)
class OdomPose:
    """The camera pose from an odometry topic: odom's pose of its child (base) frame, times the
    camera's pose in that base frame (`camera_in_base`; None: from /tf_static, or identity when
    the camera frame is the odometry's child frame)."""

    topic: str
    camera_in_base: Matrix | None = None
    camera_frame: str | None = None


def stamp_ns(header: Any) -> int:
    """Nanoseconds of a std_msgs/Header stamp."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def image_array(message: Any, topic: str) -> npt.NDArray[Any]:
    """The pixels of a sensor_msgs/Image as a 2D array (uint16, float32 or an integer label)."""
    encodings: dict[str, str] = {
        "16UC1": "u2",
        "mono16": "u2",
        "32FC1": "f4",
        "8UC1": "u1",
        "mono8": "u1",
        "32SC1": "i4",
        "16SC1": "i2",
    }
    code = encodings.get(message.encoding)
    if code is None:
        raise IngestError(
            f"topic {topic}: image encoding {message.encoding!r} is not supported "
            f"(one of {', '.join(encodings)})"
        )
    dtype = np.dtype(code).newbyteorder(">" if message.is_bigendian else "<")
    height, width, step = int(message.height), int(message.width), int(message.step)
    raw = np.asarray(message.data, dtype=np.uint8)
    if step < width * dtype.itemsize or raw.size < step * height:
        raise IngestError(
            f"topic {topic}: image data of {raw.size} bytes does not hold {height} rows of "
            f"step {step}"
        )
    rows = raw[: step * height].reshape(height, step)[:, : width * dtype.itemsize]
    return (
        np.ascontiguousarray(rows)
        .view(dtype)
        .reshape(height, width)
        .astype(dtype.newbyteorder("="))
    )


def intrinsics_of(message: Any) -> CameraIntrinsics:
    """Pinhole intrinsics of a sensor_msgs/CameraInfo (K row-major: fx 0 cx, 0 fy cy, 0 0 1)."""
    k = [float(value) for value in message.k]
    return CameraIntrinsics(
        width=int(message.width), height=int(message.height), fx=k[0], fy=k[4], cx=k[2], cy=k[5]
    )


def transform_of(transform: Any) -> Matrix:
    """4x4 matrix of a geometry_msgs/Transform."""
    t, q = transform.translation, transform.rotation
    return rigid((t.x, t.y, t.z), (q.x, q.y, q.z, q.w))


def pose_of(pose: Any) -> Matrix:
    """4x4 matrix of a geometry_msgs/Pose."""
    p, q = pose.position, pose.orientation
    return rigid((p.x, p.y, p.z), (q.x, q.y, q.z, q.w))


class RosbagSource:
    """The depth frames of a ROS 2 bag, posed and synchronised."""

    def __init__(
        self,
        path: Path,
        *,
        depth_topic: str,
        camera_info_topic: str,
        pose: TfPose | OdomPose,
        depth_scale: float = 0.001,
        stride: int = 1,
        limit: int | None = None,
        pose_tolerance: float = 0.05,
        sync_tolerance: float = 0.02,
    ) -> None:
        check_reading_options(stride, limit, depth_scale)
        if not path.exists():
            raise IngestError(f"bag {path} does not exist")
        self.path = path
        self.name = path.name or "bag"
        self.depth_topic, self.camera_info_topic = depth_topic, camera_info_topic
        self.pose_source = pose
        self.depth_scale = depth_scale
        self.stride, self.limit = stride, limit
        self.pose_tolerance_ns = int(pose_tolerance * 1e9)
        self.sync_tolerance_ns = int(sync_tolerance * 1e9)
        self.counts = SourceCounts()
        self._depth_count: int | None = None

    def _open(self) -> AnyReader:
        try:
            return AnyReader([self.path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        except AnyReaderError as error:
            raise IngestError(f"bag {self.path} cannot be read: {error}") from error

    def _connections(
        self, reader: AnyReader, topic: str, msgtype: str, role: str
    ) -> list[Connection]:
        """The connections of `topic`, checked to exist with the expected type."""
        found = [c for c in reader.connections if c.topic == topic]
        if not found:
            topics = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})
            raise IngestError(
                f"{role} topic {topic!r} is not in bag {self.path}; its topics: {', '.join(topics)}"
            )
        wrong = sorted({c.msgtype for c in found if c.msgtype != msgtype})
        if wrong:
            raise IngestError(f"{role} topic {topic!r} has type {wrong[0]}, expected {msgtype}")
        return found

    def expected_frames(self) -> int | None:
        """Depth messages the stride and limit select (known once the bag was opened)."""
        if self._depth_count is None:
            with self._open() as reader:
                connections = self._connections(reader, self.depth_topic, IMAGE, "depth")
                self._depth_count = sum(c.msgcount for c in connections)
        selected = len(range(0, self._depth_count, self.stride))
        return selected if self.limit is None else min(selected, self.limit)

    def frames(self, extra_topics: tuple[str, ...] = ()) -> Iterator[SourceFrame]:
        """Each selected depth image, posed, with the extra topics' nearest messages."""
        with self._open() as reader:
            depth_connections = self._connections(reader, self.depth_topic, IMAGE, "depth")
            infos = self._camera_infos(reader)
            poser = self._poser(reader)
            extras = {topic: self._index(reader, topic) for topic in extra_topics}
            for position, (connection, _, raw) in enumerate(reader.messages(depth_connections)):
                take, stop = frame_window(position, self.stride, self.limit)
                if stop:
                    return
                if not take:
                    continue
                image: Any = reader.deserialize(raw, connection.msgtype)
                stamp = stamp_ns(image.header)
                # The nearest camera info at any distance: drivers may publish it once (latched),
                # and intrinsics change only with the camera's mode.
                info_index = nearest(infos[0], stamp, INT64_MAX)
                assert info_index is not None  # there is at least one
                intrinsics = infos[1][info_index]
                camera_frame = str(image.header.frame_id)
                try:
                    pose = poser(stamp, camera_frame)
                except DisconnectedFrames as error:
                    raise IngestError(
                        f"{error} (the camera frame is the depth images' frame_id "
                        f"{camera_frame!r} unless --camera-frame names another)"
                    ) from error
                except TransformLookupError as error:
                    self.counts.skip(f"no pose: {_shorten(str(error))}")
                    continue
                messages: dict[str, object] = {}
                for topic, (stamps, bag_times, connections) in extras.items():
                    found = nearest(stamps, stamp, self.sync_tolerance_ns)
                    if found is None:
                        break
                    messages[topic] = self._fetch(
                        reader, connections, bag_times[found], stamps[found]
                    )
                if len(messages) < len(extras):
                    missing = next(t for t in extras if t not in messages)
                    self.counts.skip(f"no {missing} message near the depth stamp")
                    continue
                depth = image_array(image, self.depth_topic)
                if depth.dtype not in (np.uint16, np.float32):
                    raise IngestError(
                        f"depth topic {self.depth_topic}: encoding {image.encoding!r} is not "
                        "depth (16UC1, mono16 or 32FC1)"
                    )
                if (intrinsics.height, intrinsics.width) != depth.shape:
                    raise IngestError(
                        f"camera info {self.camera_info_topic} says {intrinsics.width}x"
                        f"{intrinsics.height}, the depth images are {depth.shape[1]}x{depth.shape[0]}"
                    )
                self.counts.read += 1
                yield SourceFrame(
                    index=position,
                    frame_id=f"{self.name}-{stamp}",
                    timestamp=stamp / 1e9,
                    depth=depth,
                    intrinsics=intrinsics,
                    pose=pose,
                    depth_scale=self.depth_scale,
                    stamp_ns=stamp,
                    messages=messages,
                )

    def _camera_infos(self, reader: AnyReader) -> tuple[list[int], list[CameraIntrinsics]]:
        """Every camera info's stamp and intrinsics, by stamp."""
        connections = self._connections(reader, self.camera_info_topic, CAMERA_INFO, "camera info")
        pairs = []
        for connection, _, raw in reader.messages(connections):
            message: Any = reader.deserialize(raw, connection.msgtype)
            pairs.append((stamp_ns(message.header), intrinsics_of(message)))
        pairs.sort(key=lambda pair: pair[0])
        if not pairs:
            raise IngestError(f"camera info topic {self.camera_info_topic!r} has no messages")
        return [stamp for stamp, _ in pairs], [intrinsics for _, intrinsics in pairs]

    def _tree(self, reader: AnyReader, required: bool) -> TransformTree:
        """The tf tree of /tf and /tf_static."""
        tree = TransformTree()
        topics = [
            (topic, topic == TF_STATIC_TOPIC)
            for topic in (TF_TOPIC, TF_STATIC_TOPIC)
            if any(c.topic == topic for c in reader.connections)
        ]
        if required and not topics:
            raise IngestError(f"bag {self.path} has neither {TF_TOPIC} nor {TF_STATIC_TOPIC}")
        for topic, static in topics:
            connections = self._connections(reader, topic, TF_MESSAGE, "transform")
            for connection, _, raw in reader.messages(connections):
                message: Any = reader.deserialize(raw, connection.msgtype)
                for stamped in message.transforms:
                    try:
                        tree.add(
                            str(stamped.header.frame_id),
                            str(stamped.child_frame_id),
                            stamp_ns(stamped.header),
                            transform_of(stamped.transform),
                            static=static,
                        )
                    except TransformLookupError as error:
                        raise IngestError(f"topic {topic}: {error}") from error
        return tree

    def _poser(self, reader: AnyReader) -> Poser:
        """A function (stamp, image frame) -> camera-to-map pose; raises TransformLookupError."""
        source = self.pose_source
        tolerance = self.pose_tolerance_ns
        if isinstance(source, TfPose):
            tree = self._tree(reader, required=True)
            for name in (source.map_frame, source.camera_frame):
                if name is not None and name.lstrip("/") not in tree.frames():
                    raise IngestError(
                        f"frame {name!r} is not in the bag's transforms; frames: "
                        f"{', '.join(sorted(tree.frames()))}"
                    )

            def from_tf(stamp: int, image_frame: str) -> Matrix:
                camera = source.camera_frame or image_frame
                return tree.lookup(source.map_frame, camera, stamp, tolerance)

            return from_tf
        connections = self._connections(reader, source.topic, ODOMETRY, "odometry")
        stamps: list[int] = []
        poses: list[Matrix] = []
        base_frames: set[str] = set()
        for connection, _, raw in reader.messages(connections):
            message: Any = reader.deserialize(raw, connection.msgtype)
            stamps.append(stamp_ns(message.header))
            poses.append(pose_of(message.pose.pose))
            base_frames.add(str(message.child_frame_id).lstrip("/"))
        if not stamps:
            raise IngestError(f"odometry topic {source.topic!r} has no messages")
        order = np.argsort(stamps, kind="stable")
        stamps = [stamps[i] for i in order]
        poses = [poses[i] for i in order]
        static_tree = self._tree(reader, required=False) if source.camera_in_base is None else None
        base = sorted(base_frames)[0]

        def from_odometry(stamp: int, image_frame: str) -> Matrix:
            index = nearest(stamps, stamp, tolerance)
            if index is None:
                raise TransformLookupError(
                    f"no {source.topic} message within {tolerance / 1e9:g} s of "
                    f"t = {stamp / 1e9:.3f} s"
                )
            if source.camera_in_base is not None:
                return poses[index] @ source.camera_in_base
            camera = (source.camera_frame or image_frame).lstrip("/")
            if camera == base:
                return poses[index]
            assert static_tree is not None
            try:
                return poses[index] @ static_tree.lookup(base, camera, stamp, tolerance)
            except TransformLookupError as error:
                raise IngestError(
                    f"the camera's pose in the odometry's frame {base!r} is unknown ({error}); "
                    "give --camera-in-base or record /tf_static"
                ) from error

        return from_odometry

    def _index(
        self, reader: AnyReader, topic: str
    ) -> tuple[list[int], list[int], list[Connection]]:
        """(header stamps, bag times, connections) of an extra topic, sorted by header stamp."""
        connections = [c for c in reader.connections if c.topic == topic]
        if not connections:
            topics = sorted({c.topic for c in reader.connections})
            raise IngestError(
                f"detector topic {topic!r} is not in bag {self.path}; its topics: "
                f"{', '.join(topics)}"
            )
        pairs = []
        for connection, bag_time, raw in reader.messages(connections):
            message: Any = reader.deserialize(raw, connection.msgtype)
            header = getattr(message, "header", None)
            pairs.append((stamp_ns(header) if header is not None else bag_time, bag_time))
        pairs.sort()
        return [stamp for stamp, _ in pairs], [bag for _, bag in pairs], connections

    def _fetch(
        self, reader: AnyReader, connections: Sequence[Connection], bag_time: int, stamp: int
    ) -> object:
        """The message of `connections` recorded at `bag_time` whose stamp is `stamp`."""
        for connection, _, raw in reader.messages(connections, start=bag_time, stop=bag_time + 1):
            message: Any = reader.deserialize(raw, connection.msgtype)
            header = getattr(message, "header", None)
            if header is None or stamp_ns(header) == stamp:
                return message
        raise IngestError(f"message at t = {bag_time / 1e9:.3f} s vanished from the bag")


def _shorten(reason: str) -> str:
    """A skip reason without the stamp, so that equal reasons count together."""
    return reason.split(" of t = ")[0]
