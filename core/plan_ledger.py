"""What the log says of inspection planning (section 3.4): the locked target and its view, and
each fixture's failed views; folded from `inspection_targeted` and inspection events."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from core.values import ViewPose


@dataclass(frozen=True)
class InspectionLock:
    """The locked inspection target (section 3.4): the fixture, its view, the event's seq."""

    fixture_id: str
    view: ViewPose
    pitch: float
    seq: int


@dataclass(frozen=True)
class PlanLedger:
    """What the log says of inspection planning: the lock, and each fixture's failures."""

    lock: InspectionLock | None = None
    locks: int = 0  # inspection_targeted events so far
    failed_views: Mapping[str, tuple[ViewPose, ...]] = field(default_factory=dict)
    # The value of `locks` when the fixture's last capture failed (the retry cooldown).
    failed_at_lock: Mapping[str, int] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (snapshots)."""
        lock = self.lock
        return {
            "lock": None
            if lock is None
            else {
                "fixture_id": lock.fixture_id,
                "view": lock.view.to_dict(),
                "pitch": lock.pitch,
                "seq": lock.seq,
            },
            "locks": self.locks,
            "failed_views": {
                key: [v.to_dict() for v in views]
                for key, views in sorted(self.failed_views.items())
            },
            "failed_at_lock": dict(sorted(self.failed_at_lock.items())),
        }

    @classmethod
    def from_dict(cls, record: Mapping[str, Any]) -> PlanLedger:
        """Inverse of `to_dict`."""
        lock = record["lock"]
        return cls(
            lock=None
            if lock is None
            else InspectionLock(
                lock["fixture_id"],
                ViewPose.from_dict(lock["view"]),
                float(lock["pitch"]),
                int(lock["seq"]),
            ),
            locks=int(record["locks"]),
            failed_views={
                key: tuple(ViewPose.from_dict(v) for v in views)
                for key, views in record["failed_views"].items()
            },
            failed_at_lock={key: int(v) for key, v in record["failed_at_lock"].items()},
        )
