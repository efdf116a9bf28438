"""The store's own exceptions; driver and file-system errors are translated into these at the
adapter (`service.store.engine` for the database, `service.store.blobs` for blobs).

Two kinds, as everywhere (`pbdag_errors`): what the store refuses (an unknown scene, a head that
moved, a batch id reused with other content...) and how it fails (`StoreError`: the database or
the blob store unavailable, a lease lost, an event that could never be replayed).
"""

from __future__ import annotations

from core.errors import NotFound
from pbdag_errors import Failure, Refused


class StoreError(Failure):
    """Base of the store's failures: nothing the caller did wrong."""


class StoreUnavailable(StoreError):
    """The database or the blob store could not answer (a lost connection, a lock held too long,
    a disk error): the same request may succeed later."""

    def __init__(self, what: str, cause: BaseException) -> None:
        driver = getattr(cause, "orig", None) or cause  # SQLAlchemy's wraps the driver's
        reason = (str(driver).strip().splitlines() or [""])[0][:200]  # never its SQL
        super().__init__(f"{what} failed ({type(cause).__name__}: {reason})")
        self.cause_name = type(cause).__name__  # for the short message a batch keeps


class LeaseLost(StoreError):
    """The batch's lease expired or moved to another worker: the append was rolled back."""


class NonFiniteEvent(StoreError):
    """An event holds NaN or infinity: it could never be replayed, so it is never stored."""


class ConcurrencyConflict(Refused):
    """The scene's head moved since the caller read it: nothing was appended."""


class BatchConflict(Refused):
    """A batch id was posted again with different content."""

    def __init__(self, detail: str) -> None:
        super().__init__(detail, "batch_id")


class SceneNotFound(NotFound):
    """No scene with this id."""

    def __init__(self, scene_id: str) -> None:
        super().__init__("scene", scene_id, "scene_id")
        self.scene_id = scene_id


class SeqOutOfRange(Refused):
    """as_of beyond the scene's head, or an as_of_time before its first batch."""

    def __init__(self, detail: str, field: str = "as_of") -> None:
        super().__init__(detail, field)


class UnreadableEvent(Refused):
    """A stored event that cannot be decoded (written by an older version that let NaN through):
    the scene's reads are refused until an operator repairs it."""

    def __init__(self, seq: int, reason: str) -> None:
        super().__init__(
            f"event {seq} cannot be read ({reason}); `pbdag repair` quarantines the scene and "
            "rebuilds it as a new scene from the events before it",
        )
        self.seq = seq
        self.reason = reason


class SceneQuarantined(Refused):
    """The scene was quarantined by `pbdag repair`: it takes no writes, its state is not served."""

    def __init__(self, scene_id: str, reason: str) -> None:
        super().__init__(f"scene {scene_id!r} is quarantined: {reason}", "scene_id")
