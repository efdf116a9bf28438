"""From one batch's evidence about one track to its events (section 3.3, lifecycle and audit)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from core.belief import update_existence
from core.events import (
    Event,
    TrackAdded,
    TrackConfirmed,
    TrackDemoted,
    TrackMoved,
    TrackRemoved,
    TrackReparented,
    TrackUpdated,
    VerificationRequested,
)
from core.fixtures import FixtureProposal, ema_center
from core.geometry import Proposal
from core.lifecycle import moved_distance, should_confirm, should_demote, should_move, should_remove
from core.params import Params
from core.state import Track, Vec3, logistic


def _vec(values: Any) -> list[float]:
    return [float(v) for v in values]


def _top(evidence: Mapping[str, float], current: str | None = None) -> str | None:
    """Most supported key; the current one keeps ties, then names decide."""
    if not evidence:
        return None
    best = max(evidence.values())
    if current is not None and evidence.get(current) == best:
        return current
    return min(key for key, weight in evidence.items() if weight == best)


# -- objects ---------------------------------------------------------------------------------


def object_details(
    track: Track | None, proposals: Sequence[Proposal], parents: Sequence[str | None]
) -> dict[str, Any]:
    """The batch's observations of one object track, as evolve needs them."""
    dim = (
        len(track.embedding_sum) if track is not None and track.embedding_sum is not None else None
    )
    embeddings = [p.embedding for p in proposals if p.embedding is not None]
    if dim is None and embeddings:
        dim = embeddings[0].shape[0]
    embeddings = [e for e in embeddings if e.shape[0] == dim]
    return {
        "evidence": "observed",
        "observations": [
            {
                "frame_id": p.frame_id,
                "label": p.label,
                "score": float(p.score),
                "center": _vec(p.center),
                "extent": _vec(p.extent),
                "valid_pixels": p.valid_pixels,
                "parent": parent,
            }
            for p, parent in zip(proposals, parents, strict=True)
        ],
        "embedding_sum": _vec(np.sum(embeddings, axis=0)) if embeddings else None,
        "embedding_count": len(embeddings),
        "timestamp": float(proposals[-1].timestamp),
    }


def _support_events(
    track_id: str, lifecycle: str, frame_id: str, old_parent: str | None, evidence: dict[str, float]
) -> list[Event]:
    """A valid support change emits `reparent` naming the old and the new parent."""
    new_parent = _top(evidence, old_parent)
    if new_parent is None or new_parent == old_parent:
        return []
    return [
        TrackReparented(
            track_id, lifecycle, frame_id, {"old_parent": old_parent, "new_parent": new_parent}
        )
    ]


def first_sighting(kind: str, params: Params) -> dict[str, Any]:
    """Existence of a new hypothesis: the prior plus one positive observation (equation (3))."""
    logodds = update_existence(params.existence.prior_logodds, params.existence, observed=True)
    return {
        "kind": kind,
        "existence_logodds": logodds,
        "p_exist": logistic(logodds),
        "batches_observed": 1,
    }


def added_object(
    track_id: str, proposals: Sequence[Proposal], parents: Sequence[str | None], params: Params
) -> list[Event]:
    """A new hypothesis (`add`), and its first support."""
    evidence = _parent_evidence({}, parents, params)
    details = object_details(None, proposals, parents)
    details.update(first_sighting("object", params), parent_evidence=evidence)
    logodds = details["existence_logodds"]
    frame_id = proposals[0].frame_id
    emitted: list[Event] = [TrackAdded(track_id, "tentative", frame_id, details)]
    lifecycle = "tentative"
    p_exist = logistic(logodds)
    if should_confirm(lifecycle, p_exist, 1, params.lifecycle):  # only when one batch may publish
        lifecycle = "confirmed"
        center = _vec(proposals[-1].center)
        emitted.append(
            TrackConfirmed(
                track_id,
                lifecycle,
                frame_id,
                {"p_exist": p_exist, "center": center, "batches_observed": 1},
            )
        )
    return [*emitted, *_support_events(track_id, lifecycle, frame_id, None, evidence)]


def _parent_evidence(
    previous: Mapping[str, float], parents: Sequence[str | None], params: Params
) -> dict[str, float]:
    evidence = dict(previous)
    for parent in parents:
        if parent is not None:
            evidence[parent] = evidence.get(parent, 0.0) + params.fusion.observation_evidence_weight
    return evidence


