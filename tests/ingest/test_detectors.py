"""Detector plugins: loading by entry point, label maps, instance images to masks."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from ingest.detectors import (
    InstancePngsDetector,
    LabelEntry,
    LabelImageDetector,
    available_detectors,
    load_detector,
    load_label_map,
)
from ingest.frames import CameraIntrinsics, IngestError, SkipFrame, SourceCounts, SourceFrame

INTRINSICS = CameraIntrinsics(width=20, height=10, fx=30.0, fy=30.0, cx=10.0, cy=5.0)


class NoSource:
    """A stand-in recording (the shipped plugins do not use it)."""

    name = "none"
    counts = SourceCounts()

    def expected_frames(self) -> int | None:
        return None

    def check(self, extra_topics: tuple[str, ...] = ()) -> None:
        pass

    def frames(self, extra_topics: tuple[str, ...] = ()) -> Iterator[SourceFrame]:
        return iter(())


def frame(frame_id: str = "frame-000004", messages: dict[str, object] | None = None) -> SourceFrame:
    return SourceFrame(
        index=4,
        frame_id=frame_id,
        timestamp=0.0,
        depth=np.ones((10, 20), np.uint16),
        intrinsics=INTRINSICS,
        pose=np.eye(4),
        stamp_ns=123,
        messages=messages or {},
    )


@pytest.fixture
def labels(tmp_path: Path) -> Path:
    path = tmp_path / "labels.yaml"
    path.write_text("1: mug\n2: {label: table, kind: fixture, score: 0.7}\n")
    return path


def instances() -> np.ndarray:
    """Id 1 on 60 pixels, id 2 on 80, id 9 (unlabelled) on 20."""
    ids = np.zeros((10, 20), np.uint16)
    ids[0:6, 0:10] = 1
    ids[6:10, 0:20] = 2
    ids[0:2, 10:20] = 9
    return ids


def test_the_shipped_plugins_are_entry_points() -> None:
    assert {"label-image", "instance-pngs"} <= set(available_detectors())


def test_label_maps_in_yaml_and_json(labels: Path, tmp_path: Path) -> None:
    assert load_label_map(labels) == {1: LabelEntry("mug"), 2: LabelEntry("table", "fixture", 0.7)}
    as_json = tmp_path / "labels.json"
    as_json.write_text('{"1": "mug", "2": {"label": "table", "kind": "fixture", "score": 0.7}}')
    assert load_label_map(as_json) == load_label_map(labels)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("mug: 1\n", "key 'mug' is not an integer id"),
        ("0: floor\n", "id 0 must be positive"),
        ("1: {label: table, kind: furniture}\n", "kind must be 'object' or 'fixture'"),
        ("1: {label: mug, score: 2}\n", r"score must be a number in \[0, 1\]"),
        ("1: {label: mug, colour: red}\n", r"unknown keys \['colour'\]"),
        ("- mug\n", "non-empty mapping"),
        ("1: [mug\n", "cannot be parsed"),
        ("1: [SECRET\n", r"cannot be parsed \(line 2, column 1: expected ',' or ']', but got"),
        (b"1: \xff\xfe", "is not UTF-8 text"),
    ],
)
def test_a_bad_label_map_says_what_is_wrong(
    tmp_path: Path, text: str | bytes, message: str
) -> None:
    path = tmp_path / "labels.yaml"
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    with pytest.raises(IngestError, match=message) as raised:
        load_label_map(path)
    assert "\n" not in str(raised.value) and "SECRET" not in str(raised.value)


def test_unknown_detectors_and_missing_options_are_named(labels: Path, tmp_path: Path) -> None:
    with pytest.raises(
        IngestError,
        match=r"unknown detector 'yolo'; installed detectors .*instance-pngs, label-image",
    ):
        load_detector("yolo", {})
    with pytest.raises(IngestError, match="'label-image' needs --label-topic"):
        load_detector("label-image", {"labels": str(labels)})
    with pytest.raises(IngestError, match="'instance-pngs' needs --masks"):
        load_detector("instance-pngs", {"labels": str(labels)})
    with pytest.raises(IngestError, match="'instance-pngs' needs --labels"):
        load_detector("instance-pngs", {"masks": str(tmp_path)})
    with pytest.raises(IngestError, match=r"label map .*nope.json does not exist"):
        load_detector(
            "instance-pngs", {"masks": str(tmp_path), "labels": str(tmp_path / "nope.json")}
        )


def test_instance_pngs_give_one_mask_per_labelled_id(labels: Path, tmp_path: Path) -> None:
    Image.fromarray(instances()).save(tmp_path / "frame-000004.png")
    detector = load_detector(
        "instance-pngs", {"masks": str(tmp_path), "labels": str(labels), "min-pixels": "61"}
    )
    assert isinstance(detector, InstancePngsDetector) and detector.topics == ()
    (table,) = detector.detect(frame(), NoSource())  # the mug's 60 pixels are under min-pixels
    assert (table.label, table.kind, table.score) == ("table", "fixture", 0.7)
    np.testing.assert_array_equal(table.mask, instances() == 2)
    assert detector.masks.unlabelled == {9}
    with pytest.raises(SkipFrame, match="no instance PNG"):
        detector.detect(frame("frame-000005"), NoSource())


def test_instance_png_names_follow_the_pattern_and_sizes_must_match(
    labels: Path, tmp_path: Path
) -> None:
    Image.fromarray(instances()).save(tmp_path / "000004-123.png")
    options = {"masks": str(tmp_path), "labels": str(labels), "pattern": "{index:06d}-{stamp}.png"}
    found = load_detector("instance-pngs", options).detect(frame(), NoSource())
    assert [(d.label, d.kind, d.score, int(d.mask.sum())) for d in found] == [
        ("mug", "object", 1.0, 60),
        ("table", "fixture", 0.7, 80),
    ]
    Image.fromarray(instances()[:, :10]).save(tmp_path / "000004-123.png")
    with pytest.raises(IngestError, match="instance image is 10x10, the depth is 20x10"):
        load_detector("instance-pngs", options).detect(frame(), NoSource())


def test_label_images_come_from_the_synchronised_message(labels: Path) -> None:
    class Image16:
        """A sensor_msgs/Image's fields."""

        encoding, is_bigendian, height, width, step = "16UC1", 0, 10, 20, 40
        data = instances().astype("<u2").view(np.uint8).reshape(-1)

    detector = load_detector("label-image", {"label-topic": "/ids", "labels": str(labels)})
    assert isinstance(detector, LabelImageDetector) and detector.topics == ("/ids",)
    found = detector.detect(frame(messages={"/ids": Image16()}), NoSource())
    assert [d.label for d in found] == ["mug", "table"]
    np.testing.assert_array_equal(found[1].mask, instances() == 2)
    with pytest.raises(SkipFrame, match="no /ids message"):
        detector.detect(frame(), NoSource())


class FakeEntryPoint:
    """An installed plugin's entry point (what importlib.metadata gives)."""

    def __init__(self, factory: object) -> None:
        self.factory = factory

    def load(self) -> object:
        return self.factory


def test_a_plugin_must_follow_the_protocol(monkeypatch: pytest.MonkeyPatch) -> None:
    class NoTopics:
        def __init__(self, options: dict[str, str]) -> None:
            self.options = options

        def detect(self, frame: SourceFrame, source: object) -> list[object]:
            return []

    class NoDetect:
        topics = ()

        def __init__(self, options: dict[str, str]) -> None:
            pass

    class Fine(NoTopics):
        topics = ("/camera/color",)

    plugins = {
        name: FakeEntryPoint(f) for name, f in (("a", NoTopics), ("b", NoDetect), ("c", Fine))
    }
    monkeypatch.setattr("ingest.detectors.available_detectors", lambda: plugins)
    with pytest.raises(IngestError, match="'a' must have `topics`, a tuple of bag topic names"):
        load_detector("a", {})
    with pytest.raises(IngestError, match="'b' has no detect"):
        load_detector("b", {})
    fine = load_detector("c", {"threshold": "0.6"})
    assert isinstance(fine, Fine) and fine.options == {"threshold": "0.6"}
