"""The Celery app factory shared by the workers (which add the tasks) and the API (which sends by name)."""

from __future__ import annotations

from celery import Celery
from kombu import Queue

from amprep.jobs.params import KINDS as _KINDS
from amprep.settings import CALLBACK_QUEUE, KINDS, QUEUE_OF_KIND, Settings, get_settings

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
