"""`pbdag gc` that SIGKILLs itself at one step, for the fault tests (run as a module):

    python -m tests.service.gc_killer STEP

STEP is `marking` (before the rows are marked), `deleting` (after the rows are marked, before
any blob is deleted) or `deleted-one` (after the first blob is deleted). The store comes from
PBDAG_DATABASE_URL and PBDAG_DATA_DIR, as for `pbdag gc`.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from typing import Any

import sqlalchemy as sa

from service.bootstrap import build_container
from service.retention import collect


def killed(*_args: Any, **_kwargs: Any) -> Any:
    os.kill(os.getpid(), signal.SIGKILL)


def main(step: str) -> None:
    container = build_container()
    queue, blobs = container.queue, container.blobs
    if step == "marking":
        queue.mark_collected = killed  # type: ignore[method-assign]
    elif step == "deleting":
        blobs.delete = killed  # type: ignore[method-assign]
    elif step == "deleted-one":
        original = blobs.delete

        def delete_once(key: str, connection: sa.Connection | None = None) -> bool:
            blobs.delete = killed  # type: ignore[method-assign]
            return original(key, connection)

        blobs.delete = delete_once  # type: ignore[method-assign]
    else:
        raise SystemExit(f"unknown step {step!r}")
    collect(container, 0.0, clock=lambda: time.time() + 10)
    raise SystemExit("gc finished: the kill never came")


if __name__ == "__main__":
    main(sys.argv[1])
