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


class UnreadableEvent(StoreError):
    """A stored event that cannot be decoded (written by an older version that let NaN through)."""

    def __init__(self, seq: int, reason: str) -> None:
        super().__init__(
            f"event {seq} cannot be read ({reason}); `pbdag repair` quarantines the scene and "
            "rebuilds it as a new scene from the events before it",
        )
        self.seq = seq
        self.reason = reason


class SceneQuarantined(StoreError):
    """The scene was quarantined by `pbdag repair`: it takes no writes, its state is not served."""

    def __init__(self, scene_id: str, reason: str) -> None:
        super().__init__(f"scene {scene_id!r} is quarantined: {reason}", "scene_id")
