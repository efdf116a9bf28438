"""World edits return new worlds, objects rest on fixtures, and raycast scenes are cached."""

from __future__ import annotations

import numpy as np
import pytest

from sim.world import Box, World, box_corners, build_scene, object_on

TABLE = Box("table", "table", (2.0, 2.0, 0.375), (1.2, 0.8, 0.75), kind="fixture")
MUG = object_on(TABLE, "mug", "mug", (0.08, 0.08, 0.10), at=(0.3, -0.1))
WORLD = World(room_size=(5.0, 4.0, 2.5), fixtures=(TABLE,), objects=(MUG,))


def test_object_on_rests_on_the_fixture_top_at_the_offset() -> None:
    assert MUG.center == pytest.approx((2.3, 1.9, 0.80))
    turned_table = Box("t2", "table", (2.0, 2.0, 0.375), (1.2, 0.8, 0.75), yaw=np.pi / 2)
    on_turned = object_on(turned_table, "cup", "cup", (0.1, 0.1, 0.1), at=(0.3, 0.0))
    # The offset follows the fixture's own axes, so a quarter turn sends +x to world +y.
    assert on_turned.center == pytest.approx((2.0, 2.3, 0.80))


def test_edits_return_new_worlds_and_leave_the_original_alone() -> None:
    book = Box("book", "book", (1.0, 1.0, 0.02), (0.2, 0.15, 0.04))
    grown = WORLD.with_object(book)
    assert [box.id for box in grown.objects] == ["mug", "book"]
    assert [box.id for box in grown.without("mug").objects] == ["book"]
    moved = WORLD.moved("mug", (1.0, 1.0, 0.8))
    assert moved.object_by_id("mug").center == (1.0, 1.0, 0.8)
    assert WORLD.object_by_id("mug").center == MUG.center
    assert WORLD.with_occluder(book).occluders[0].kind == "occluder"
    assert len(WORLD.objects) == 1 and WORLD.occluders == ()


def test_bad_edits_are_refused() -> None:
    with pytest.raises(KeyError):
        WORLD.without("ghost")
    with pytest.raises(ValueError):
        WORLD.with_object(MUG)


def test_box_corners_respect_yaw() -> None:
    corners = box_corners(Box("b", "b", (0.0, 0.0, 0.5), (2.0, 1.0, 1.0), yaw=np.pi / 2))
    assert corners[:, 0].max() == pytest.approx(0.5)
    assert corners[:, 1].max() == pytest.approx(1.0)
    assert corners[:, 2].min() == pytest.approx(0.0) and corners[:, 2].max() == pytest.approx(1.0)


def test_build_scene_is_cached_per_world_and_maps_geometry_to_boxes() -> None:
    first = build_scene(WORLD)
    assert build_scene(World(WORLD.room_size, WORLD.fixtures, WORLD.objects)) is first
    assert build_scene(WORLD.without("mug")) is not first
    assert sorted(
        (box.id if box is not None else "room") for box in first.box_by_geometry.values()
    ) == ["mug", "room", "table"]
    mug_geometry = next(gid for gid, box in first.box_by_geometry.items() if box == MUG)
    assert first.object_lookup[mug_geometry] == 0
    assert first.fixture_lookup[mug_geometry] == -1
