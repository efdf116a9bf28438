"""Runner hooks: what a baseline does between batches that the core's update rules do not.

A hook object lives for one run. After every batch the runner shows it the batch's events and
lets it maintain the memory (periodic merging, pruning) by returning more core events, which are
folded like any others; it also filters which tracks the graph publishes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from core.events import Event
from core.state import SceneState, Track


class RunnerHooks(Protocol):
    """Per-run maintenance of a baseline."""

    def after_batch(
        self, state: SceneState, events: Sequence[Event], last_frame: int
    ) -> list[Event]:
        """Events that maintain the memory after this batch (folded by the runner)."""
        ...

    def publishable(self, track: Track) -> bool:
        """Whether a track the core publishes is in this method's graph."""
        ...
