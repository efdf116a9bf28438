"""Frames of a ROS 2 bag, read with the `rosbags` library (no ROS install needed).

A frame is a depth image (`sensor_msgs/Image`, 16UC1 / mono16 or 32FC1) with the intrinsics of
the nearest `sensor_msgs/CameraInfo` and a camera-to-map pose, either composed along the tf tree
(/tf and /tf_static) or taken from an odometry topic (`nav_msgs/Odometry`) times a fixed
camera-in-base transform. Poses and detector topics are matched to the depth image's header
stamp: the nearest message within a tolerance, otherwise the frame is skipped and counted.

`check()` reads the bag once before anything is sent, as `frames()` does, keeping nothing: every
selected depth image (encoding, size within `MAX_IMAGE_SIDE`, data length, the camera info's
size), its intrinsics, its pose (finite and rigid) and whether its detector topics have a message
near it; a bag that cannot be read, opened or deserialised is one error naming the bag and topic.
Only the detector topics' messages themselves are left to the detector, when frames are sent.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Connection

from ingest.bag_reader import BagReader, open_bag
from ingest.checks import frame_error, intrinsics_problem, pose_problem
from ingest.frames import (
    CameraIntrinsics,
    IngestError,
    SourceCounts,
    SourceFrame,
    check_reading_options,
    frame_window,
    one_line,
)
from ingest.messages import image_array, intrinsics_of, pose_of, stamp_ns, transform_of
from ingest.transforms import (
    DisconnectedFrames,
    Matrix,
    TransformLookupError,
    TransformTree,
    nearest,
)

IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_TOPIC, TF_STATIC_TOPIC = "/tf", "/tf_static"
INT64_MAX = 2**63 - 1
DEPTH_ENCODINGS = frozenset({"16UC1", "mono16", "32FC1"})
DEPTH_FIX = "record depth as 16UC1/mono16 or 32FC1, the size its camera info gives"
CAMERA_INFO_FIX = (
    "record the depth camera's calibration on the camera info topic (K: focal lengths "
    "positive, principal point inside the image)"
)
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

    def expected_frames(self) -> int | None:
        """Depth messages the stride and limit select (known once the bag was opened)."""
        if self._depth_count is None:
            with open_bag(self.path) as bag:
                connections = bag.connections_of(self.depth_topic, IMAGE, "depth")
                self._depth_count = sum(c.msgcount for c in connections)
        selected = len(range(0, self._depth_count, self.stride))
        return selected if self.limit is None else min(selected, self.limit)

    def check(self, extra_topics: tuple[str, ...] = ()) -> None:
        """Read every selected frame as `frames()` does (the detector topics' messages are only
        looked up, not fetched), keeping none and counting nothing."""
        for _ in self._frames(extra_topics, SourceCounts(), fetch=False):
            pass

    def frames(self, extra_topics: tuple[str, ...] = ()) -> Iterator[SourceFrame]:
        """Each selected depth image, posed, with the extra topics' nearest messages."""
        yield from self._frames(extra_topics, self.counts, fetch=True)

    def _frames(
        self, extra_topics: tuple[str, ...], counts: SourceCounts, *, fetch: bool
    ) -> Iterator[SourceFrame]:
        """The frames, skips counted in `counts`; with `fetch`, each with its extra messages."""
        with open_bag(self.path) as bag:
            depth_connections = bag.connections_of(self.depth_topic, IMAGE, "depth")
            infos = self._camera_infos(bag)
            poser = self._poser(bag)
            extras = {topic: self._index(bag, topic) for topic in extra_topics}
            depth_messages = bag.raw(depth_connections, self.depth_topic)
            for position, (connection, _, raw) in enumerate(depth_messages):
                take, stop = frame_window(position, self.stride, self.limit)
                if stop:
                    return
                if not take:
                    continue
                image: Any = bag.decoded(connection, raw, f"frame {position}")
                stamp = stamp_ns(image.header)
                frame = f"frame {position} (t = {stamp / 1e9:.3f} s)"
                intrinsics = self._intrinsics_at(infos, stamp, frame)
                pose = self._pose_at(poser, stamp, str(image.header.frame_id), frame)
                if isinstance(pose, str):
                    counts.skip(pose)
                    continue
                messages = self._synchronised(bag, extras, stamp, fetch)
                if isinstance(messages, str):
                    counts.skip(messages)
                    continue
                depth = self._depth(image, intrinsics, frame)
                counts.read += 1
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

    def _intrinsics_at(
        self, infos: tuple[list[int], list[CameraIntrinsics]], stamp: int, frame: str
    ) -> CameraIntrinsics:
        """The checked intrinsics of the camera info nearest to `stamp` at any distance: drivers
        may publish it once (latched), and intrinsics change only with the camera's mode."""
        index = nearest(infos[0], stamp, INT64_MAX)
        assert index is not None  # there is at least one
        intrinsics = infos[1][index]
        problem = intrinsics_problem(intrinsics)
        if problem is not None:
            at = f"t = {infos[0][index] / 1e9:.3f} s"
            where = f"bag {self.path}, topic {self.camera_info_topic} at {at}"
            raise frame_error(frame, where, problem, CAMERA_INFO_FIX)
        return intrinsics

    def _pose_at(self, poser: Poser, stamp: int, image_frame: str, frame: str) -> Matrix | str:
        """The checked camera pose at `stamp`, or why the frame is skipped (no pose near it)."""
        try:
            pose = poser(stamp, image_frame)
        except DisconnectedFrames as error:
            raise IngestError(
                f"{error} (the camera frame is the depth images' frame_id "
                f"{image_frame!r} unless --camera-frame names another)"
            ) from error
        except TransformLookupError as error:
            return f"no pose: {_shorten(str(error))}"
        problem = pose_problem(pose)
        if problem is not None:
            source = self.pose_source
            topics = (
                f"{TF_TOPIC} and {TF_STATIC_TOPIC}" if isinstance(source, TfPose) else source.topic
            )
            fix = f"correct the pose messages of {topics} near t = {stamp / 1e9:.3f} s"
            raise frame_error(frame, f"bag {self.path}, the pose from {topics}", problem, fix)
        return pose

    def _synchronised(
        self,
        bag: BagReader,
        extras: dict[str, tuple[list[int], list[int], list[Connection]]],
        stamp: int,
        fetch: bool,
    ) -> dict[str, object] | str:
        """The extra topics' messages nearest to `stamp` (fetched only with `fetch`), or why the
        frame is skipped (a topic has none within the sync tolerance)."""
        messages: dict[str, object] = {}
        for topic, (stamps, bag_times, connections) in extras.items():
            found = nearest(stamps, stamp, self.sync_tolerance_ns)
            if found is None:
                return f"no {topic} message near the depth stamp"
            if fetch:
                messages[topic] = self._fetch(bag, connections, bag_times[found], stamps[found])
        return messages

    def _depth(self, image: Any, intrinsics: CameraIntrinsics, frame: str) -> npt.NDArray[Any]:
        """The depth image's pixels, checked: a depth encoding, the camera info's size."""
        where = f"{frame}: bag {self.path}, topic {self.depth_topic}"
        if image.encoding not in DEPTH_ENCODINGS:
            raise IngestError(
                one_line(
                    f"{where}: encoding {image.encoding!r} is not depth "
                    f"(16UC1, mono16 or 32FC1); fix: {DEPTH_FIX}"
                )
            )
        size = (int(image.height), int(image.width))
        if (intrinsics.height, intrinsics.width) != size:
            raise IngestError(
                f"{where}: the depth image is {size[1]}x{size[0]}, camera info "
                f"{self.camera_info_topic} says {intrinsics.width}x{intrinsics.height}; "
                f"fix: {DEPTH_FIX}"
            )
        return image_array(image, self.depth_topic, where)

    def _camera_infos(self, bag: BagReader) -> tuple[list[int], list[CameraIntrinsics]]:
        """Every camera info's stamp and intrinsics, by stamp."""
        connections = bag.connections_of(self.camera_info_topic, CAMERA_INFO, "camera info")
        pairs = [
            (stamp_ns(message.header), intrinsics_of(message))
            for _, message in bag.messages(connections, self.camera_info_topic)
        ]
        pairs.sort(key=lambda pair: pair[0])
        if not pairs:
            raise IngestError(f"camera info topic {self.camera_info_topic!r} has no messages")
        return [stamp for stamp, _ in pairs], [intrinsics for _, intrinsics in pairs]

    def _tree(self, bag: BagReader, required: bool) -> TransformTree:
        """The tf tree of /tf and /tf_static."""
        tree = TransformTree()
        topics = [
            (topic, topic == TF_STATIC_TOPIC)
            for topic in (TF_TOPIC, TF_STATIC_TOPIC)
            if any(c.topic == topic for c in bag.connections)
        ]
        if required and not topics:
            raise IngestError(f"bag {self.path} has neither {TF_TOPIC} nor {TF_STATIC_TOPIC}")
        for topic, static in topics:
            connections = bag.connections_of(topic, TF_MESSAGE, "transform")
            for _, message in bag.messages(connections, topic):
                for stamped in message.transforms:
                    parent, child = str(stamped.header.frame_id), str(stamped.child_frame_id)
                    stamp = stamp_ns(stamped.header)
                    try:
                        matrix = transform_of(stamped.transform)
                        tree.add(parent, child, stamp, matrix, static=static)
                    except (TransformLookupError, ValueError) as error:  # a zero quaternion
                        raise IngestError(
                            one_line(
                                f"bag {self.path}, topic {topic}: transform {parent!r} -> "
                                f"{child!r} at t = {stamp / 1e9:.3f} s: {error}; fix: correct "
                                "the transforms published there"
                            )
                        ) from error
        return tree

    def _poser(self, bag: BagReader) -> Poser:
        """A function (stamp, image frame) -> camera-to-map pose; raises TransformLookupError."""
        source = self.pose_source
        tolerance = self.pose_tolerance_ns
        if isinstance(source, TfPose):
            tree = self._tree(bag, required=True)
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
        connections = bag.connections_of(source.topic, ODOMETRY, "odometry")
        stamps: list[int] = []
        poses: list[Matrix] = []
        base_frames: set[str] = set()
        for _, message in bag.messages(connections, source.topic):
            stamps.append(stamp_ns(message.header))
            try:
                poses.append(pose_of(message.pose.pose))
            except ValueError as error:  # a zero quaternion
                raise IngestError(
                    f"bag {self.path}, topic {source.topic} at t = {stamps[-1] / 1e9:.3f} s: "
                    f"{error}; fix: correct the odometry published there"
                ) from error
            base_frames.add(str(message.child_frame_id).lstrip("/"))
        if not stamps:
            raise IngestError(f"odometry topic {source.topic!r} has no messages")
        order = np.argsort(stamps, kind="stable")
        stamps = [stamps[i] for i in order]
        poses = [poses[i] for i in order]
        static_tree = self._tree(bag, required=False) if source.camera_in_base is None else None
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

    def _index(self, bag: BagReader, topic: str) -> tuple[list[int], list[int], list[Connection]]:
        """(header stamps, bag times, connections) of an extra topic, sorted by header stamp."""
        connections = [c for c in bag.connections if c.topic == topic]
        if not connections:
            topics = sorted({c.topic for c in bag.connections})
            raise IngestError(
                f"detector topic {topic!r} is not in bag {self.path}; its topics: "
                f"{', '.join(topics)}"
            )
        pairs = []
        for bag_time, message in bag.messages(connections, topic):
            header = getattr(message, "header", None)
            pairs.append((stamp_ns(header) if header is not None else bag_time, bag_time))
        pairs.sort()
        return [stamp for stamp, _ in pairs], [bag for _, bag in pairs], connections

    def _fetch(
        self, bag: BagReader, connections: Sequence[Connection], bag_time: int, stamp: int
    ) -> object:
        """The message of `connections` recorded at `bag_time` whose stamp is `stamp`."""
        topic = connections[0].topic
        window = {"start": bag_time, "stop": bag_time + 1}
        for _, message in bag.messages(connections, topic, **window):
            header = getattr(message, "header", None)
            if header is None or stamp_ns(header) == stamp:
                return message
        raise IngestError(f"message at t = {bag_time / 1e9:.3f} s vanished from the bag")


def _shorten(reason: str) -> str:
    """A skip reason without the stamp, so that equal reasons count together."""
    return reason.split(" of t = ")[0]
