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
