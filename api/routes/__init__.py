"""
The HTTP routes, one module per resource.

Each route is thin: read the request, call the service, answer. Errors are raised, never
answered here: :mod:`api.errors` maps them to their status and code.

- :mod:`api.routes.match`: ``POST /v1/match``
- :mod:`api.routes.networks`: ``GET /v1/networks``
- :mod:`api.routes.health`: ``GET /healthz``, ``GET /readyz``
- :mod:`api.routes.metrics`: ``GET /metrics``
- :mod:`api.routes.trips`: ``/v1/trips`` (live trips)
"""

from __future__ import annotations

from fastapi import APIRouter

from api.routes import health, match, metrics, networks, trips

__all__ = ["router"]

router = APIRouter()
for _module in (match, networks, health, metrics, trips):
    router.include_router(_module.router)
