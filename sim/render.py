"""Raycast rendering of a World into z-depth and instance maps, plus Kinect-style depth noise."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from sim.camera import CameraModel
from sim.world import CPU, World, build_scene

INVALID_GEOMETRY = o3d.t.geometry.RaycastingScene.INVALID_ID


@dataclass(frozen=True, eq=False)
class Render:
    """What the sensor and an oracle segmenter see from one pose."""

    depth: np.ndarray  # float32 (H, W) z-depth in metres, 0 = no valid return
    instance: np.ndarray  # int32 (H, W) index into world.objects of the first hit, -1 otherwise
    fixture_instance: np.ndarray  # int32 (H, W) index into world.fixtures, -1 otherwise
    camera: CameraModel
    pose: np.ndarray  # (4, 4) camera-to-world
    # int32 (H, W) index into world.occluders (walls, chairs, people), -1 otherwise; None when
    # the render was painted by hand or composited without it.
    occluder_instance: np.ndarray | None = None


def _pinhole_rays(camera: CameraModel, pose: np.ndarray) -> o3d.core.Tensor:
    """World-frame rays whose direction has unit length along the optical axis."""
    # Open3D samples pixel u at u + 0.5 while OpenCV puts pixel u's center at u; shifting the
    # principal point by half a pixel makes the rays pass through OpenCV pixel centers.
    intrinsic = camera.matrix()
    intrinsic[0, 2] += 0.5
    intrinsic[1, 2] += 0.5
    world_to_camera = np.linalg.inv(pose)
    return o3d.t.geometry.RaycastingScene.create_rays_pinhole(
        o3d.core.Tensor(intrinsic, o3d.core.float64, CPU),
        o3d.core.Tensor(world_to_camera, o3d.core.float64, CPU),
        camera.width,
        camera.height,
    )


def render(world: World, camera: CameraModel, pose: np.ndarray, *, nthreads: int = 0) -> Render:
    """Depth and instance maps of `world` seen from camera-to-world `pose` (nthreads 0 = all)."""
    pose = np.asarray(pose, dtype=np.float64)
    geometry = build_scene(world)
    rays = _pinhole_rays(camera, pose)
    hits = geometry.scene.cast_rays(rays, nthreads=nthreads)
    ray_length_units = hits["t_hit"].numpy()
    # t_hit is measured in multiples of the direction vector; projecting the direction on the
    # optical axis turns it into z-depth whatever length Open3D gave the direction.
    directions = rays.numpy()[..., 3:]
    axial_step = directions @ pose[:3, 2].astype(np.float32)
    depth = (ray_length_units * axial_step).astype(np.float32)
    in_range = np.isfinite(depth) & (depth >= camera.min_depth) & (depth <= camera.max_depth)
    depth[~in_range] = 0.0

    geometry_ids = hits["geometry_ids"].numpy()
    missed = geometry_ids == INVALID_GEOMETRY
    # Clamp misses to a valid slot so the lookup can be a single gather, then blank them out.
    safe_ids = np.where(missed, 0, geometry_ids).astype(np.intp)
    instance = geometry.object_lookup[safe_ids]
    fixture_instance = geometry.fixture_lookup[safe_ids]
    occluder_instance = geometry.occluder_lookup[safe_ids]
    instance[missed] = -1
    fixture_instance[missed] = -1
    occluder_instance[missed] = -1
    return Render(depth, instance, fixture_instance, camera, pose, occluder_instance)


def add_kinect_noise(
    depth: np.ndarray, rng: np.random.Generator, sigma_at_1m: float = 0.0012
) -> np.ndarray:
    """Depth with axial Gaussian noise growing as z^2; invalid (0) pixels stay 0."""
    valid = depth > 0
    noisy = depth.astype(np.float32, copy=True)
    sigma = sigma_at_1m * np.square(noisy[valid], dtype=np.float32)
    noisy[valid] += (rng.standard_normal(sigma.shape, dtype=np.float32) * sigma).astype(np.float32)
    # Noise must not turn a valid return into the "no return" marker or a negative depth.
    np.maximum(noisy, np.float32(1e-6), out=noisy, where=valid)
    return noisy
