"""
Pictures of a match: an interactive map and a static figure, to see what the matcher did.

Needs the ``viz`` extra (``pip install mapmatch[viz]``: folium, matplotlib and the bundled
Leaflet files of ``xstatic-leaflet``); they are imported only when a drawing is made, so
``import mapmatch`` never loads them. Maps carry Leaflet in the page and draw the network's own
roads, so they work offline (``assets="cdn"`` links Leaflet from a CDN instead);
:func:`mapmatch.viz.browser.screenshot` takes a PNG of a saved map with headless Chromium.

>>> import roadnets, mapmatch, mapmatch.viz                      # doctest: +SKIP
>>> net = roadnets.load()                                         # doctest: +SKIP
>>> result = mapmatch.match(trace, net, diagnostics=True)         # doctest: +SKIP
>>> mapmatch.viz.match_map(result, net, candidates_of=12)         # doctest: +SKIP
>>> mapmatch.viz.match_figure(result, net).savefig("match.png")   # doctest: +SKIP
"""

from __future__ import annotations

from mapmatch.viz.assets import ASSET_MODES
from mapmatch.viz.data import CANDIDATE_COLUMNS, candidate_table, confidence_colour
from mapmatch.viz.leaflet import LAYER_NAMES, match_map
from mapmatch.viz.static import match_figure

__all__ = [
    "ASSET_MODES",
    "CANDIDATE_COLUMNS",
    "LAYER_NAMES",
    "candidate_table",
    "confidence_colour",
    "match_figure",
    "match_map",
]
