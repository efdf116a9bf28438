""" "Why was this object removed?": the answer from the track's events alone."""

from __future__ import annotations

from collections.abc import Sequence

from api_schema import Explanation, Removal, VisibleMiss
from service.routes.events import event_out
from service.store.event_log import StoredEvent


def explain(track_id: str, events: Sequence[StoredEvent]) -> Explanation:
    """The track's history, and for a removal the visible misses that led to it."""
    last = events[-1]
    state = last.state or "unknown"
    label = _label(events)
    removal = _removal(events) if state == "removed" else None
    if removal is not None:
        summary = (
            f"{track_id} ({label}) was removed at seq {removal.seq} (frame {removal.frame_id}): "
            f"after {len(removal.visible_misses)} visibility-admissible misses in a row, "
            f"p_exist fell to {removal.p_exist:.3f}."
        )
    else:
        seen = [
            e
            for e in events
            if e.type in ("add", "update") and e.details.get("evidence") == "observed"
        ]
        where = f", last observed in frame {seen[-1].frame_id} (seq {seen[-1].seq})" if seen else ""
        p_exist = next(
            (e.details["p_exist"] for e in reversed(events) if "p_exist" in e.details), None
        )
        chance = f" with p_exist {p_exist:.3f}" if p_exist is not None else ""
        summary = f"{track_id} ({label}) is {state}{chance}{where}."
    return Explanation(
        track_id=track_id,
        state=state,
        summary=summary,
        events=[event_out(e) for e in events],
        removal=removal,
    )


def _label(events: Sequence[StoredEvent]) -> str:
    """The label most observations gave."""
    counts: dict[str, int] = {}
    for event in events:
        for observation in event.details.get("observations", ()):
            counts[observation["label"]] = counts.get(observation["label"], 0) + 1
    return min(counts.items(), key=lambda item: (-item[1], item[0]))[0] if counts else "unknown"


def _removal(events: Sequence[StoredEvent]) -> Removal | None:
    """The last `remove` and the misses since the last positive observation before it."""
    removal_index = max((i for i, e in enumerate(events) if e.type == "remove"), default=None)
    if removal_index is None:
        return None
    misses: list[VisibleMiss] = []
    for event in reversed(events[:removal_index]):
        if event.type == "add" or event.details.get("evidence") == "observed":
            break
        if event.details.get("evidence") == "visible_miss":
            misses.append(
                VisibleMiss(
                    seq=event.seq,
                    frame_id=event.frame_id,
                    samples_passed=int(event.details["samples_passed"]),
                    p_exist_after=float(event.details["p_exist"]),
                )
            )
    removed = events[removal_index]
    return Removal(
        seq=removed.seq,
        frame_id=removed.frame_id,
        p_exist=float(removed.details["p_exist"]),
        visible_misses=list(reversed(misses)),
    )
