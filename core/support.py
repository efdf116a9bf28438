"""Support-parent evidence from geometry (section 3.3, p_parent): what an object rests on."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from core.fixture_association import footprint_of
from core.fixtures import FixtureProposal, ema_center
from core.geometry import Proposal
from core.graph import is_published
from core.params import FixtureParams, Params
from core.state import SceneState, Track
from core.values import vec3


@dataclass(frozen=True)
class SupportSurface:
    """A fixture's top surface: its identity, planar box and top height."""

    track_id: str
    center: tuple[float, float, float]
    extent: tuple[float, float, float]
    published: bool = True  # a node of the graph (a hypothesis is not)

    @property
    def top_z(self) -> float:
        """Height of the top surface."""
        return self.center[2] + self.extent[2] / 2


def support_of(
    center: Sequence[float] | npt.NDArray[np.float64],
    bottom_z: float,
    surfaces: Sequence[SupportSurface],
    params: FixtureParams,
) -> str | None:
    """The fixture whose top the object's bottom rests on, with its center over the footprint:
    within the tolerance of its top face, or of the band under it (`support_top_band_m`).

    Among candidates, a published fixture wins over a fixture hypothesis (an `on` edge names
    a node of the graph; a second, unconfirmed hypothesis of the same counter must not take
    the objects on it), then the closest top (ties by id), so a shelf above a counter is not
    taken for the counter.
    """
    best: tuple[bool, float, float, str] | None = None
    for surface in surfaces:
        box = footprint_of(surface.center, surface.extent, params.support_footprint_margin_m)
        if not (box[0] <= center[0] <= box[2] and box[1] <= center[1] <= box[3]):
            continue
        top = surface.top_z
        gap = max(bottom_z - top, (top - params.support_top_band_m) - bottom_z, 0.0)
        face = abs(bottom_z - top)  # among tops the band reaches, the closest face
        rank = (
            params.published_parent_first and not surface.published,
            gap,
            face,
            surface.track_id,
        )
        if gap <= params.support_height_tolerance_m and (best is None or rank < best):
            best = rank
    return None if best is None else best[3]


def surface_of(
    track: Track | None, track_id: str, proposal: FixtureProposal | None, alpha: float
) -> SupportSurface | None:
    """A fixture's top as a batch sees it: moved by this batch's cluster (the EMA of its center,
    the cluster's extent), or as stored; none for a rejected one, or a removed one unseen."""
    if track is not None and track.verification == "rejected":
        return None
    if track is not None and track.lifecycle == "removed" and proposal is None:
        return None
    if proposal is not None:
        if track is None or track.lifecycle == "removed":
            center = vec3(proposal.center)
        else:
            center = ema_center(track.center, proposal.center, alpha)
        extent = vec3(proposal.extent)
    else:
        assert track is not None
        center, extent = track.center, track.extent
    published = track is not None and is_published(track)
    return SupportSurface(track_id, center, extent, published)


def support_parents(
    state: SceneState,
    fixtures: Mapping[str, FixtureProposal],
    merged: Mapping[str, str],
    observations: Mapping[str, Sequence[Proposal]],
    params: Params,
) -> dict[str, tuple[str | None, ...]]:
    """Per object track a batch sighted, the support parent of each of its proposals, on the
    fixture tops as this batch sees them (`fixtures`: the clusters it matched; `merged`: second
    fixture tracks, which hold nothing)."""
    if not observations:
        return {}
    fixture_ids = {
        track_id
        for track_id, kind in zip(state.arrays.track_ids, state.arrays.kinds, strict=True)
        if kind == "fixture"
    }
    surfaces = [
        surface
        for track_id in sorted((fixture_ids | set(fixtures)) - set(merged))
        if (
            surface := surface_of(
                state.tracks.get(track_id),
                track_id,
                fixtures.get(track_id),
                params.fusion.fixture_center_alpha,
            )
        )
        is not None
    ]
    return {
        track_id: parents_of(proposals, surfaces, params.fixtures)
        for track_id, proposals in observations.items()
    }


def parents_of(
    proposals: Sequence[Proposal], surfaces: Sequence[SupportSurface], params: FixtureParams
) -> tuple[str | None, ...]:
    """The support parent of each proposal among `surfaces` (None: on nothing known)."""
    return tuple(support_of(p.center, p.bottom_z, surfaces, params) for p in proposals)
