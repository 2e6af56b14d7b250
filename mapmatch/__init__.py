"""Map matching of fused vehicle positions onto OpenStreetMap road networks."""

from __future__ import annotations

from roadnets.errors import MapMatchError

__all__ = ["MapMatchError"]
