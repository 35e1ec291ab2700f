"""Prometheus metrics read from the shared store at scrape time, so every API replica reports the same."""

from __future__ import annotations

from collections.abc import Iterator

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, HistogramMetricFamily
from prometheus_client.registry import Collector

from amprep.settings import CALLBACK_QUEUE, KINDS
from amprep.store import JobStore


class StoreCollector(Collector):
    """amprep_jobs_total{kind,status}, amprep_job_duration_seconds{kind}, amprep_queue_depth{queue},
    amprep_tasks_sent_again_total."""

    def __init__(self, store: JobStore) -> None:
        self.store = store

    def collect(self) -> Iterator[CounterMetricFamily | GaugeMetricFamily | HistogramMetricFamily]:
        jobs = CounterMetricFamily("amprep_jobs", "Jobs entering each status, by kind", labels=["kind", "status"])
        for (kind, status), n in sorted(self.store.job_counts().items()):
            jobs.add_metric([kind, status], n)
        yield jobs
        hist = HistogramMetricFamily("amprep_job_duration_seconds", "Run time of ended jobs", labels=["kind"])
        for kind in KINDS:
            buckets, _, total = self.store.durations(kind)
            hist.add_metric([kind], buckets, total)
        yield hist
        depth = GaugeMetricFamily("amprep_queue_depth", "Messages waiting per queue", labels=["queue"])
        for q in ("quick", "heavy", CALLBACK_QUEUE):
            depth.add_metric([q], self.store.queue_depth(q))
        yield depth
        yield CounterMetricFamily("amprep_tasks_sent_again", "Job tasks the broker lost, sent again",
                                  value=self.store.sent_again())
