"""`core.warmup.compile_kernels` reaches every numba kernel it names, so that the container image
(and `python -m core.warmup`) leaves none of them to compile on the first real batch."""

from __future__ import annotations

import importlib

from core.warmup import KERNELS, compile_kernels


def test_the_warm_up_compiles_every_kernel_it_names() -> None:
    assert compile_kernels() > 0
    for name in KERNELS:
        module, function = name.rsplit(".", 1)
        assert getattr(importlib.import_module(module), function).signatures, name
