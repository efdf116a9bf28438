"""Support parents from geometry (section 3.3): which fixture top an object rests on."""

from __future__ import annotations

from core.params import Params
from core.support import SupportSurface, support_of

PARAMS = Params().fixtures
COUNTER = SupportSurface("trk-000009", (7.6, 3.0, 0.45), (0.6, 2.6, 0.9), published=True)
# A second, unconfirmed hypothesis of the same counter, its top 3 cm higher.
ITS_TWIN = SupportSurface("trk-000013", (7.6, 3.2, 0.47), (0.6, 1.2, 0.94), published=False)
SHELF = SupportSurface("trk-000020", (7.6, 3.0, 1.35), (0.4, 1.0, 0.1), published=True)


def test_a_published_fixture_wins_over_a_hypothesis_whose_top_is_closer() -> None:
    cup = (7.6, 3.3, 0.955)
    bottom = 0.93  # 3 cm above the counter's top, 1 cm below the hypothesis's
    assert support_of(cup, bottom, [COUNTER, ITS_TWIN], PARAMS) == COUNTER.track_id
    # Alone, the hypothesis is the support (its objects follow it once it is confirmed).
    assert support_of(cup, bottom, [ITS_TWIN], PARAMS) == ITS_TWIN.track_id


def test_the_closest_top_wins_among_published_fixtures_within_the_tolerance() -> None:
    book = (7.6, 3.0, 1.42)
    assert support_of(book, 1.40, [COUNTER, SHELF], PARAMS) == SHELF.track_id
    assert support_of((7.6, 3.0, 0.95), 0.90, [COUNTER, SHELF], PARAMS) == COUNTER.track_id
    assert support_of((9.0, 3.0, 0.95), 0.90, [COUNTER, SHELF], PARAMS) is None  # off both


def test_the_gap_is_measured_to_the_band_under_the_top_face() -> None:
    # The counter's top face is at 0.90; its band (one voxel) reaches down to 0.85.
    band, tolerance = PARAMS.support_top_band_m, PARAMS.support_height_tolerance_m
    assert (band, tolerance) == (0.05, 0.08)
    under = 0.90 - band - tolerance
    assert support_of((7.6, 3.0, 0.8), under + 0.005, [COUNTER], PARAMS) == COUNTER.track_id
    assert support_of((7.6, 3.0, 0.8), under - 0.005, [COUNTER], PARAMS) is None
    # Above the face the band adds nothing.
    assert support_of((7.6, 3.0, 1.0), 0.90 + tolerance - 0.005, [COUNTER], PARAMS) is not None
    assert support_of((7.6, 3.0, 1.0), 0.90 + tolerance + 0.005, [COUNTER], PARAMS) is None
    # Without the band, the face alone: 0.09 m under it is off the counter.
    face_only = Params.from_dict({"fixtures": {"support_top_band_m": 0.0}}).fixtures
    assert support_of((7.6, 3.0, 0.8), 0.81, [COUNTER], PARAMS) == COUNTER.track_id
    assert support_of((7.6, 3.0, 0.8), 0.81, [COUNTER], face_only) is None


def test_two_tops_the_band_reaches_go_to_the_closer_face() -> None:
    # The counter's face at 0.90 and a second published fixture's at 0.94: an object resting
    # at 0.895 is inside both bands and goes to the face 0.5 cm away, not the one 4.5 cm away.
    higher = SupportSurface("trk-000001", (7.6, 3.0, 0.47), (0.6, 2.6, 0.94), published=True)
    assert support_of((7.6, 3.0, 0.95), 0.895, [higher, COUNTER], PARAMS) == COUNTER.track_id
    assert support_of((7.6, 3.0, 0.95), 0.935, [higher, COUNTER], PARAMS) == higher.track_id
