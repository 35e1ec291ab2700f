"""Job records in Redis and artifacts in a directory: what the API and the workers share.

Keys (prefix `amprep:`): `job:<id>` a hash per job; `jobs` and `jobs:owner:<owner>` sorted sets by creation
time (the listing indexes); `events:<id>` a pub/sub channel carrying the job JSON on every change (and `{id, owner, deleted}` when deleted);
`idem:<owner>:<key>` idempotency keys; `result:<fingerprint>` finished results that may be reused; `unstarted` a sorted
set of the jobs that have not started, by the time their task was last sent (or the job made: what requeue_lost
watches);
`metrics:*` counters for /metrics. Artifacts live in `<data_dir>/jobs/<id>/{input,out}/`.
"""

from __future__ import annotations

import hashlib
import json
import os
import secrets
import shutil
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import redis
from redis.backoff import ExponentialBackoff
from redis.retry import Retry

P = "amprep:"
UNSTARTED = f"{P}unstarted"
STATUSES = ("queued", "running", "succeeded", "failed", "cancelled")
TERMINAL = ("succeeded", "failed", "cancelled")
#: Upper bounds (seconds) of the job-duration histogram buckets.
DURATION_BUCKETS = (0.5, 1, 2, 5, 10, 30, 60, 300, 900, 3600)
ANONYMOUS = "anonymous"

MEDIA_TYPES = {".stl": "model/stl", ".3mf": "model/3mf", ".json": "application/json", ".png": "image/png",
               ".npz": "application/octet-stream", ".csv": "text/csv", ".zip": "application/zip"}

# Move a job from one of the allowed states to another, atomically: KEYS[1] job hash, KEYS[2] the unstarted set;
# ARGV[1] allowed states (comma separated), ARGV[2] JSON object of fields to set, ARGV[3] the job id, ARGV[4] '1'
# to count an attempt too. A job that leaves `queued` leaves the unstarted set. Returns the old status, or false.
_TRANSITION = """
local cur = redis.call('HGET', KEYS[1], 'status')
if not cur then return false end
local ok = false
for s in string.gmatch(ARGV[1], '[^,]+') do if s == cur then ok = true end end
if not ok then return false end
local f = cjson.decode(ARGV[2])
for k, v in pairs(f) do redis.call('HSET', KEYS[1], k, v) end
if f['status'] and f['status'] ~= 'queued' then redis.call('ZREM', KEYS[2], ARGV[3]) end
if ARGV[4] == '1' then redis.call('HINCRBY', KEYS[1], 'attempts', 1) end
return cur
"""

# Mark a job's task sent, only while its record exists (a job deleted meanwhile must not come back as a bare hash):
# KEYS[1] job hash, KEYS[2] the unstarted set; ARGV[1] the job id, ARGV[2] the time.
_MARK_SENT = """
if redis.call('EXISTS', KEYS[1]) == 0 then return 0 end
redis.call('HSET', KEYS[1], 'sent', '1')
redis.call('ZADD', KEYS[2], ARGV[2], ARGV[1])
return 1
"""


def now() -> float:
    return time.time()


def iso(t: float) -> str:
    """UTC ISO 8601 with milliseconds."""
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(t)) + f".{int(t * 1000) % 1000:03d}Z"


def new_job_id() -> str:
    """Time-ordered, unguessable id: 12 hex of milliseconds then 16 random hex."""
    return f"{int(now() * 1000):012x}{secrets.token_hex(8)}"


