"""Compile the method's numba kernels ahead of the first batch.

numba compiles each kernel on its first call (about 7 s for all of them on a 2-core machine) and
caches the machine code beside the module (or under `NUMBA_CACHE_DIR`), so that later processes
load it in a fraction of a second. `compile_kernels` runs `decide` on two small synthetic
batches, which calls every kernel with the argument types a real batch gives it: the container
image runs it at build time, and `python -m core.warmup` does the same on a fresh install.
"""

from __future__ import annotations

import time

import numpy as np

from core.decide import decide
from core.evolve import fold
from core.masks import Mask
from core.observation import Batch, Detection, Frame, Intrinsics
from core.state import SceneState

KERNELS = (
    "core.grounding_kernel.mask_points",
    "core.occupancy_evidence._lower_usable_medians",
    "core.occupancy_evidence._marked_cells",
    "core.visibility._windows",
    "core.visibility._bbox_area",
)


def synthetic_batch(batch_id: str) -> Batch:
    """A camera 1.5 m above the floor looking down at a box on it: one object mask."""
    width, height = 80, 60
    intrinsics = Intrinsics(width, height, 70.0, 70.0, width / 2 - 0.5, height / 2 - 0.5)
    depth = np.full((height, width), 1.5, np.float32)
    depth[20:40, 30:50] = 1.4
    mask = np.zeros((height, width), bool)
    mask[22:38, 32:48] = True
    pose = np.eye(4)
    pose[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking straight down
    pose[2, 3] = 1.5
    embedding = np.linspace(-1.0, 1.0, 16)
    detection = Detection("box", 0.9, "object", Mask.from_array(mask), embedding)
    return Batch(batch_id, (Frame(f"{batch_id}-f", 0.0, intrinsics, pose, depth, (detection,)),))


def compile_kernels() -> float:
    """Run every kernel once (compiling it, or loading it from the cache); seconds taken."""
    started = time.perf_counter()
    state = SceneState()
    for batch_id in ("warm-up-1", "warm-up-2"):  # the second sees the first's track
        state = fold(state, decide(state, synthetic_batch(batch_id)))
    return time.perf_counter() - started


if __name__ == "__main__":
    print(f"numba kernels ready in {compile_kernels():.1f} s")
