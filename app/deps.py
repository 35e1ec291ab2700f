"""Dependencies: settings, the job store, the Celery client and the caller's identity (API key → owner)."""

from __future__ import annotations

from typing import Annotated

from celery import Celery
from fastapi import Depends, Header, Request

from amprep.errors import ErrorCode
from amprep.settings import Settings
from amprep.store import ANONYMOUS, JobStore

from .auth import valid_key
from .problems import ApiError


def get_settings_dep(request: Request) -> Settings:
    return request.app.state.settings


def get_store(request: Request) -> JobStore:
    return request.app.state.store


def get_celery(request: Request) -> Celery:
    return request.app.state.celery


def get_owner(request: Request, authorization: Annotated[str | None, Header(
        description="`Bearer KEY`; required when the server has API keys configured")] = None) -> str:
    """The caller's owner id: the key's sha256 when keys are configured (a key sees only its jobs), else anonymous."""
    keys: frozenset[str] = request.app.state.key_hashes
    if not keys:
        return ANONYMOUS
    digest = valid_key(authorization, keys)  # auth.KeyGuard refused the request already when it is None
    if digest is None:
        raise ApiError(401, ErrorCode.UNAUTHORIZED, "the API key is not valid")
    return digest


SettingsDep = Annotated[Settings, Depends(get_settings_dep)]
StoreDep = Annotated[JobStore, Depends(get_store)]
CeleryDep = Annotated[Celery, Depends(get_celery)]
OwnerDep = Annotated[str, Depends(get_owner)]
