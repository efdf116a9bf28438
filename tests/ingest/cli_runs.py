"""`pbdag ingest folder|rosbag` run as a user runs it, on the test recordings, and what a refused
run must print."""

from __future__ import annotations

from pathlib import Path

from service.cli import main
from tests.ingest.conftest import Recordings


def ingest_folder(
    recordings: Recordings, url: str, scene: str, *extra: str, folder: Path | None = None
) -> int:
    return main(
        [
            "ingest",
            "folder",
            str(folder or recordings.folder),
            "--scene",
            scene,
            "--url",
            url,
            "--detector",
            "instance-pngs",
            "--masks",
            str(recordings.folder / "masks"),
            "--labels",
            str(recordings.labels),
            *extra,
        ]
    )


def ingest_bag(bag: Path, url: str, scene: str, *extra: str) -> int:
    return main(
        [
            "ingest",
            "rosbag",
            str(bag),
            "--scene",
            scene,
            "--url",
            url,
            "--depth-topic",
            "/camera/depth",
            "--camera-info-topic",
            "/camera/camera_info",
            *extra,
        ]
    )


def error_line(err: str) -> str:
    """The one line a refused run prints on stderr (it must print exactly one, no traceback)."""
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("pbdag ingest: error: "), err
    return lines[0]
