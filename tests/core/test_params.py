"""The parameter tree: the paper's numbers, overrides, and validation."""

from typing import Any

import pytest

from core.errors import InvalidParams
from core.params import Params


def test_paper_constants() -> None:
    params = Params()
    assert params.association.max_center_distance_m == 0.8
    assert params.association.min_appearance_cosine == 0.78
    existence = params.existence
    assert (
        existence.eta_observed,
        existence.eta_confirmed,
        existence.eta_missed,
        existence.eta_rejected,
    ) == (
        1.0,
        1.8,
        0.70,
        2.20,
    )
    lifecycle = params.lifecycle
    assert (
        lifecycle.confirm_min_p_exist,
        lifecycle.demote_below_p_exist,
        lifecycle.remove_at_most_p_exist,
    ) == (
        0.72,
        0.30,
        0.12,
    )
    assert lifecycle.move_min_distance_m == 0.35 and lifecycle.remove_min_visible_misses == 3
    assert params.visibility.occlusion_margin_m == 0.15 and params.visibility.depth_window_px == 5
    assert params.fusion.max_recent_centers == 32 and params.fusion.fixture_center_alpha == 0.35


def test_round_trip_and_partial_override() -> None:
    params = Params.from_dict({"lifecycle": {"move_min_distance_m": 0.5}})
    assert params.lifecycle.move_min_distance_m == 0.5
    assert params.lifecycle.confirm_min_p_exist == 0.72
    assert Params.from_dict(params.to_dict()) == params


@pytest.mark.parametrize(
    ("overrides", "field", "reason"),
    [
        ({"nope": 1}, "params.nope", "unknown parameter"),
        (
            {"lifecycle": {"confirm_min_batches": 2.5}},
            "params.lifecycle.confirm_min_batches",
            "integer",
        ),
        (
            {"lifecycle": {"confirm_min_batches": True}},
            "params.lifecycle.confirm_min_batches",
            "integer",
        ),
        ({"existence": {"eta_missed": "a lot"}}, "params.existence.eta_missed", "number"),
        ({"existence": {"eta_missed": float("nan")}}, "params.existence.eta_missed", "number"),
        ({"proposal": {"extent_percentiles": [5]}}, "params.proposal.extent_percentiles[1]", ""),
        # Ranges: each of these used to be accepted and then broke every later batch.
        (
            {"visibility": {"box_samples_per_axis": 100000}},
            "params.visibility.box_samples_per_axis",
            "9",
        ),
        ({"visibility": {"depth_window_px": -3}}, "params.visibility.depth_window_px", "1"),
        ({"fixtures": {"voxel_size_m": 0}}, "params.fixtures.voxel_size_m", "0.02"),
        ({"fixtures": {"taxonomy": ["ta\x00ble"]}}, "params.fixtures.taxonomy[0]", "printable"),
        # Cross-field rules.
        (
            {"existence": {"logodds_min": 5.0, "logodds_max": 1.0}},
            "params.existence",
            "logodds_min",
        ),
        ({"visibility": {"min_range_m": 7.0}}, "params.visibility", "min_range_m"),
        ({"visibility": {"depth_window_px": 4}}, "params.visibility", "odd"),
        ({"fixtures": {"size_limits": {"bench": [1, 1, 1, 0, 0, 0]}}}, "params.fixtures", "bench"),
    ],
)
def test_bad_overrides_name_the_field(overrides: dict[str, Any], field: str, reason: str) -> None:
    with pytest.raises(InvalidParams) as raised:
        Params.from_dict(overrides)
    assert raised.value.field == field
    assert raised.value.detail.startswith(f"{field}: ") and reason in raised.value.detail


def test_per_class_maps_merge_key_by_key() -> None:
    params = Params.from_dict(
        {"fixtures": {"size_limits": {"bench": [0.8, 0.3, 0.3, 2.5, 0.8, 0.6]}}}
    )
    assert params.fixtures.size_limits["bench"] == (0.8, 0.3, 0.3, 2.5, 0.8, 0.6)
    assert params.fixtures.size_limits["table"] == Params().fixtures.size_limits["table"]
