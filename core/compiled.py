"""The decorator of the method's numba kernels: compiled without the GIL, cached when it can be.

numba caches a kernel's machine code beside its module, or under the user's cache directory, or
under `NUMBA_CACHE_DIR`; where none of them is writable it refuses `cache=True` when the module
is imported. A kernel is then compiled without its cache (on its first call in every process,
about 7 s for all of them), rather than the service failing to start.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any, Literal, TypeVar, cast

import numba

Function = TypeVar("Function", bound=Callable[..., Any])

logger = logging.getLogger(__name__)


def compiled(*, inline: Literal["never", "always"] = "never") -> Callable[[Function], Function]:
    """`numba.njit(cache=True, nogil=True, inline=inline)`, without the cache where numba has
    nowhere to write it."""

    def decorate(function: Function) -> Function:
        try:
            kernel: Any = numba.njit(cache=True, nogil=True, inline=inline)(function)
        except RuntimeError as error:  # "cannot cache function ...: no locator available"
            logger.warning("numba kernel %s not cached: %s", function.__qualname__, error)
            kernel = numba.njit(nogil=True, inline=inline)(function)
        return cast(Function, kernel)

    return decorate