def fingerprint(kind: str, input_sha: str, stl_sha: str, params: dict[str, Any]) -> str:
    """sha256 over what determines a result: kind, input bytes, optional STL bytes, params after defaults."""
    p = {k: v for k, v in params.items() if k not in ("callback_url", "reuse")}
    blob = json.dumps([kind, input_sha, stl_sha, p], sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()


@dataclass
class Job:
    """One job record: what the API shows and the worker updates."""

    id: str
    kind: str
    owner: str
    params: dict[str, Any]
    input: dict[str, Any]
    status: str = "queued"
    progress: float = 0.0
    stage: str = "queued"
    error: dict[str, str] | None = None
    artifacts: list[dict[str, Any]] = field(default_factory=list)
    result: dict[str, Any] | None = None
    provenance: dict[str, Any] = field(default_factory=dict)
    reused_from: str | None = None
    idempotency_key: str | None = None
    attempts: int = 0
    worker: str | None = None
    created_at: float = 0.0
    started_at: float | None = None
    finished_at: float | None = None

    _JSON = ("params", "input", "error", "artifacts", "result", "provenance")

    def to_redis(self) -> dict[str, str]:
        out: dict[str, str] = {}
        for k, v in asdict(self).items():
            out[k] = json.dumps(v) if k in self._JSON or v is None else str(v)
        return out

    @classmethod
    def from_redis(cls, h: dict[str, str]) -> Job:
        kw: dict[str, Any] = {}
        for k in cls.__dataclass_fields__:
            if k not in h:
                continue
            v = h[k]
            if k in cls._JSON or v == "null":
                kw[k] = json.loads(v)
            elif k in ("progress", "created_at", "started_at", "finished_at"):
                kw[k] = float(v)
            elif k == "attempts":
                kw[k] = int(v)
            else:
                kw[k] = v
        return cls(**kw)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def public(self) -> dict[str, Any]:
        """What clients see (GET, events, callbacks): no owner, ISO 8601 times, artifact URLs."""
        d = asdict(self)
        d.pop("owner")
        d["input"] = {k: ({kk: vv for kk, vv in v.items() if kk != "stored_as"} if isinstance(v, dict) else v)
                      for k, v in self.input.items() if k != "fingerprint"}
        for k in ("created_at", "started_at", "finished_at"):
            d[k] = iso(d[k]) if d[k] else None
        d["artifacts"] = [a | {"url": f"/v1/jobs/{self.id}/artifacts/{a['name']}"} for a in self.artifacts]
        return d

    @property
    def queue(self) -> str:
        from amprep.settings import QUEUE_OF_KIND

        return QUEUE_OF_KIND[self.kind]


def _retries_within(patience: float, base: float = 0.05, cap: float = 1.0) -> int:
    """The most retries whose backoffs min(cap, base·2^i) add up to at most `patience` seconds (at least 1)."""
    n, spent = 0, 0.0
    while spent + min(cap, base * 2**n) <= patience:
        spent += min(cap, base * 2**n)
        n += 1
    return max(1, n)


# SET key new IF it holds old (compare and set), keeping a TTL
_REBIND = """
if redis.call('GET', KEYS[1]) == ARGV[1] then
  redis.call('SET', KEYS[1], ARGV[2], 'EX', tonumber(ARGV[3]))
  return 1
end
return 0
"""


#: a job directory without a record, or a temporary file, unchanged this long is left over (a job deleted while its
#: worker still wrote its files, a crash between storing an upload and creating its record, an archive whose response
#: broke off); an upload or a response takes far less
ORPHAN_GRACE = 3600.0
#: seconds between two searches for left-over files (each lists the job directories)
ORPHAN_SWEEP = 600


def _entries(folder: Path) -> list[Path]:
    try:
        return list(folder.iterdir())
    except FileNotFoundError:
        return []


def _changed(path: Path) -> float:
    """Its last change (mtime); +inf when it went meanwhile."""
    try:
        return path.stat().st_mtime
    except FileNotFoundError:
        return float("inf")


class JobStore:
    """Job records (Redis) and artifact files (a directory) behind one small API; safe across processes."""

    def __init__(self, redis_url: str, data_dir: str | Path, retention_seconds: int = 7 * 24 * 3600,
                 patience: float = 0.5) -> None:
        """`patience`: seconds a command is retried while Redis does not answer (a restart): short for the API,
        which answers 503 with Retry-After, long for a worker, whose job must not be lost to a blip."""
        retry = Retry(ExponentialBackoff(cap=1.0, base=0.05), retries=_retries_within(patience))
        self.redis = redis.Redis.from_url(redis_url, decode_responses=True, health_check_interval=30, retry=retry,
                                          retry_on_error=[redis.ConnectionError, redis.TimeoutError])
        self.root = Path(data_dir) / "jobs"
        self.tmp = Path(data_dir) / "tmp"  # files made for one response (archives); sweep_orphans removes stragglers
        self.retention = retention_seconds
        self._transition = self.redis.register_script(_TRANSITION)
        self._rebind = self.redis.register_script(_REBIND)
        self._mark_sent = self.redis.register_script(_MARK_SENT)

    # -- records ---------------------------------------------------------------------------------------------
    def key(self, job_id: str) -> str:
        return f"{P}job:{job_id}"

    def create(self, job: Job) -> Job:
        job.created_at = job.created_at or now()
        pipe = self.redis.pipeline()
        pipe.hset(self.key(job.id), mapping=job.to_redis())
        pipe.zadd(f"{P}jobs", {job.id: job.created_at})
        pipe.zadd(f"{P}jobs:owner:{job.owner}", {job.id: job.created_at})
        pipe.hincrby(f"{P}metrics:jobs", f"{job.kind}|{job.status}", 1)
        if job.status == "queued":
            pipe.zadd(UNSTARTED, {job.id: job.created_at})
        pipe.execute()
        self.publish(job)
        return job

    def get(self, job_id: str) -> Job | None:
        if not job_id.isalnum():
            return None
        h = self.redis.hgetall(self.key(job_id))
        return Job.from_redis(h) if h else None

    def transition(self, job_id: str, allowed: Iterable[str], attempt: bool = False, **fields: Any) -> Job | None:
        """Set `fields` (and count an attempt if `attempt`) only if the job's status is one of `allowed` (atomic);
        the new job, or None."""
        enc = {k: json.dumps(v) if k in Job._JSON or v is None else str(v) for k, v in fields.items()}
        old = self._transition(keys=[self.key(job_id), UNSTARTED],
                               args=[",".join(allowed), json.dumps(enc), job_id, "1" if attempt else "0"])
        if not old:
            return None
        job = self.get(job_id)
        if job is None:
            return None
        if "status" in fields and fields["status"] != old:
            self.redis.hincrby(f"{P}metrics:jobs", f"{job.kind}|{job.status}", 1)
            if job.status in TERMINAL and job.started_at:
                self._observe_duration(job.kind, (job.finished_at or now()) - job.started_at)
            if job.status in TERMINAL:
                self.redis.expire(self.key(job_id), self.retention)
        self.publish(job)
        return job

    def set_progress(self, job_id: str, stage: str, fraction: float) -> Job | None:
        return self.transition(job_id, ("running",), stage=stage, progress=round(float(fraction), 4))

    def publish(self, job: Job) -> None:
        self.redis.publish(f"{P}events:{job.id}", json.dumps(job.to_dict()))

    @staticmethod
    def channel(job_id: str) -> str:
        return f"{P}events:{job_id}"

    def list(self, owner: str | None, status: str | None = None, kind: str | None = None,
             cursor: float | None = None, limit: int = 50) -> tuple[list[Job], float | None]:
        """Jobs newest first with created_at < cursor, filtered; (page, next cursor or None)."""
        index = f"{P}jobs" if owner is None else f"{P}jobs:owner:{owner}"
        hi: str | float = "+inf" if cursor is None else f"({cursor!r}"
        out: list[Job] = []
        while len(out) < limit:
            rows = self.redis.zrevrangebyscore(index, hi, "-inf", start=0, num=max(limit * 2, 50), withscores=True)
            if not rows:
                return out, None
            for job_id, score in rows:
                hi = f"({score!r}"
                job = self.get(job_id)
                if job is None:
                    self.redis.zrem(index, job_id)
                    continue
                if (status is None or job.status == status) and (kind is None or job.kind == kind):
                    out.append(job)
                    if len(out) == limit:
                        return out, job.created_at
        return out, None

    def delete(self, job: Job) -> None:
        """Remove a job's record, index entries and files."""
        pipe = self.redis.pipeline()
        pipe.delete(self.key(job.id))
        pipe.zrem(f"{P}jobs", job.id)
        pipe.zrem(f"{P}jobs:owner:{job.owner}", job.id)
        pipe.zrem(UNSTARTED, job.id)
        pipe.publish(self.channel(job.id), json.dumps({"id": job.id, "owner": job.owner, "deleted": True}))
        pipe.execute()
        shutil.rmtree(self.job_dir(job.id), ignore_errors=True)

    def discard_files(self, job_id: str) -> None:
        """Remove the files stored for a job that was never created (a refused or repeated request)."""
        shutil.rmtree(self.job_dir(job_id), ignore_errors=True)

    # -- idempotency and reuse ------------------------------------------------------------------------------
    def _idem(self, owner: str, key: str) -> str:
        return f"{P}idem:{owner}:{hashlib.sha256(key.encode()).hexdigest()}"

    def claim_idempotency(self, owner: str, key: str, job_id: str) -> str | None:
        """Bind `key` to `job_id` unless already bound: None if claimed, else the job id it names."""
        k = self._idem(owner, key)
        if self.redis.set(k, job_id, nx=True, ex=self.retention):
            return None
        return self.redis.get(k)

    def rebind_idempotency(self, owner: str, key: str, stale: str, job_id: str) -> bool:
        """Bind `key` to `job_id` if it still names `stale` (a job whose record was never written: Redis went away
        between the claim and the record); False when another request rebound it first."""
        return bool(self._rebind(keys=[self._idem(owner, key)], args=[stale, job_id, self.retention]))

    def mark_sent(self, job_id: str) -> None:
        """Record that the job's task reached the broker (now: requeue_lost counts from here)."""
        self._mark_sent(keys=[self.key(job_id), UNSTARTED], args=[job_id, repr(now())])

    def was_sent(self, job_id: str) -> bool:
        return self.redis.hget(self.key(job_id), "sent") == "1"

    def count_sent_again(self) -> None:
        self.redis.incr(f"{P}metrics:sent-again")

    def sent_again(self) -> int:
        """Job tasks sent again because the broker lost them (queue.requeue_lost)."""
        return int(self.redis.get(f"{P}metrics:sent-again") or 0)

    def unstarted(self, older_than: float) -> list[Job]:
        """Queued jobs made or last sent more than `older_than` seconds ago, oldest first (entries of jobs that
        started or went meanwhile are dropped)."""
        out = []
        for job_id in self.redis.zrangebyscore(UNSTARTED, "-inf", now() - older_than):
            job = self.get(job_id)
            if job is None or job.status != "queued":
                self.redis.zrem(UNSTARTED, job_id)
            else:
                out.append(job)
        return out

    def remember_result(self, fp: str, job_id: str) -> None:
        self.redis.set(f"{P}result:{fp}", job_id, ex=self.retention)

    def reusable(self, fp: str, owner: str) -> Job | None:
        """A succeeded job of this owner with the same fingerprint whose files are still there."""
        job_id = self.redis.get(f"{P}result:{fp}")
        job = self.get(job_id) if job_id else None
        if job is None or job.status != "succeeded" or job.owner != owner:
            return None
        if not all(self.artifact_path(job.id, a["name"]).exists() for a in job.artifacts):
            return None
        return job

    # -- files -----------------------------------------------------------------------------------------------
    def job_dir(self, job_id: str) -> Path:
        return self.root / job_id

    def input_path(self, job_id: str, name: str) -> Path:
        return self.job_dir(job_id) / "input" / name

    def artifact_path(self, job_id: str, name: str) -> Path:
        return self.job_dir(job_id) / "out" / name

    def add_artifact(self, job_id: str, path: Path) -> dict[str, Any]:
        """Describe a file already written under the job's out/ directory: name, media type, size, sha256."""
        h = hashlib.sha256()
        with path.open("rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        return {"name": path.name, "media_type": MEDIA_TYPES.get(path.suffix.lower(), "application/octet-stream"),
                "size": path.stat().st_size, "sha256": h.hexdigest()}

    def copy_artifacts(self, src: Job, dst_id: str) -> None:
        """Hard-link (else copy) a finished job's artifacts into another job's directory."""
        out = self.job_dir(dst_id) / "out"
        out.mkdir(parents=True, exist_ok=True)
        for a in src.artifacts:
            s, d = self.artifact_path(src.id, a["name"]), out / a["name"]
            try:
                os.link(s, d)
            except OSError:
                shutil.copyfile(s, d)

    # -- retention -------------------------------------------------------------------------------------------
    def sweep(self) -> int:
        """Delete ended jobs older than the retention (at most once a minute, or per retention/4, across all
        processes), and left-over files (sweep_orphans, at most every ORPHAN_SWEEP seconds)."""
        removed = self.sweep_orphans() if self.redis.set(f"{P}orphan-lock", "1", nx=True, ex=ORPHAN_SWEEP) else 0
        if not self.redis.set(f"{P}sweep-lock", "1", nx=True, ex=max(1, min(60, self.retention // 4))):
            return removed
        cutoff = now() - self.retention
        for job_id in self.redis.zrangebyscore(f"{P}jobs", "-inf", cutoff):
            job = self.get(job_id)
            if job is None:
                self.redis.zrem(f"{P}jobs", job_id)
                shutil.rmtree(self.job_dir(job_id), ignore_errors=True)
                removed += 1
            elif job.status in TERMINAL and (job.finished_at or job.created_at) < cutoff:
                self.delete(job)
                removed += 1
        return removed

    def sweep_orphans(self) -> int:
        """Remove each job directory that has no record and each temporary file (an archive being sent), last changed
        over ORPHAN_GRACE seconds ago; the number removed."""
        old = now() - ORPHAN_GRACE
        stale = [d for d in _entries(self.root) if d.is_dir() and d.name.isalnum() and _changed(d) < old]
        removed = 0
        for s in range(0, len(stale), 1000):
            batch = stale[s:s + 1000]
            pipe = self.redis.pipeline(transaction=False)
            for d in batch:
                pipe.exists(self.key(d.name))
            for d, kept in zip(batch, pipe.execute(), strict=True):
                if not kept:
                    shutil.rmtree(d, ignore_errors=True)
                    removed += 1
        for f in _entries(self.tmp):
            if f.is_file() and _changed(f) < old:
                f.unlink(missing_ok=True)
                removed += 1
        return removed

    # -- metrics ---------------------------------------------------------------------------------------------
    def _observe_duration(self, kind: str, seconds: float) -> None:
        key = f"{P}metrics:duration:{kind}"
        pipe = self.redis.pipeline()
        for b in DURATION_BUCKETS:
            if seconds <= b:
                pipe.hincrby(key, str(b), 1)
        pipe.hincrby(key, "count", 1)
        pipe.hincrbyfloat(key, "sum", seconds)
        pipe.execute()

    def job_counts(self) -> dict[tuple[str, str], int]:
        """Transitions into each (kind, status) since the store began."""
        raw = self.redis.hgetall(f"{P}metrics:jobs")
        return {tuple(k.split("|", 1)): int(v) for k, v in raw.items()}  # type: ignore[misc]

    def durations(self, kind: str) -> tuple[list[tuple[str, int]], int, float]:
        """Cumulative histogram buckets [(le, count)], count and sum of job durations of a kind."""
        raw = self.redis.hgetall(f"{P}metrics:duration:{kind}")
        buckets = [(str(float(b)), int(raw.get(str(b), 0))) for b in DURATION_BUCKETS]
        count = int(raw.get("count", 0))
        buckets.append(("+Inf", count))
        return buckets, count, float(raw.get("sum", 0.0))

    def queue_depth(self, queue: str) -> int:
        """Messages waiting in a Celery queue (Redis transport keeps each queue as a list)."""
        return int(self.redis.llen(queue))
