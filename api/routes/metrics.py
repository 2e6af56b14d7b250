"""``GET /metrics``: Prometheus metrics of the service (summed over workers)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import Response

from api.deps import MetricsDep  # noqa: TC001 - FastAPI resolves it at runtime
from api.routes.common import error_responses

__all__ = ["router"]

router = APIRouter(tags=["operations"])


@router.get(
    "/metrics",
    summary="Prometheus metrics",
    response_class=Response,
    responses={
        200: {"content": {"text/plain": {"schema": {"type": "string"}}}, "description": "Text."},
        **error_responses(401, 500),
    },
)
async def metrics(service_metrics: MetricsDep) -> Response:
    """Request counts and latencies by route and status, points matched, breaks."""
    content, media_type = service_metrics.render()
    return Response(content, media_type=media_type)
