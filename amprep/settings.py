"""Service settings from `AMPREP_*` environment variables (pydantic-settings), built lazily by get_settings()."""

from __future__ import annotations

import hashlib
from functools import lru_cache
from pathlib import Path
from typing import Annotated

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from amprep.jobs.params import KINDS as _KINDS

KINDS = tuple(_KINDS)
#: Which Celery queue each job kind goes to: a long refine never blocks conversions.
QUEUE_OF_KIND = {k.name: k.queue for k in _KINDS.values()}
CALLBACK_QUEUE = "callbacks"


def hash_key(key: str) -> str:
    """sha256 hex of an API key: what the settings hold and what a job records as its owner."""
    return hashlib.sha256(key.encode()).hexdigest()


class Settings(BaseSettings):
    """Everything the API, the workers and `amprep serve` read from the environment (prefix AMPREP_)."""

    model_config = SettingsConfigDict(env_prefix="AMPREP_", extra="ignore")

    redis_url: str = Field("redis://127.0.0.1:6379/0", description="Broker and job records")
    data_dir: Path = Field(Path("amprep-data"), description="Uploads and artifacts (a shared volume for many hosts)")
    max_upload_bytes: int = Field(200 * 1024 * 1024, gt=0, description="Per request, enforced while streaming")
    retention_seconds: int = Field(7 * 24 * 3600, gt=0, description="Finished jobs and their files are kept this long")
    api_keys: Annotated[list[str], NoDecode] = Field(
        default_factory=list, description="sha256 hex digests of the accepted API keys (comma separated)")
    callback_secret: str = Field("", description="HMAC-SHA256 key for callback signatures")
    callback_retries: int = Field(5, ge=0)
    callback_allow: Annotated[list[str], NoDecode] = Field(
        default_factory=list, description="Addresses or networks (comma separated, e.g. 10.0.0.0/8) callbacks may "
        "reach although loopback, private, link-local or reserved; none by default")
    soft_time_limit_quick: int = Field(600, gt=0, description="Seconds before a convert/analyze job is told to stop")
    hard_time_limit_quick: int = Field(660, gt=0)
    soft_time_limit_heavy: int = Field(3600, gt=0, description="Seconds before a refine job is told to stop")
    hard_time_limit_heavy: int = Field(3720, gt=0)
    max_jobs_per_process: int = Field(20, gt=0, description="A worker process is replaced after this many jobs")
    requeue_after_seconds: int = Field(60, gt=0, description="A queued job whose task is in no queue and held by no "
                                       "worker this long after it was sent is sent again (a task lost to a broker "
                                       "restart)")
    max_crashes: int = Field(2, gt=0, description="Worker-process deaths before a job fails with worker_crashed")
    max_triangles: int = Field(20_000_000, gt=0, description="The most triangles any job may output: a job's own "
                               "max_triangles above it is lowered to it")
    memory_limit_mb: int = Field(8192, ge=0, description="Address space a job may add to its worker process (RLIMIT_AS, "
                                 "MiB); past it the job fails with memory_limit. 0: no limit")
    allow_insecure_bind: bool = Field(False, description="Serve on a non-loopback address without API keys")

    @field_validator("api_keys", mode="before")
    @classmethod
    def _split_keys(cls, value: object) -> object:
        if isinstance(value, str):
            return [k.strip().lower() for k in value.split(",") if k.strip()]
        return value

    @field_validator("callback_allow", mode="before")
    @classmethod
    def _split_networks(cls, value: object) -> object:
        if isinstance(value, str):
            return [n.strip() for n in value.split(",") if n.strip()]
        return value

    @field_validator("callback_allow")
    @classmethod
    def _networks(cls, value: list[str]) -> list[str]:
        from amprep.callbacks import networks
        from amprep.errors import AmprepError

        try:
            networks(value)  # an entry that is no address or network stops the start-up, with its reason
        except AmprepError as exc:
            raise ValueError(exc.message) from None
        return value

    @field_validator("api_keys")
    @classmethod
    def _hex_digests(cls, value: list[str]) -> list[str]:
        for k in value:
            if len(k) != 64 or any(c not in "0123456789abcdef" for c in k):
                raise ValueError("AMPREP_API_KEYS holds sha256 hex digests of keys (see `amprep key`), not keys")
        return value

    def time_limits(self, kind: str) -> tuple[int, int]:
        """(soft, hard) seconds for a job kind."""
        if QUEUE_OF_KIND[kind] == "heavy":
            return self.soft_time_limit_heavy, self.hard_time_limit_heavy
        return self.soft_time_limit_quick, self.hard_time_limit_quick

    @property
    def artifacts_dir(self) -> Path:
        return self.data_dir / "jobs"


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The process's settings, read from the environment on first use (tests clear the cache to override)."""
    return Settings()
