"""Tests of the simulator and the evaluation need the `eval` extra, tests of `pbdag ingest` the
`ingest` extra; without them they skip, saying so (a service-only install runs tests/service and
tests/core)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import pytest

from evaluation.cli import missing_eval_distributions
from ingest.cli import missing_ingest_extra


def missing_reason() -> str | None:
    """Why the eval extra's tests cannot run here, or None when they can."""
    missing = missing_eval_distributions()
    if not missing:
        return None
    return f"needs the eval extra (missing {', '.join(missing)}): pip install -e '.[eval]'"


def require_eval_extra() -> None:
    """Skip the calling test module when the extra is not installed."""
    reason = missing_reason()
    if reason is not None:
        pytest.skip(reason, allow_module_level=True)


class NeedsEvalExtra(pytest.File):
    """A test module that is not imported (its imports need the extra): it reports a skip."""

    def collect(self) -> Iterable[pytest.Item]:
        """Skip, with the reason."""
        pytest.skip(missing_reason() or "needs the eval extra")


def skip_modules_without_eval_extra(
    module_path: Path, parent: pytest.Collector
) -> pytest.File | None:
    """A conftest's `pytest_pycollect_makemodule`: every module of its directory skips without
    the extra (None: pytest collects the module as usual)."""
    if missing_reason() is None:
        return None
    return NeedsEvalExtra.from_parent(parent, path=module_path)


def ingest_missing_reason() -> str | None:
    """Why the ingest extra's tests cannot run here, or None when they can."""
    missing = missing_ingest_extra()
    if not missing:
        return None
    return f"needs the ingest extra (missing {', '.join(missing)}): pip install -e '.[ingest]'"


class NeedsIngestExtra(pytest.File):
    """A test module that is not imported (its imports need rosbags): it reports a skip."""

    def collect(self) -> Iterable[pytest.Item]:
        """Skip, with the reason."""
        pytest.skip(ingest_missing_reason() or "needs the ingest extra")


def skip_modules_without_ingest_extra(
    module_path: Path, parent: pytest.Collector
) -> pytest.File | None:
    """A conftest's `pytest_pycollect_makemodule`: every module of its directory skips without
    the ingest extra (None: pytest collects the module as usual)."""
    if ingest_missing_reason() is None:
        return None
    return NeedsIngestExtra.from_parent(parent, path=module_path)
