"""`core.warmup.compile_kernels` and `codec.warmup.compile_kernels` reach every numba kernel
they name, so that the container image (and `python -m core.warmup`, `python -m codec.warmup`)
leaves none of them to compile on the first real batch."""

from __future__ import annotations

import importlib
from types import ModuleType

import pytest

import codec.warmup
import core.warmup


@pytest.mark.parametrize("warmup", [core.warmup, codec.warmup], ids=lambda m: m.__name__)
def test_the_warm_up_compiles_every_kernel_it_names(warmup: ModuleType) -> None:
    assert warmup.compile_kernels() > 0
    for name in warmup.KERNELS:
        module, function = name.rsplit(".", 1)
        assert getattr(importlib.import_module(module), function).signatures, name
