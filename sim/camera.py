"""Pinhole depth-camera model and look-at poses (OpenCV axes: x right, y down, z forward)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics plus the depth range a Kinect-like sensor reports."""

    width: int = 640
    height: int = 480
    fx: float = 525.0
    fy: float = 525.0
    cx: float = 319.5
    cy: float = 239.5
    min_depth: float = 0.3
    max_depth: float = 6.0

    def matrix(self) -> np.ndarray:
        """The 3x3 intrinsic matrix K."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=np.float64
        )

    def intrinsics_dict(self) -> dict[str, float | int]:
        """The intrinsics as the wire format spells them."""
        return {
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
        }


def look_at(
    eye: tuple[float, float, float] | np.ndarray,
    target: tuple[float, float, float] | np.ndarray,
    up: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 1.0),
) -> np.ndarray:
    """4x4 camera-to-world pose at `eye` whose optical axis points at `target`, image-down = -up."""
    eye_point = np.asarray(eye, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - eye_point
    forward_norm = np.linalg.norm(forward)
    if forward_norm < 1e-9:
        raise ValueError("eye and target coincide")
    forward /= forward_norm
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    right_norm = np.linalg.norm(right)
    if right_norm < 1e-9:
        raise ValueError("viewing direction is parallel to up")
    right /= right_norm
    down = np.cross(forward, right)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, down, forward, eye_point
    return pose
