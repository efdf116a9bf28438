"""`core.compiled.compiled`: a kernel whose cache numba cannot write is compiled without it, and
still computes (the service starts where neither the code nor the home directory is writable)."""

from __future__ import annotations

import logging
from typing import Any

import numba
import pytest

from core.compiled import compiled


def test_a_kernel_numba_cannot_cache_is_compiled_without_its_cache(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    real_njit = numba.njit

    def njit_without_locator(*args: Any, cache: bool = False, **kwargs: Any) -> Any:
        if cache:
            raise RuntimeError("cannot cache function 'twice': no locator available for file")
        return real_njit(*args, **kwargs)

    monkeypatch.setattr(numba, "njit", njit_without_locator)  # as core.compiled calls it

    def twice(value: float) -> float:
        return 2.0 * value

    with caplog.at_level(logging.WARNING, logger="core.compiled"):
        kernel = compiled()(twice)
    assert kernel(2.5) == 5.0
    assert kernel.signatures  # type: ignore[attr-defined]  # compiled, by numba
    assert "not cached" in caplog.text


def test_a_kernel_is_cached_where_it_can_be() -> None:
    def thrice(value: float) -> float:
        return 3.0 * value

    kernel = compiled()(thrice)
    assert kernel(2.0) == 6.0
    assert kernel._cache.__class__.__name__ == "FunctionCache"  # type: ignore[attr-defined]
