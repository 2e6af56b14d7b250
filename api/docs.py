"""
The service's documentation pages, ``/docs`` (Swagger UI) and ``/redoc`` (ReDoc), offline.

FastAPI's own pages load Swagger UI and ReDoc from a CDN (and a favicon and Google fonts), so
on a machine without internet, which is where a map-matching service often runs, ``/docs`` is
a blank page. Here both pages load the files that PyPI's ``fastapi-offline`` package ships
(Swagger UI 5 and ReDoc 2, installed with the service), served under :data:`ASSETS_PATH`.
``MAPMATCH_DOCS_ASSETS=cdn`` switches back to FastAPI's CDN links.
"""

from __future__ import annotations

import importlib.resources
import inspect
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fastapi.openapi.docs import (
    get_redoc_html,
    get_swagger_ui_html,
    get_swagger_ui_oauth2_redirect_html,
)
from fastapi.responses import Response
from fastapi.staticfiles import StaticFiles

if TYPE_CHECKING:
    from fastapi import FastAPI, Request
    from fastapi.responses import HTMLResponse

__all__ = ["ASSETS_PATH", "DOCS_URL", "REDOC_URL", "add_docs", "docs_assets_dir"]

DOCS_URL = "/docs"
REDOC_URL = "/redoc"
OAUTH2_REDIRECT_URL = "/docs/oauth2-redirect"
#: Where the bundled Swagger UI and ReDoc files are served.
ASSETS_PATH = "/docs-assets"
_FILES = ("swagger-ui-bundle.js", "swagger-ui.css", "redoc.standalone.js", "favicon.png")
#: Swagger UI options: no online validator badge (it would call validator.swagger.io).
_SWAGGER_PARAMETERS: dict[str, Any] = {"validatorUrl": None}
_REDOC_LOGO = b"https://cdn.redoc.ly/redoc/logo-mini.svg"
_EMPTY_SVG = b"data:image/svg+xml,%3Csvg xmlns='http://www.w3.org/2000/svg'/%3E"
#: FastAPI's own CDN links (the defaults of its page builders), for ``assets="cdn"``.
_CDN_DEFAULTS: dict[str, str] = {
    name: parameter.default
    for builder in (get_swagger_ui_html, get_redoc_html)
    for name, parameter in inspect.signature(builder).parameters.items()
    if isinstance(parameter.default, str) and parameter.default.startswith("https://")
}


def docs_assets_dir() -> Path:
    """
    The folder of the bundled Swagger UI and ReDoc files (from ``fastapi-offline``).

    Raises
    ------
    ImportError
        ``fastapi-offline`` is not installed, or lacks one of the files.
    """
    hint = "the offline /docs needs the fastapi-offline package: pip install fastapi-offline"
    try:
        folder = Path(str(importlib.resources.files("fastapi_offline") / "static"))
    except ModuleNotFoundError as exc:
        raise ImportError(hint) from exc
    missing = [name for name in _FILES if not (folder / name).is_file()]
    if missing:
        msg = f"{folder} lacks {', '.join(missing)}; reinstall fastapi-offline. {hint}"
        raise ImportError(msg)
    return folder


def add_docs(app: FastAPI, *, assets: str) -> None:
    """
    Add ``/docs``, its OAuth2 redirect and ``/redoc`` to an app built with no docs URLs.

    Parameters
    ----------
    app
        The app (``FastAPI(docs_url=None, redoc_url=None, ...)``).
    assets
        ``"bundled"``: the pages load the packaged files from :data:`ASSETS_PATH`;
        ``"cdn"``: FastAPI's default CDN links.
    """
    openapi_url = app.openapi_url or "/openapi.json"
    if assets == "bundled":
        folder = docs_assets_dir()
        redoc_js = _offline_redoc(folder / "redoc.standalone.js")

        async def redoc_bundle(_request: Request) -> Response:
            return Response(redoc_js, media_type="text/javascript; charset=utf-8")

        # the route comes before the mount, so it answers for this one file
        app.add_route(f"{ASSETS_PATH}/redoc.standalone.js", redoc_bundle, include_in_schema=False)
        app.mount(ASSETS_PATH, StaticFiles(directory=folder), name="docs-assets")

    def link(request: Request, argument: str, name: str) -> str:
        """The bundled file ``name``, or FastAPI's own CDN default for ``argument``."""
        if assets == "bundled":
            return f"{_root(request)}{ASSETS_PATH}/{name}"
        return _CDN_DEFAULTS[argument]

    async def swagger_ui(request: Request) -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=_root(request) + openapi_url,
            title=f"{app.title} - Swagger UI",
            swagger_js_url=link(request, "swagger_js_url", "swagger-ui-bundle.js"),
            swagger_css_url=link(request, "swagger_css_url", "swagger-ui.css"),
            swagger_favicon_url=link(request, "swagger_favicon_url", "favicon.png"),
            oauth2_redirect_url=_root(request) + OAUTH2_REDIRECT_URL,
            swagger_ui_parameters=_SWAGGER_PARAMETERS,
        )

    async def oauth2_redirect(_request: Request) -> HTMLResponse:
        return get_swagger_ui_oauth2_redirect_html()

    async def redoc(request: Request) -> HTMLResponse:
        return get_redoc_html(
            openapi_url=_root(request) + openapi_url,
            title=f"{app.title} - ReDoc",
            redoc_js_url=link(request, "redoc_js_url", "redoc.standalone.js"),
            redoc_favicon_url=link(request, "redoc_favicon_url", "favicon.png"),
            with_google_fonts=assets != "bundled",
        )

    app.add_route(DOCS_URL, swagger_ui, include_in_schema=False)
    app.add_route(OAUTH2_REDIRECT_URL, oauth2_redirect, include_in_schema=False)
    app.add_route(REDOC_URL, redoc, include_in_schema=False)


def _offline_redoc(path: Path) -> bytes:
    """
    ReDoc's bundle without its one request to the internet: the footer's Redocly logo.

    The bundle draws ``<img src="https://cdn.redoc.ly/redoc/logo-mini.svg">`` in the side
    menu's footer whatever its options; offline that is a failed request in the console. The
    URL is swapped for an empty inline SVG (the "API docs by Redocly" link stays).
    """
    text = path.read_bytes()
    if _REDOC_LOGO not in text:  # a newer ReDoc: nothing to swap, and nothing is broken
        return text
    return text.replace(_REDOC_LOGO, _EMPTY_SVG)


def _root(request: Request) -> str:
    return str(request.scope.get("root_path", "")).rstrip("/")