def observed_object(
    track: Track, proposals: Sequence[Proposal], parents: Sequence[str | None], params: Params
) -> list[Event]:
    """A positive batch: `update`, then `confirm`, `move` and `reparent` as they apply."""
    frame_id = proposals[-1].frame_id
    lifecycle_params = params.lifecycle
    reacquired, logodds, p_exist, batches, lifecycle = positive_batch(track, params)
    center: Vec3 = (
        float(proposals[-1].center[0]),
        float(proposals[-1].center[1]),
        float(proposals[-1].center[2]),
    )
    # Evidence about the old support is stale once the object was relocated.
    relocated = reacquired or should_move(track.published_center, center, lifecycle_params)
    evidence = _parent_evidence({} if relocated else track.parent_evidence, parents, params)
    details = object_details(track, proposals, parents)
    details.update(
        existence_logodds=logodds,
        p_exist=p_exist,
        batches_observed=batches,
        reacquired=reacquired,
        parent_evidence=evidence,
    )
    emitted: list[Event] = [TrackUpdated(track.track_id, lifecycle, frame_id, details)]
    if should_confirm(lifecycle, p_exist, batches, lifecycle_params):
        lifecycle = "confirmed"
        emitted.append(
            TrackConfirmed(
                track.track_id,
                lifecycle,
                frame_id,
                {"p_exist": p_exist, "center": list(center), "batches_observed": batches},
            )
        )
    emitted.extend(_move_events(track, lifecycle, frame_id, center, params))
    emitted.extend(_support_events(track.track_id, lifecycle, frame_id, track.parent, evidence))
    return emitted


def positive_batch(track: Track, params: Params) -> tuple[bool, float, float, int, str]:
    """Equation (3) for a matched track: (re-acquired, log-odds, p_exist, batches, lifecycle).

    A removed track that is re-acquired keeps its identity and restarts as a hypothesis.
    """
    existence = params.existence
    reacquired = track.lifecycle == "removed"
    prior = existence.prior_logodds if reacquired else track.existence_logodds
    logodds = update_existence(prior, existence, observed=True)
    batches = 1 if reacquired else track.batches_observed + 1
    return (
        reacquired,
        logodds,
        logistic(logodds),
        batches,
        "tentative" if reacquired else track.lifecycle,
    )


def _move_events(
    track: Track, lifecycle: str, frame_id: str, center: Vec3, params: Params
) -> list[Event]:
    if lifecycle != "confirmed" or not should_move(
        track.published_center, center, params.lifecycle
    ):
        return []
    assert track.published_center is not None
    return [
        TrackMoved(
            track.track_id,
            lifecycle,
            frame_id,
            {
                "from": list(track.published_center),
                "to": list(center),
                "distance": moved_distance(track.published_center, center),
            },
        )
    ]


def visible_miss(
    track: Track, samples: int, frame_id: str, params: Params, removal: bool = True
) -> list[Event]:
    """An unmatched, visible track: one miss (equation (3)), then `demote` / `remove` as they apply."""
    existence, lifecycle_params = params.existence, params.lifecycle
    logodds = update_existence(track.existence_logodds, existence, visible_miss=True)
    p_exist = logistic(logodds)
    misses = track.visible_misses + 1
    details = {
        "evidence": "visible_miss",
        "samples_passed": samples,
        "samples_total": params.visibility.box_samples_per_axis**3,
        "existence_logodds": logodds,
        "p_exist": p_exist,
        "visible_misses": misses,
    }
    lifecycle = track.lifecycle
    emitted: list[Event] = [TrackUpdated(track.track_id, lifecycle, frame_id, details)]
    if not removal:  # an append-only memory never resolves a disappearance
        return emitted
    if not track.pinned and should_demote(
        lifecycle, p_exist, lifecycle_params
    ):  # pinned: never unpublished
        lifecycle = "demoted"
        emitted.append(TrackDemoted(track.track_id, lifecycle, frame_id, {"p_exist": p_exist}))
    if should_remove(lifecycle, p_exist, misses, track.pinned, lifecycle_params):
        lifecycle = "removed"
        emitted.append(
            TrackRemoved(
                track.track_id, lifecycle, frame_id, {"p_exist": p_exist, "visible_misses": misses}
            )
        )
    return emitted


# -- fixtures --------------------------------------------------------------------------------


