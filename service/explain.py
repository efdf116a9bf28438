""" "Why was this object removed?": the answer from the track's events alone."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence

from api_schema import Explanation, Removal, VisibleMiss
from core.events import Event, Sighting, TrackRemoved
from core.events import VisibleMiss as MissEvent
from service.store.event_log import StoredEvent
from service.wire import event_out


def explain(
    track_id: str, stored: Sequence[StoredEvent], *, with_events: bool = False
) -> Explanation:
    """The sentence and the misses since the last sighting (for a removal, those that led to
    it); the track's events too `with_events`."""
    events = [(row.seq, row.to_core()) for row in stored]
    last = events[-1][1]
    state = last.state or "unknown"
    label = _label(event for _seq, event in events)
    removal = _removal(events) if state == "removed" else None
    if removal is not None:
        summary = (
            f"{track_id} ({label}) was removed at seq {removal.seq} (frame {removal.frame_id}): "
            f"after {len(removal.visible_misses)} visibility-admissible misses in a row, "
            f"p_exist fell to {removal.p_exist:.3f}."
        )
    else:
        seen = [(seq, event) for seq, event in events if isinstance(event, Sighting)]
        where = (
            f", last observed in frame {seen[-1][1].frame_id} (seq {seen[-1][0]})" if seen else ""
        )
        p_exist = next((e.p_exist for _s, e in reversed(events) if hasattr(e, "p_exist")), None)
        chance = f" with p_exist {p_exist:.3f}" if p_exist is not None else ""
        summary = f"{track_id} ({label}) is {state}{chance}{where}."
    return Explanation(
        track_id=track_id,
        state=state,
        summary=summary,
        visible_misses=_misses_before(events, len(events)),
        removal=removal,
        events=[event_out(row) for row in stored] if with_events else None,
    )


def _label(events: Iterable[Event]) -> str:
    """The label most observations gave."""
    counts = Counter(
        observation.label
        for event in events
        if isinstance(event, Sighting)
        for observation in event.observations
    )
    return min(counts.items(), key=lambda item: (-item[1], item[0]))[0] if counts else "unknown"


def _removal(events: Sequence[tuple[int, Event]]) -> Removal | None:
    """The last `remove` and the misses since the last positive observation before it."""
    index = max(
        (i for i, (_s, e) in enumerate(events) if isinstance(e, TrackRemoved)), default=None
    )
    if index is None:
        return None
    seq, removed = events[index]
    assert isinstance(removed, TrackRemoved)
    return Removal(
        seq=seq,
        frame_id=removed.frame_id,
        p_exist=removed.p_exist,
        visible_misses=_misses_before(events, index),
    )


def _misses_before(events: Sequence[tuple[int, Event]], index: int) -> list[VisibleMiss]:
    """The visible misses among events[:index] since the last positive observation, oldest
    first."""
    misses: list[VisibleMiss] = []
    for seq, event in reversed(events[:index]):
        if isinstance(event, Sighting):
            break
        if isinstance(event, MissEvent):
            misses.append(
                VisibleMiss(
                    seq=seq,
                    frame_id=event.frame_id,
                    samples_passed=event.samples_passed,
                    p_exist_after=event.p_exist,
                )
            )
    return list(reversed(misses))
