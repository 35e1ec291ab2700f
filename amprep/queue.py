"""The Celery app factory shared by the workers (which add the tasks) and the API (which sends by name), and the
watch that sends again a task the broker lost."""

from __future__ import annotations

import json
import time

from celery import Celery
from kombu import Queue
from kombu.transport.redis import Channel as RedisChannel

from amprep.jobs.params import KINDS as _KINDS
from amprep.settings import CALLBACK_QUEUE, KINDS, QUEUE_OF_KIND, Settings, get_settings
from amprep.store import JobStore, P

TASK_OF_KIND = {kind: _KINDS[kind].task for kind in KINDS}
CALLBACK_TASK = "amprep.callback"


def make_celery(settings: Settings | None = None, name: str = "amprep") -> Celery:
    """A Celery app on the settings' Redis: late acks, re-queue on worker loss, one job per process at a time."""
    s = settings or get_settings()
    app = Celery(name, broker=s.redis_url)
    annotations = {}
    for kind in KINDS:
        soft, hard = s.time_limits(kind)
        annotations[TASK_OF_KIND[kind]] = {"soft_time_limit": soft, "time_limit": hard}
    app.conf.update(
        task_ignore_result=True,  # job records live in the store, not in a result backend
        task_acks_late=True,  # a message is acknowledged only when its job has ended...
        task_reject_on_worker_lost=True,  # ...and goes back to the queue when the process running it dies
        worker_prefetch_multiplier=1,
        worker_max_tasks_per_child=s.max_jobs_per_process,  # a fresh process after N jobs (OCCT leaks)
        task_queues=[Queue("quick"), Queue("heavy"), Queue(CALLBACK_QUEUE)],
        task_default_queue="quick",
        task_routes={TASK_OF_KIND[k]: {"queue": q} for k, q in QUEUE_OF_KIND.items()}
        | {CALLBACK_TASK: {"queue": CALLBACK_QUEUE}},
        task_annotations=annotations,
        # Unacknowledged messages of a worker host that vanished whole come back after this many seconds:
        # longer than any job may run, so a live job is never delivered twice.
        broker_transport_options={"visibility_timeout": s.hard_time_limit_heavy + 300},
        broker_connection_retry_on_startup=True,
        worker_hijack_root_logger=False,
        worker_send_task_events=False,
        task_send_sent_event=False,
    )
    return app


def _task_ids(raw: list[str], wrapped: bool) -> list[str]:
    """The task ids of kombu's Redis messages: queue entries (the message JSON) or unacked entries
    ([message, exchange, routing key])."""
    out = []
    for r in raw:
        try:
            m = json.loads(r)
            out.append(str((m[0] if wrapped else m)["headers"]["id"]))
        except (ValueError, KeyError, IndexError, TypeError):
            continue
    return out


def requeue_lost(store: JobStore, celery: Celery, after: float) -> list[str]:
    """Send again the task of each job still queued `after` seconds after it was made or last sent whose message is
    neither waiting in its queue nor held by a worker since less than `after` (a message lost to a broker restart, a
    reservation a worker dropped when its connection went, a send the broker refused); the job ids sent again. One
    process at a time."""
    r = store.redis
    if not r.set(f"{P}requeue-lock", "1", nx=True, ex=max(5, int(after))):
        return []
    try:
        jobs = store.unstarted(after)
        if not jobs:
            return []
        waiting = set()
        for queue in sorted({job.queue for job in jobs}):
            waiting.update(_task_ids(r.lrange(queue, 0, -1), wrapped=False))
        tags = r.zrangebyscore(RedisChannel.unacked_index_key, "-inf", time.time() - after)
        stale = dict(zip(_task_ids(r.hmget(RedisChannel.unacked_key, tags) if tags else [], wrapped=True), tags))
        held = set(_task_ids(list(r.hvals(RedisChannel.unacked_key)), wrapped=True)) - set(stale)
        sent = []
        for job in jobs:
            current = store.get(job.id)  # read after the queues: a job a worker took meanwhile is running by now
            if job.id in waiting or job.id in held or current is None or current.status != "queued":
                continue
            if job.id in stale:  # kombu would restore it only after its visibility timeout (hours)
                r.pipeline().zrem(RedisChannel.unacked_index_key, stale[job.id]).hdel(
                    RedisChannel.unacked_key, stale[job.id]).execute()
            celery.send_task(TASK_OF_KIND[job.kind], args=[job.id], task_id=job.id)
            store.mark_sent(job.id)
            store.count_sent_again()
            sent.append(job.id)
        return sent
    finally:
        r.delete(f"{P}requeue-lock")