def fixture_details(proposal: FixtureProposal, center: Vec3, batch_frame: str) -> dict[str, Any]:
    """One cluster's evidence for a fixture track, with the EMA center evolve stores."""
    return {
        "evidence": "observed",
        "observations": [
            {
                "frame_id": proposal.best_frame or batch_frame,
                "label": proposal.label,
                "score": proposal.mean_score,
                "center": _vec(proposal.center),
                "extent": _vec(proposal.extent),
                "valid_pixels": proposal.voxel_count,
                "parent": None,
            }
        ],
        "center": list(center),
        "margin": proposal.margin,
        "best_frame": proposal.best_frame,
        "best_frame_support": proposal.contributed,
        "embedding_sum": None,
        "embedding_count": 0,
    }


def added_fixture(
    track_id: str, proposal: FixtureProposal, batch_frame: str, timestamp: float, params: Params
) -> list[Event]:
    """A new coarse fixture hypothesis."""
    center: Vec3 = (float(proposal.center[0]), float(proposal.center[1]), float(proposal.center[2]))
    details = fixture_details(proposal, center, batch_frame)
    details.update(first_sighting("fixture", params), timestamp=timestamp)
    return [TrackAdded(track_id, "tentative", proposal.best_frame or batch_frame, details)]


def observed_fixture(
    track: Track, proposal: FixtureProposal, batch_frame: str, timestamp: float, params: Params
) -> list[Event]:
    """Support from one more batch: `update`, then promotion or a verification request."""
    if track.verification == "rejected":
        return []  # a retired hypothesis explains its cluster and stays retired
    reacquired, logodds, p_exist, batches, lifecycle = positive_batch(track, params)
    center = (
        (float(proposal.center[0]), float(proposal.center[1]), float(proposal.center[2]))
        if reacquired
        else ema_center(track.center, proposal.center, params.fusion.fixture_center_alpha)
    )
    frame_id = proposal.best_frame or batch_frame
    details = fixture_details(proposal, center, batch_frame)
    details.update(
        existence_logodds=logodds,
        p_exist=p_exist,
        batches_observed=batches,
        reacquired=reacquired,
        timestamp=timestamp,
    )
    if proposal.contributed <= track.best_frame_support:
        details.update(best_frame=track.best_frame, best_frame_support=track.best_frame_support)
    emitted: list[Event] = [TrackUpdated(track.track_id, lifecycle, frame_id, details)]
    # Promotion: several distinct batches, then the consensus gate or one verification.
    class_evidence = dict(track.class_evidence)
    class_evidence[proposal.label] = (
        class_evidence.get(proposal.label, 0.0) + params.fusion.observation_evidence_weight
    )
    label = _top(class_evidence) or proposal.label
    agreement = class_evidence[label] / sum(class_evidence.values())
    mean_margin = (track.margin_sum + proposal.margin) / max(batches, 1)
    fixture_params = params.fixtures
    ready = (
        lifecycle in ("tentative", "demoted")
        and batches >= fixture_params.confirm_min_batches
        and p_exist >= params.lifecycle.confirm_min_p_exist
    )
    consensus = (
        agreement >= fixture_params.consensus_min_agreement
        and mean_margin >= fixture_params.consensus_min_margin
    )
    if ready and (consensus or track.verification == "confirmed"):
        lifecycle = "confirmed"
        emitted.append(
            TrackConfirmed(
                track.track_id,
                lifecycle,
                frame_id,
                {
                    "p_exist": p_exist,
                    "center": list(center),
                    "batches_observed": batches,
                    "consensus": consensus,
                },
            )
        )
    elif ready and track.verification is None:
        total = sum(class_evidence.values())
        emitted.append(
            VerificationRequested(
                track.track_id,
                lifecycle,
                frame_id,
                {
                    # What a verifier needs: each class's mean similarity over the cluster,
                    # and how the supporting batches voted.
                    "candidates": dict(
                        sorted(proposal.class_means.items(), key=lambda item: -item[1])
                    ),
                    "batch_votes": {
                        name: weight / total for name, weight in sorted(class_evidence.items())
                    },
                    "agreement": agreement,
                    "mean_margin": mean_margin,
                    "batches_observed": batches,
                    "best_frame": details["best_frame"],
                },
            )
        )
    emitted.extend(_move_events(track, lifecycle, frame_id, center, params))
    return emitted


def fixture_verdict_logodds(track: Track, confirm: bool, params: Params) -> float:
    """Equation (3) with a cached confirmation (eta_c) or rejection (eta_r)."""
    return update_existence(
        track.existence_logodds, params.existence, confirmed=confirm, rejected=not confirm
    )
