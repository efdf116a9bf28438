"""Every constant of the method, each with the paper section it comes from.

Values the paper leaves open are chosen here, named and documented. A scene records its
parameters in its log when it is created, so a replay always uses the values the events
were decided with.
"""

from __future__ import annotations

import math
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


SizeLimits = tuple[float, float, float, float, float, float]  # min dx, dy, dz then max dx, dy, dz


@dataclass(frozen=True)
class FixtureParams:
    """Coarse fixtures: voxel class evidence, DBSCAN, association and promotion (sections 3.2, 3.3).

    The paper gives the structure and reports its exact fixture gates in its supplementary
    material, which we do not have; the numbers here are ours, chosen for indoor furniture.
    """

    taxonomy: tuple[str, ...] = ("table", "desk", "counter", "bed", "shelf", "cabinet", "sofa")
    # Only these classes enter the inspection queue Q_t (section 3.4, T_insp).
    inspection_taxonomy: tuple[str, ...] = ("table", "desk", "counter", "shelf")
    voxel_size_m: float = 0.05
    # Every 4th pixel of a fixture mask in each direction: at 6 m that is 4.6 cm, still inside
    # one 5 cm voxel, and it makes the map 16 times cheaper to feed.
    mask_pixel_stride: int = 4
    # A voxel is kept for class c when its mean similarity to c reaches the threshold of c and
    # beats every competing class by the margin.
    default_class_threshold: float = 0.40
    class_thresholds: dict[str, float] = field(default_factory=dict)
    min_class_margin: float = 0.02
    # DBSCAN in metric space over kept voxel centres (eps spans the 26-neighbourhood).
    dbscan_eps_m: float = 0.09
    dbscan_min_points: int = 4
    # Plausible sizes per class: min dx, dy, dz, max dx, dy, dz (dx >= dy: footprint sorted).
    default_size_limits: SizeLimits = (0.25, 0.20, 0.10, 4.0, 2.5, 2.5)
    size_limits: dict[str, SizeLimits] = field(
        default_factory=lambda: {
            "table": (0.4, 0.3, 0.3, 3.5, 2.0, 1.2),
            "desk": (0.5, 0.3, 0.4, 3.0, 1.5, 1.2),
            "counter": (0.5, 0.3, 0.5, 5.0, 1.5, 1.3),
            "bed": (1.2, 0.7, 0.2, 2.6, 2.4, 1.2),
        }
    )
    # Association: same class, planar center distance, expanded-footprint coverage or IoU.
    max_planar_distance_m: float = 1.0
    footprint_expand_m: float = 0.25
    min_expanded_coverage: float = 0.6
    min_footprint_iou: float = 0.25
    # A residual cluster this much inside a matched fixture's expanded footprint is absorbed.
    residual_containment: float = 0.9
    # Promotion: support from several temporally distinct batches, then the consensus gate.
    confirm_min_batches: int = 3
    consensus_min_agreement: float = 0.8  # share of supporting batches whose top class agrees
    consensus_min_margin: float = 0.08  # mean top-vs-second margin of those batches
    # Support: an object rests on a fixture when its bottom is this close to the fixture top
    # and its center is inside the fixture footprint grown by the margin.
    support_height_tolerance_m: float = 0.08
    support_footprint_margin_m: float = 0.05


@dataclass(frozen=True)
class InspectionParams:
    """Fixture-centered inspection capture (sections 3.2 and 3.4)."""

    max_attempts: int = 3  # bounded retry: a fixture failing this often is abandoned
    min_support_samples: int = 2  # support-region samples that must pass the visibility gate
    nms_mask_iou: float = 0.5  # same-class non-maximum suppression
    cross_class_mask_iou: float = 0.7  # cross-class overlap suppression


@dataclass(frozen=True)
class Params:
    """The whole parameter tree of one scene."""

    proposal: ProposalParams = field(default_factory=ProposalParams)
    association: AssociationParams = field(default_factory=AssociationParams)
    existence: ExistenceParams = field(default_factory=ExistenceParams)
    visibility: VisibilityParams = field(default_factory=VisibilityParams)
    fusion: FusionParams = field(default_factory=FusionParams)
    lifecycle: LifecycleParams = field(default_factory=LifecycleParams)
    fixtures: FixtureParams = field(default_factory=FixtureParams)
    inspection: InspectionParams = field(default_factory=InspectionParams)

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
        elif isinstance(current, dict):
            changes[key] = _merge_map(current, value, f"{path}.{key}", known[key].type)
        elif isinstance(current, tuple) and all(isinstance(item, str) for item in current):
            if not isinstance(value, list | tuple) or not all(
                isinstance(i, str) and i for i in value
            ):
                raise ValueError(f"{path}.{key}: expected a list of non-empty strings")
            changes[key] = tuple(value)
        elif isinstance(current, tuple):
            if not isinstance(value, list | tuple) or len(value) != len(current):
                raise ValueError(f"{path}.{key}: expected a list of {len(current)} numbers")
            changes[key] = tuple(
                _coerce(item, c, f"{path}.{key}") for item, c in zip(value, current, strict=True)
            )
        else:
            changes[key] = _coerce(value, current, f"{path}.{key}")
    return replace(node, **changes)


def _merge_map(current: dict[str, Any], value: Any, path: str, annotation: Any) -> dict[str, Any]:
    """A per-class map: replaced key by key; numbers or fixed-length number lists as values."""
    if not isinstance(value, dict):
        raise ValueError(f"{path}: expected an object")
    merged = dict(current)
    tuple_values = "SizeLimits" in str(annotation)
    for name, item in value.items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"{path}: keys must be non-empty strings")
        if tuple_values:
            if not isinstance(item, list | tuple) or len(item) != 6:
                raise ValueError(f"{path}.{name}: expected a list of 6 numbers")
            merged[name] = tuple(_coerce(v, 0.0, f"{path}.{name}") for v in item)
        else:
            merged[name] = _coerce(item, 0.0, f"{path}.{name}")
    return merged


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
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise ValueError(f"{path}: expected a finite number")
        return float(value)
    return value


DEFAULT_PARAMS = Params()
