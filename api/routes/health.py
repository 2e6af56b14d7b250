"""``GET /healthz`` (the process answers) and ``GET /readyz`` (every network is loaded)."""

from __future__ import annotations

from fastapi import APIRouter

from api.deps import ReadyNetworksDep  # noqa: TC001 - FastAPI resolves it at runtime
from api.routes.common import error_responses
from api.schemas import HealthResponse, ReadyResponse

__all__ = ["router"]

router = APIRouter(tags=["operations"])


@router.get(
    "/healthz",
    summary="Liveness: the process answers",
    response_model=HealthResponse,
    responses=error_responses(500),
)
async def healthz() -> HealthResponse:
    """Always 200 while the process serves; needs no token."""
    return HealthResponse(status="alive")


@router.get(
    "/readyz",
    summary="Readiness: every network is loaded",
    response_model=ReadyResponse,
    responses=error_responses(401, 500, 503),
)
async def readyz(networks: ReadyNetworksDep) -> ReadyResponse:
    """200 once the networks are loaded; 503 while loading or after a failure."""
    return ReadyResponse(status="ready", networks=networks.ids())
