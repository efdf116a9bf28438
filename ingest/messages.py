"""ROS 2 messages as arrays and matrices: header stamps, `sensor_msgs/Image` pixels,
`sensor_msgs/CameraInfo` intrinsics, `geometry_msgs` transforms and poses (the messages as the
`rosbags` library deserialises them; nothing here reads a bag)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from ingest.checks import image_size_problem
from ingest.frames import CameraIntrinsics, IngestError, one_line
from ingest.transforms import Matrix, rigid

# Image encodings read, as numpy type codes (the byte order comes from the message).
IMAGE_ENCODINGS: dict[str, str] = {
    "16UC1": "u2",
    "mono16": "u2",
    "32FC1": "f4",
    "8UC1": "u1",
    "mono8": "u1",
    "32SC1": "i4",
    "16SC1": "i2",
}


def stamp_ns(header: Any) -> int:
    """Nanoseconds of a std_msgs/Header stamp."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def image_array(message: Any, topic: str, where: str | None = None) -> npt.NDArray[Any]:
    """The pixels of a sensor_msgs/Image as a 2D array (uint16, float32 or an integer label),
    its size checked against the limit first; errors start with `where` (default: the topic)."""
    where = where or f"topic {topic}"
    code = IMAGE_ENCODINGS.get(message.encoding)
    if code is None:
        raise IngestError(
            one_line(
                f"{where}: image encoding {message.encoding!r} is not supported "
                f"(one of {', '.join(IMAGE_ENCODINGS)})"
            )
        )
    dtype = np.dtype(code).newbyteorder(">" if message.is_bigendian else "<")
    height, width, step = int(message.height), int(message.width), int(message.step)
    too_large = image_size_problem(width, height)
    if too_large is not None:
        raise IngestError(f"{where}: {too_large}")
    raw = np.asarray(message.data, dtype=np.uint8)
    if step < width * dtype.itemsize or raw.size < step * height:
        raise IngestError(
            f"{where}: image data of {raw.size} bytes does not hold {height} rows of step {step}"
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
