"""Prometheus metrics of one process: its own registry, so two apps in one process never mix.

Two kinds of figures:
- the queue, read from the database at scrape time (`pbdag_batches`, `pbdag_queue_oldest_age_seconds`):
  every process that answers /metrics shows the same, whole-service view;
- what this process did (counters and histograms of the worker and of the unit of work): an API
  with its in-process worker (`pbdag serve`) reports its worker; `pbdag worker --metrics-port`
  serves its own. Prometheus sums them across processes (no multiprocess mode needed, since
  every process is scraped on its own).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram
from prometheus_client.core import GaugeMetricFamily, Metric
from prometheus_client.exposition import CONTENT_TYPE_LATEST, generate_latest
from prometheus_client.registry import Collector

from service.store.queue import BatchQueue

__all__ = ["BATCH_STATUSES", "CONTENT_TYPE_LATEST", "Metrics", "QueueCollector"]

BATCH_STATUSES = ("queued", "running", "failed", "done", "dead")
# Seconds: decide is milliseconds to seconds per batch (depth decoding and association), an append
# a few milliseconds (one transaction).
DECIDE_BUCKETS = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0)
APPEND_BUCKETS = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5)


class QueueCollector(Collector):
    """Batches per status and the age of the oldest waiting batch, read when scraped."""

    def __init__(self, queue: BatchQueue, clock: Callable[[], float] = time.time) -> None:
        self.queue = queue
        self.clock = clock

    def collect(self) -> Iterable[Metric]:
        """One query for the counts, one for the oldest waiting batch."""
        counts = self.queue.counts()
        by_status = GaugeMetricFamily(
            "pbdag_batches", "Batches in the queue table, by status.", labels=["status"]
        )
        for status in sorted(set(BATCH_STATUSES) | set(counts)):
            by_status.add_metric([status], counts.get(status, 0))
        yield by_status
        oldest = self.queue.oldest_waiting_received_at()
        age = 0.0 if oldest is None else max(0.0, self.clock() - oldest)
        yield GaugeMetricFamily(
            "pbdag_queue_oldest_age_seconds",
            "Seconds since the oldest batch still waiting (queued, or failed and waiting for a "
            "retry) was received; 0 when none waits.",
            value=age,
        )


class Metrics:
    """The registry of one process and the instruments the worker and the store update."""

    def __init__(
        self, queue: BatchQueue | None = None, clock: Callable[[], float] = time.time
    ) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        self.queue_collector = None if queue is None else QueueCollector(queue, clock)
        if self.queue_collector is not None:
            self.registry.register(self.queue_collector)
        self.decide_seconds = Histogram(
            "pbdag_decide_seconds",
            "Worker: decoding and deciding one batch (seconds).",
            buckets=DECIDE_BUCKETS,
            registry=self.registry,
        )
        self.append_seconds = Histogram(
            "pbdag_append_seconds",
            "Worker: the append transaction of one batch (events, projections, done).",
            buckets=APPEND_BUCKETS,
            registry=self.registry,
        )
        self.events_appended = Counter(
            "pbdag_events_appended",
            "Events this process appended to scene logs (batches and commands).",
            registry=self.registry,
        )
        self.batches_processed = Counter(
            "pbdag_batches_processed",
            "Batches this process's worker finished, by outcome.",
            labelnames=["outcome"],
            registry=self.registry,
        )
        for outcome in ("done", "retry", "dead", "lease_lost", "dropped"):
            self.batches_processed.labels(outcome)
        self.batches_handed_off = Counter(
            "pbdag_batches_handed_off",
            "Batches this process's worker took as the API decoded them, not decoding them again.",
            registry=self.registry,
        )
        self.dead_letters = Counter(
            "pbdag_dead_letters",
            "Batches this process parked as dead (never decodable, or out of attempts).",
            registry=self.registry,
        )
        self.worker_healthy = Gauge(
            "pbdag_worker_healthy",
            "1 while this process's worker can record what it does; 0 when it cannot (a full "
            "disk, a read-only or lost database): it then claims nothing.",
            registry=self.registry,
        )
        self.worker_healthy.set(1)

    @contextmanager
    def timed(self, histogram: Histogram) -> Iterator[None]:
        """Observe the duration of the block (also when it raises)."""
        start = time.perf_counter()
        try:
            yield
        finally:
            histogram.observe(time.perf_counter() - start)

    def exposition(self) -> bytes:
        """The registry in the Prometheus text format."""
        return generate_latest(self.registry)
