"""The views of an inspection sweep (core/sweep.py): counting a view's objects, and the views'
votes on each object's label."""

from __future__ import annotations

import numpy as np

from core.geometry import Proposal
from core.sweep import class_votes, view_score


def proposal(label: str, x: float, width: float = 0.05, y: float = 0.0) -> Proposal:
    center, extent = np.array([x, y, 0.8]), np.array([width, 0.08, 0.1])
    scores = {label: 0.9, "other": 0.7}
    return Proposal(label, 0.9, "object", center, extent, None, 100, "f", 0.0, 0.75, 0, scores)


def objects(view: list[Proposal]) -> int:
    return view_score(view, [])[1]


def test_a_view_s_objects_count_a_mask_split_in_two_once() -> None:
    halves = [proposal("mug", 0.0), proposal("mug", 0.045)]  # boxes overlapping by 5 mm
    assert objects(halves) == 1
    assert objects([*halves, proposal("mug", 0.3)]) == 2  # another mug 0.3 m along
    assert objects([proposal("mug", 0.0), proposal("book", 0.045)]) == 2  # two classes
    # A chain of touching pieces is one object; nothing is none.
    assert objects([proposal("mug", 0.0), proposal("mug", 0.09), proposal("mug", 0.045)]) == 1
    assert view_score([], [[proposal("mug", 0.0)]]) == (0, 0)


def test_the_label_most_views_give_an_object_wins_and_its_geometry_stays() -> None:
    primary = [proposal("cup", 0.0), proposal("book", 0.5)]
    alternates = [
        [proposal("mug", 0.01), proposal("book", 0.5)],
        [proposal("mug", -0.01), proposal("remote", 0.52)],
    ]
    mug, book = class_votes(primary, alternates)
    assert (mug.label, mug.class_scores) == ("mug", {"mug": 0.9, "other": 0.7})
    assert np.array_equal(mug.center, primary[0].center)  # the primary's geometry
    assert book is primary[1]  # two of three say book
    # A tie keeps the primary's label; an alternate proposal touching nothing votes for nothing.
    tied = class_votes([proposal("cup", 0.0)], [[proposal("mug", 0.0)], [proposal("mug", 2.0)]])
    assert tied[0].label == "cup"
    assert class_votes([], alternates) == []


def test_an_alternate_proposal_votes_for_the_nearest_primary_proposal_it_touches() -> None:
    # Two mugs side by side whose boxes both touch the alternate's: the nearer one gets it.
    primary = [proposal("mug", 0.0, width=0.1), proposal("mug", 0.09, width=0.1)]
    alternates = [[proposal("cup", 0.06)], [proposal("cup", 0.065)]]  # touching both
    first, second = class_votes(primary, alternates)
    assert (first.label, second.label) == ("mug", "cup")


def test_only_objects_another_view_corroborates_count_first() -> None:
    view = [proposal("mug", 0.0), proposal("mug", 0.045), proposal("cup", 0.5)]  # halves, a cup
    assert view_score(view, [[proposal("bowl", 0.09)]]) == (1, 2)  # a piece seen again: the mug
    assert view_score(view, [[proposal("cup", 0.5)], [proposal("mug", 0.0)]]) == (2, 2)
    assert view_score(view, [[proposal("cup", 1.5)], []]) == (0, 2)  # nothing seen again
    assert view_score(view, []) == (0, 2)
