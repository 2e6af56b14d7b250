"""
``uvicorn api.main:app``: the service's app, with settings from the environment.

The settings are read from the ``MAPMATCH_*`` environment when this module is imported.

``mapmatch serve`` does not use this module: it builds its settings from the command line and
calls :func:`api.app.create_app` in each worker (:mod:`api.server`).
"""

from __future__ import annotations

from api.app import create_app

__all__ = ["app", "create_app"]

app = create_app()
