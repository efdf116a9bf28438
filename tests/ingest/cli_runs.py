"""`pbdag ingest folder` run as a user runs it, on the test recordings."""

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
