"""Waiting on a job without polling: Redis pub/sub of the job's channel (redis.asyncio)."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from typing import Any

import redis.asyncio as aioredis

from amprep.store import TERMINAL, Job, JobStore


async def job_updates(aredis: aioredis.Redis, store: JobStore, job_id: str, timeout: float | None,
                      owner: str) -> AsyncIterator[Job]:
    """Yield the job now and on every change, until it ends, disappears or `timeout` seconds pass."""
    loop = asyncio.get_running_loop()
    deadline = None if timeout is None else loop.time() + timeout
    pubsub = aioredis.Redis.pubsub(aredis)
    try:
        await pubsub.subscribe(store.channel(job_id))
        job = store.get(job_id)  # read after subscribing: no change can fall between the two
        while job is not None and job.owner == owner:
            yield job
            if job.status in TERMINAL:
                return
            while True:
                wait = 15.0 if deadline is None else deadline - loop.time()
                if wait <= 0:
                    return
                msg = await pubsub.get_message(ignore_subscribe_messages=True, timeout=min(wait, 15.0))
                if msg is not None:
                    # the message says something changed; read the job itself: messages published between our
                    # subscribe and first read arrive after it, older than what was already yielded
                    job = store.get(job_id)
                    break
                if deadline is None:
                    job = store.get(job_id)  # idle: re-read (and let the caller send a keep-alive)
                    break
    finally:
        await pubsub.aclose()


async def wait_for_end(aredis: aioredis.Redis, store: JobStore, job_id: str, timeout: float, owner: str) -> Job | None:
    """The job once it has ended, or as it is when `timeout` seconds have passed."""
    last = None
    async for job in job_updates(aredis, store, job_id, timeout, owner):
        last = job
    return store.get(job_id) if last is None or last.status not in TERMINAL else last


async def owner_updates(aredis: aioredis.Redis, owner: str) -> AsyncIterator[dict[str, Any]]:
    """Yield every change of the owner's jobs as published (the public job JSON, or `{id, deleted: true}`), forever;
    an idle 15 s yields `{}` (for the caller's keep-alive and disconnect check)."""
    pubsub = aioredis.Redis.pubsub(aredis)
    try:
        await pubsub.psubscribe(JobStore.channel("*"))
        while True:
            msg = await pubsub.get_message(ignore_subscribe_messages=True, timeout=15.0)
            if msg is None:
                yield {}
                continue
            data = json.loads(msg["data"])
            if data.get("owner") != owner:
                continue
            if data.get("deleted"):
                yield {"id": data["id"], "deleted": True}
            else:
                yield Job(**data).public()
    finally:
        await pubsub.aclose()
