"""
Leaflet's script and style sheet for the maps: bundled (from a registry package) or a CDN.

folium's maps link about a dozen files from CDNs (Leaflet, jQuery, Bootstrap, Font Awesome,
awesome-markers, ...), so a saved map or a notebook opened offline draws nothing. The match
map needs Leaflet alone; its files come from PyPI's ``xstatic-leaflet`` (part of the ``viz``
extra), and :func:`use_assets` either writes them into the page (``"inline"``: one
self-contained HTML file, which also works inside a notebook's output frame) or links the
same version from a CDN (``"cdn"``: a smaller file that needs the internet).
"""

from __future__ import annotations

import base64
import importlib.metadata
import re
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

if TYPE_CHECKING:
    import folium

__all__ = ["ASSET_MODES", "AssetMode", "leaflet_files", "leaflet_version", "use_assets"]

AssetMode = Literal["inline", "cdn"]

#: How a map gets Leaflet: written into the page, or linked from a CDN.
ASSET_MODES: tuple[AssetMode, ...] = ("inline", "cdn")

_DISTRIBUTION = "XStatic-Leaflet"
_DATA = "xstatic/pkg/leaflet/data"
#: The Leaflet version linked from the CDN when the bundled package is not installed.
_FALLBACK_VERSION = "1.9.3"
_CDN = "https://cdn.jsdelivr.net/npm/leaflet@{version}/dist/{name}"
_HINT = (
    "the bundled Leaflet files come from the xstatic-leaflet package: "
    "pip install mapmatch[viz] (or pass assets='cdn' to link them from a CDN instead)"
)


def leaflet_files() -> tuple[Path, Path]:
    """
    Paths of the bundled ``leaflet.js`` and ``leaflet.css``.

    Raises
    ------
    ImportError
        ``xstatic-leaflet`` is not installed.
    """
    try:
        dist = importlib.metadata.distribution(_DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError as exc:
        raise ImportError(_HINT) from exc
    js = Path(str(dist.locate_file(f"{_DATA}/leaflet.js")))
    css = Path(str(dist.locate_file(f"{_DATA}/leaflet.css")))
    for path in (js, css):
        if not path.is_file():
            msg = f"{path} is missing from the installed xstatic-leaflet; reinstall it. {_HINT}"
            raise ImportError(msg)
    return js, css


def leaflet_version() -> str:
    """The Leaflet version bundled (``"1.9.3"``), or the CDN default when none is."""
    try:
        packaged = importlib.metadata.version(_DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:
        return _FALLBACK_VERSION
    return ".".join(packaged.split(".")[:3])  # xstatic appends its own build number


@cache
def _inline_js() -> str:
    js, _ = leaflet_files()
    # a literal "</script" would end the element early; Leaflet has none, but be safe
    return js.read_text(encoding="utf-8").replace("</script", "<\\/script")


@cache
def _inline_css() -> str:
    _, css = leaflet_files()
    text = css.read_text(encoding="utf-8")

    def data_uri(match: re.Match[str]) -> str:
        image = css.parent / match.group(1)
        if not image.is_file():  # pragma: no cover - the package ships every image it names
            return match.group(0)
        encoded = base64.b64encode(image.read_bytes()).decode("ascii")
        return f"url(data:image/png;base64,{encoded})"

    return re.sub(r"url\((images/[\w.-]+\.png)\)", data_uri, text)


def use_assets(fmap: folium.Map, assets: AssetMode) -> None:
    """
    Make a folium map load Leaflet, and only Leaflet, the way ``assets`` says.

    Parameters
    ----------
    fmap
        The map; its links to folium's default CDN files are replaced.
    assets
        ``"inline"``: the bundled files written into the page (works offline, anywhere);
        ``"cdn"``: ``<script>``/``<link>`` to the same Leaflet version on a CDN.

    Raises
    ------
    ValueError
        ``assets`` is not one of :data:`ASSET_MODES`.
    ImportError
        ``"inline"`` without ``xstatic-leaflet`` installed.
    """
    from branca.element import CssLink, Element, JavascriptLink

    if assets not in ASSET_MODES:
        msg = f"assets must be one of {', '.join(map(repr, ASSET_MODES))}, got {assets!r}"
        raise ValueError(msg)
    root: Any = fmap.get_root()
    header = root.header
    # folium.Map.render adds default_js/default_css to the page header; ours replace them
    fmap.default_js = []
    fmap.default_css = []
    if assets == "inline":
        leaflet_files()  # raises ImportError naming the package before any cached text is used
        header.add_child(Element(f"<style>{_inline_css()}</style>"), name="leaflet_css")
        header.add_child(Element(f"<script>{_inline_js()}</script>"), name="leaflet")
    else:
        version = leaflet_version()
        css = CssLink(_CDN.format(version=version, name="leaflet.css"))
        js = JavascriptLink(_CDN.format(version=version, name="leaflet.js"))
        header.add_child(css, name="leaflet_css")
        header.add_child(js, name="leaflet")
