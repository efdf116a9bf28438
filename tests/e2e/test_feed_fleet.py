"""The change feed of a fleet on PostgreSQL: three API processes, a worker, 500 batches, one API
process SIGKILLed twice; every consumer sees every seq once, in order, up to the head, and a
consumer that reads nothing is dropped while the others go on."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.e2e.feed_run import run_feed_fleet


@pytest.mark.slow
@pytest.mark.postgres
def test_every_consumer_sees_every_seq_once_in_order_across_kills(
    tmp_path: Path, postgres_schema_url: tuple[str, str]
) -> None:
    url, schema = postgres_schema_url
    report = run_feed_fleet(f"{url}?options=-csearch_path%3D{schema}", tmp_path / "fleet")
    assert report.batches == 500 and report.kills == 2
    assert report.head > 500  # every batch appended events
    for consumer in report.consumers:
        assert consumer.error is None, consumer.error
        assert consumer.seqs == list(range(report.head + 1)), consumer.first_url
    assert sum(c.switches for c in report.consumers) >= 1  # someone resumed elsewhere
    # The reader of nothing was dropped: its connection closed, far before the head.
    assert report.stalled_closed
    assert report.stalled_ids == list(range(len(report.stalled_ids)))
    assert len(report.stalled_ids) < report.head
    assert report.seconds < 110, report.seconds
