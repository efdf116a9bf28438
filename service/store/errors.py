"""The store's own exceptions; driver errors are translated into these at the adapter."""

from __future__ import annotations

from core.errors import PbdagError


class StoreError(PbdagError):
    """Base of store errors."""


class ConcurrencyConflict(StoreError):
    """The scene's head moved since the caller read it: nothing was appended."""


class LeaseLost(StoreError):
    """The batch's lease expired or moved to another worker: the append was rolled back."""


class NonFiniteEvent(StoreError):
    """An event holds NaN or infinity: it could never be replayed, so it is never stored."""


class BatchConflict(StoreError):
    """A batch id was posted again with different content."""

    def __init__(self, detail: str) -> None:
        super().__init__(detail, "batch_id")


class SceneNotFound(StoreError):
    """No scene with this id."""

    def __init__(self, scene_id: str) -> None:
        super().__init__(f"scene {scene_id!r} does not exist", "scene_id")
        self.scene_id = scene_id


class SeqOutOfRange(StoreError):
    """as_of beyond the scene's head."""

    def __init__(self, detail: str) -> None:
        super().__init__(detail, "as_of")
