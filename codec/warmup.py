"""Compile the codec's numba kernel ahead of the first batch, as `core.warmup` does the
method's: the container image runs `python -m codec.warmup` at build time."""

from __future__ import annotations

import time

from codec.rle import compressed_rle_counts

KERNELS = ("codec.rle._runs_of",)


def compile_kernels() -> float:
    """Run every kernel once (compiling it, or loading it from the cache); seconds taken."""
    started = time.perf_counter()
    compressed_rle_counts("0421")  # a mask of 0, 4, 2 and 1 pixel runs
    return time.perf_counter() - started


if __name__ == "__main__":
    print(f"numba kernels ready in {compile_kernels():.1f} s")
