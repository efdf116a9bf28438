"""The frozen structural baseline B^(0) = Freeze(B_t) (sections 3.1, 3.2): versioned and immutable."""

from __future__ import annotations

import hashlib
from typing import Final, Literal, TypedDict

import orjson

from core.errors import StateConflict
from core.events import BaselineFrozen, BaselineLoaded, Event
from core.state import SceneState, Track
from core.values import BaselineFixture, BaselineSource

PACKAGE_FORMAT: Final = "pbdag-baseline/1"


class PackageFixture(TypedDict):
    """A confirmed fixture in a package: its identity, class, existence and box."""

    track_id: str
    label: str
    class_probabilities: dict[str, float]
    class_evidence: dict[str, float]
    center: list[float]
    extent: list[float]
    existence_logodds: float
    p_exist: float


class BaselinePackage(TypedDict):
    """Everything a later session needs; its canonical JSON's sha256 names it."""

    format: Literal["pbdag-baseline/1"]
    scene_id: str
    version: int
    frozen_at_seq: int
    fixtures: list[PackageFixture]


def baseline_package(
    state: SceneState, scene_id: str, version: int, frozen_at_seq: int
) -> BaselinePackage:
    """The confirmed fixtures as a canonical package (everything a later session needs)."""
    fixtures: list[PackageFixture] = [
        {
            "track_id": track.track_id,
            "label": track.label,
            "class_probabilities": track.class_probabilities(),
            "class_evidence": dict(sorted(track.class_evidence.items())),
            "center": list(track.center),
            "extent": list(track.extent),
            "existence_logodds": track.existence_logodds,
            "p_exist": track.p_exist,
        }
        for track in (state.tracks[i] for i in sorted(state.tracks))
        if track.kind == "fixture" and track.lifecycle == "confirmed"
    ]
    return {
        "format": PACKAGE_FORMAT,
        "scene_id": scene_id,
        "version": version,
        "frozen_at_seq": frozen_at_seq,
        "fixtures": fixtures,
    }


def canonical_bytes(package: BaselinePackage) -> bytes:
    """Canonical JSON: sorted keys, no whitespace; its sha256 names the package."""
    return orjson.dumps(package, option=orjson.OPT_SORT_KEYS)


def package_sha256(package: BaselinePackage) -> str:
    """Hex sha256 of the canonical package."""
    return hashlib.sha256(canonical_bytes(package)).hexdigest()


def decide_freeze(state: SceneState, scene_id: str) -> tuple[list[Event], BaselinePackage]:
    """Freeze the confirmed fixtures: the event (which pins them) and the package it names."""
    version = (state.baselines[-1].version if state.baselines else 0) + 1
    package = baseline_package(state, scene_id, version, state.head_seq + 1)
    if not package["fixtures"]:
        raise StateConflict("the scene has no confirmed fixture to freeze")
    fixture_ids = [fixture["track_id"] for fixture in package["fixtures"]]
    event = BaselineFrozen(
        version=version, sha256=package_sha256(package), fixture_ids=tuple(fixture_ids)
    )
    return [event], package


def decide_load(package: BaselinePackage) -> list[Event]:
    """A new session from a package: its fixtures keep their canonical identities, pinned."""
    fixtures = tuple(
        BaselineFixture(
            track_id=fixture["track_id"],
            class_evidence=dict(sorted(fixture["class_evidence"].items())),
            existence_logodds=float(fixture["existence_logodds"]),
            center=(fixture["center"][0], fixture["center"][1], fixture["center"][2]),
            extent=(fixture["extent"][0], fixture["extent"][1], fixture["extent"][2]),
        )
        for fixture in package["fixtures"]
    )
    numbers = [
        int(fixture.track_id.rsplit("-", 1)[-1])
        for fixture in fixtures
        if fixture.track_id[-1].isdigit()
    ]
    source = BaselineSource(
        scene_id=package["scene_id"], version=package["version"], sha256=package_sha256(package)
    )
    return [
        BaselineLoaded(
            source=source, fixtures=fixtures, next_track_number=max(numbers, default=0) + 1
        )
    ]


def loaded_track(fixture: BaselineFixture) -> Track:
    """The track of a loaded baseline fixture: confirmed, published where the package says, pinned."""
    return Track(
        track_id=fixture.track_id,
        kind="fixture",
        lifecycle="confirmed",
        class_evidence=dict(fixture.class_evidence),
        existence_logodds=fixture.existence_logodds,
        center=fixture.center,
        extent=fixture.extent,
        recent_centers=(),
        published_center=fixture.center,
        pinned=True,
    )
