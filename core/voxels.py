"""Voxel keys packed into one int64, so voxel sets are merged and looked up as 1-D arrays."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

IntArray = npt.NDArray[np.int64]
BITS = 21  # +-1M voxels per axis: +-52 km at 5 cm
OFFSET = 1 << (BITS - 1)
MASK = (1 << BITS) - 1


def pack(keys: IntArray) -> IntArray:
    """(n, 3) integer voxel keys -> (n,) int64."""
    shifted = keys.astype(np.int64) + OFFSET
    packed: IntArray = (shifted[:, 0] << (2 * BITS)) | (shifted[:, 1] << BITS) | shifted[:, 2]
    return packed


def unpack(packed: IntArray) -> IntArray:
    """Inverse of `pack`."""
    keys = np.stack(((packed >> (2 * BITS)) & MASK, (packed >> BITS) & MASK, packed & MASK), axis=1)
    unpacked: IntArray = keys - OFFSET
    return unpacked
