"""``GET /v1/networks``: the road networks this service matches on."""

from __future__ import annotations

from fastapi import APIRouter

from api.deps import ReadyNetworksDep  # noqa: TC001 - FastAPI resolves it at runtime
from api.routes.common import error_responses
from api.schemas import NetworksResponse

__all__ = ["router"]

router = APIRouter(tags=["networks"])


@router.get(
    "/v1/networks",
    summary="The road networks this service matches on",
    response_model=NetworksResponse,
    responses=error_responses(401, 500, 503),
)
async def list_networks(networks: ReadyNetworksDep) -> NetworksResponse:
    """Id, source, bbox and counts of every network, the default first."""
    return NetworksResponse.model_validate({"networks": networks.describe()})
