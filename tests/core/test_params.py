"""The parameter tree: the paper's numbers, overrides, and validation."""

import pytest

from core.params import Params


def test_paper_constants():
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


def test_round_trip_and_partial_override():
    params = Params.from_dict({"lifecycle": {"move_min_distance_m": 0.5}})
    assert params.lifecycle.move_min_distance_m == 0.5
    assert params.lifecycle.confirm_min_p_exist == 0.72
    assert Params.from_dict(params.to_dict()) == params


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"nope": 1}, "params.nope: unknown parameter"),
        (
            {"lifecycle": {"confirm_min_batches": 2.5}},
            "params.lifecycle.confirm_min_batches: expected an integer",
        ),
        (
            {"existence": {"eta_missed": "a lot"}},
            "params.existence.eta_missed: expected a finite number",
        ),
        ({"proposal": {"extent_percentiles": [5]}}, "expected a list of 2 numbers"),
    ],
)
def test_bad_overrides_name_the_field(overrides, message):
    with pytest.raises(ValueError, match=message.replace(".", r"\.")):
        Params.from_dict(overrides)
