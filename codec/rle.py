"""COCO's compressed RLE strings (pycocotools' `rleFrString`), decoded without pycocotools."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

# Characters of COCO's compressed RLE: 6-bit groups stored as chr(48 + group).
_RLE_FIRST_CHAR = 48
_RLE_LAST_CHAR = 48 + 63
_RLE_MORE = 0x20  # continuation bit of a 6-bit group
_RLE_SIGN = 0x10  # sign bit of a value's last group
# Six 5-bit groups hold any signed count of a mask up to 8192 x 8192 pixels.
_RLE_MAX_GROUPS = 6


def compressed_rle_counts(counts: str) -> npt.NDArray[np.int64]:
    """Run lengths of a compressed COCO RLE string (pycocotools' `rleFrString`, vectorized).

    Raises ValueError with a plain reason when the string is not a valid encoding.
    """
    try:
        codes = np.frombuffer(counts.encode("ascii"), dtype=np.uint8)
    except UnicodeEncodeError:
        raise ValueError("compressed RLE must be ASCII") from None
    if codes.size == 0:
        raise ValueError("compressed RLE is empty")
    if codes.min() < _RLE_FIRST_CHAR or codes.max() > _RLE_LAST_CHAR:
        raise ValueError("compressed RLE contains characters outside '0'..'o'")
    groups = codes.astype(np.int64) - _RLE_FIRST_CHAR
    is_last_group = (groups & _RLE_MORE) == 0
    if not is_last_group[-1]:
        raise ValueError("compressed RLE ends in the middle of a value")
    value_ends = np.flatnonzero(is_last_group)
    value_starts = np.concatenate(([0], value_ends[:-1] + 1))
    group_counts = value_ends - value_starts + 1
    if group_counts.max() > _RLE_MAX_GROUPS:
        raise ValueError("compressed RLE contains a value too large for any mask")
    group_position = np.arange(groups.size) - np.repeat(value_starts, group_counts)
    values = np.add.reduceat((groups & 0x1F) << (5 * group_position), value_starts)
    is_negative = (groups[value_ends] & _RLE_SIGN) != 0
    values = np.where(is_negative, values - (1 << (5 * group_counts)), values)
    # From the fourth value on, each is stored as a delta to the value two places back.
    runs = values.copy()
    runs[1::2] = np.cumsum(values[1::2])
    runs[2::2] = np.cumsum(values[2::2])
    if (runs < 0).any():
        raise ValueError("compressed RLE decodes to a negative run length")
    return runs
