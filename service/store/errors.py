"""The store's own exceptions; driver errors are translated into these at the adapter."""

from __future__ import annotations


class StoreError(Exception):
    """Base of store errors."""


class ConcurrencyConflict(StoreError):
    """The scene's head moved since the caller read it: nothing was appended."""


class LeaseLost(StoreError):
    """The batch's lease expired or moved to another worker: the append was rolled back."""


class BatchConflict(StoreError):
    """A batch id was posted again with different content."""


class SceneNotFound(StoreError):
    """No scene with this id."""

    def __init__(self, scene_id: str) -> None:
        super().__init__(f"scene {scene_id!r} does not exist")
        self.scene_id = scene_id


class SeqOutOfRange(StoreError):
    """as_of beyond the scene's head."""
