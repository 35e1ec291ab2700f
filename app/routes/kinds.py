"""/v1/kinds: the job kinds and their parameters from their one definition (the dashboard's form is built from it)."""

from __future__ import annotations

from fastapi import APIRouter

from amprep.jobs.params import KINDS

from ..models import KindInfo

router = APIRouter(prefix="/v1", tags=["jobs"])


@router.get("/kinds", operation_id="list_kinds", response_model=list[KindInfo],
            summary="The job kinds and every parameter's type, default, bounds, unit and help")
async def list_kinds() -> list[KindInfo]:
    return [KindInfo.of(k) for k in KINDS.values()]
