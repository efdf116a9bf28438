"""Every constant of the method, each with the paper section it comes from.

Values the paper leaves open are chosen here, named and documented. A scene records its
parameters in its log when it is created, so a replay always uses the values the events
were decided with.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, is_dataclass, replace
from typing import Any


@dataclass(frozen=True)
class ProposalParams:
    """Grounding a 2D mask into a 3D proposal (section 3.2, "Valid mask depth is back-projected")."""

    # Not numbered in the paper: fewer valid-depth pixels than this and the proposal is rejected.
    min_valid_depth_pixels: int = 40
    # Robust inlier filtering against boundary leakage: keep |z - median z| <= max(band, k * MAD).
    depth_inlier_mad_k: float = 3.0
    depth_inlier_min_band_m: float = 0.05
    # The median is taken on the mask eroded by this many pixels, which leakage cannot reach,
    # when at least `min_interior_pixels` valid pixels remain there.
    boundary_erosion_px: int = 2
    min_interior_pixels: int = 9
    # Box extent from robust percentiles of the inlier points, floored so a thin surface still
    # gives a box the visibility gate can sample.
    extent_percentiles: tuple[float, float] = (5.0, 95.0)
    min_extent_m: float = 0.04


@dataclass(frozen=True)
class AssociationParams:
    """Dynamic association front end (section 3.3, "Type-specific association")."""

    max_center_distance_m: float = 0.8
    min_appearance_cosine: float = 0.78
    # Unique-class fallback: recover an identity after large motion when appearance agrees.
    unique_class_fallback: bool = True


@dataclass(frozen=True)
class ExistenceParams:
    """Existence log-odds, equation (3) (section 3.3, "Visibility-gated existence")."""

    eta_observed: float = 1.0  # eta_o, ordinary positive observation
    eta_confirmed: float = 1.8  # eta_c, cached verification confirm
    eta_missed: float = 0.70  # eta_m, visibility-admissible miss
    eta_rejected: float = 2.20  # eta_r, cached verification reject
    # Not given by the paper: a new hypothesis (and a removed track that is re-acquired) starts
    # from an uninformed prior, p = 0.5.
    prior_logodds: float = 0.0
    # Not given by the paper: the clamp. Without one an object seen 500 times could never be
    # removed; with +-4 (p in [0.018, 0.982]) a long-seen object needs 9 visible misses
    # ((4 + 1.99) / 0.7) to fall to p <= 0.12, and a removed one recovers in 5 positive batches.
    logodds_min: float = -4.0
    logodds_max: float = 4.0


@dataclass(frozen=True)
class VisibilityParams:
    """The geometric visibility gate V_i(t) (section 3.3)."""

    # Valid camera range; not numbered in the paper, chosen for Kinect-class RGB-D sensors.
    min_range_m: float = 0.3
    max_range_m: float = 6.0
    depth_window_px: int = 5  # "valid depth in a 5x5 window"
    occlusion_margin_m: float = 0.15  # unoccluded when d_meas + 0.15 m >= d_expected
    min_samples_passed: int = 2  # V = 1 only when at least two samples pass
    # Samples of the stored box: a grid of n per axis (27 = corners, edge and face centres, centre).
    box_samples_per_axis: int = 3


@dataclass(frozen=True)
class FusionParams:
    """Persistent state fusion (section 3.3, "Persistent state fusion")."""

    observation_evidence_weight: float = 1.0  # ordinary observations add unit evidence
    verification_evidence_weight: float = 3.0  # cached VLM class verification
    max_recent_centers: int = 32  # covariance over at most the 32 most recent centers
    fixture_center_alpha: float = 0.35  # EMA of coarse fixture centers


@dataclass(frozen=True)
class LifecycleParams:
    """Lifecycle transitions and audit events (section 3.3)."""

    confirm_min_p_exist: float = 0.72
    confirm_min_batches: int = 2  # cross-batch confirmation
    move_min_distance_m: float = 0.35
    demote_below_p_exist: float = 0.30
    remove_at_most_p_exist: float = 0.12
    remove_min_visible_misses: int = 3


@dataclass(frozen=True)
class Params:
    """The whole parameter tree of one scene."""

    proposal: ProposalParams = field(default_factory=ProposalParams)
    association: AssociationParams = field(default_factory=AssociationParams)
    existence: ExistenceParams = field(default_factory=ExistenceParams)
    visibility: VisibilityParams = field(default_factory=VisibilityParams)
    fusion: FusionParams = field(default_factory=FusionParams)
    lifecycle: LifecycleParams = field(default_factory=LifecycleParams)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict (tuples become lists)."""
        result: dict[str, Any] = _jsonable(asdict(self))
        return result

    @classmethod
    def from_dict(cls, overrides: dict[str, Any] | None = None) -> Params:
        """Defaults updated by a (possibly partial) nested dict; unknown keys raise ValueError."""
        merged: Params = _merge(cls(), overrides or {}, path="params")
        return merged


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {key: _jsonable(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(item) for item in value]
    return value


def _merge(node: Any, overrides: dict[str, Any], path: str) -> Any:
    if not isinstance(overrides, dict):
        raise ValueError(f"{path}: expected an object")
    known = {f.name: f for f in fields(node)}
    changes: dict[str, Any] = {}
    for key, value in overrides.items():
        if key not in known:
            raise ValueError(f"{path}.{key}: unknown parameter")
        current = getattr(node, key)
        if is_dataclass(current):
            changes[key] = _merge(current, value, f"{path}.{key}")
        elif isinstance(current, tuple):
            if not isinstance(value, list | tuple) or len(value) != len(current):
                raise ValueError(f"{path}.{key}: expected a list of {len(current)} numbers")
            changes[key] = tuple(
                _coerce(item, c, f"{path}.{key}") for item, c in zip(value, current, strict=True)
            )
        else:
            changes[key] = _coerce(value, current, f"{path}.{key}")
    return replace(node, **changes)


def _coerce(value: Any, like: Any, path: str) -> Any:
    if isinstance(like, bool):
        if not isinstance(value, bool):
            raise ValueError(f"{path}: expected true or false")
        return value
    if isinstance(like, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{path}: expected an integer")
        return value
    if isinstance(like, float):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{path}: expected a number")
        return float(value)
    return value


DEFAULT_PARAMS = Params()
