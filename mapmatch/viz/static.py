"""A static (matplotlib) figure of a match, for reports and the README."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from mapmatch.viz.data import (
    CONFIDENCE_COLOURS,
    MARK_COLOURS,
    SEGMENT_COLOURS,
    break_marks,
    candidate_table,
    confidence_colour,
    direction_arrows,
    edge_line,
    endpoints,
    matched_edge_lines,
    network_lines,
    trace_box_m,
    trace_gaps,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from mapmatch.result import MatchResult
    from roadnets import RoadNetwork

__all__ = ["match_figure"]

_INSTALL_HINT = "mapmatch.viz needs folium and matplotlib: pip install mapmatch[viz]"


def match_figure(
    result: MatchResult,
    net: RoadNetwork,
    *,
    ax: Axes | None = None,
    candidates_of: int | None = None,
    margin_m: float = 150.0,
) -> Figure:
    """
    Draw a match as a static figure, the same layers as :func:`mapmatch.viz.match_map`.

    Artists carry labels so a legend (and a test) can find them: ``road network``,
    ``matched path`` (one line collection per segment, ``matched path, segment <n>``, drawn
    over the fixes), ``direction``, ``start``, ``end``, ``raw points``, ``snapped points``
    (coloured by confidence, with a colour bar), ``gaps``, ``breaks`` and, with
    ``candidates_of``, ``candidates``. Axes are lon/lat degrees with the aspect set so that
    a metre is as long east-west as north-south.

    Parameters
    ----------
    result
        A match result.
    net
        The network the trace was matched on.
    ax
        Axes to draw on; a new figure otherwise.
    candidates_of
        Index of a fix whose candidate edges to draw, coloured by posterior.
    margin_m
        Metres of road network drawn around the trace's bounding box.

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn on.

    Raises
    ------
    ImportError
        matplotlib is not installed (``pip install mapmatch[viz]``).
    """
    try:
        import matplotlib.pyplot as plt
        from matplotlib.collections import LineCollection
        from matplotlib.colors import LinearSegmentedColormap
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise ImportError(_INSTALL_HINT) from exc

    if ax is None:
        _, ax = plt.subplots(figsize=(8, 8), layout="constrained")
    parent = ax.get_figure()
    figure = parent.figure if parent is not None else None
    if not isinstance(figure, Figure):  # pragma: no cover - axes always belong to a figure
        msg = "ax does not belong to a figure"
        raise ValueError(msg)
    box = trace_box_m(result, net, margin_m=margin_m)
    roads = [np.column_stack((ln.lon, ln.lat)) for ln in network_lines(net, box)]
    ax.add_collection(
        LineCollection(
            roads,
            colors=MARK_COLOURS["road"],
            linewidths=2.0,
            alpha=0.6,
            label="road network",
            zorder=1,
        )
    )
    for s, lines in enumerate(matched_edge_lines(result, net)):
        ax.add_collection(
            LineCollection(
                [np.column_stack((ln.lon, ln.lat)) for ln in lines],
                colors=SEGMENT_COLOURS[s % len(SEGMENT_COLOURS)],
                linewidths=3.0,
                alpha=0.9,
                label=f"matched path, segment {s}",
                zorder=6,
            )
        )

    p = result.points
    m = p.matched
    ax.scatter(
        p.raw_lon[m],
        p.raw_lat[m],
        s=6,
        c=MARK_COLOURS["raw"],
        marker="o",
        linewidths=0,
        label="raw points",
        zorder=4,
    )
    if p.outlier.any():
        ax.scatter(
            p.raw_lon[p.outlier],
            p.raw_lat[p.outlier],
            s=16,
            c=MARK_COLOURS["outlier"],
            marker="o",
            label="raw points, outliers",
            zorder=4,
        )
    if (~m).any():
        ax.scatter(
            p.raw_lon[~m],
            p.raw_lat[~m],
            s=30,
            c=MARK_COLOURS["unmatched"],
            marker="x",
            label="raw points, not matched",
            zorder=4,
        )
    links = [[(p.raw_lon[i], p.raw_lat[i]), (p.lon[i], p.lat[i])] for i in np.flatnonzero(m)]
    ax.add_collection(
        LineCollection(links, colors=MARK_COLOURS["link"], linewidths=0.5, linestyles=":", zorder=3)
    )
    cmap = LinearSegmentedColormap.from_list("confidence", list(CONFIDENCE_COLOURS))
    snapped = ax.scatter(
        p.lon[m],
        p.lat[m],
        s=22,
        c=p.confidence[m],
        cmap=cmap,
        vmin=0.0,
        vmax=1.0,
        edgecolors=MARK_COLOURS["snapped_edge"],
        linewidths=0.5,
        label="snapped points",
        zorder=5,
    )
    figure.colorbar(snapped, ax=ax, shrink=0.6, label="confidence")

    gaps = trace_gaps(result, net)
    if gaps:
        ax.add_collection(
            LineCollection(
                [np.column_stack((g.lon, g.lat)) for g in gaps],
                colors=MARK_COLOURS["gap"],
                linewidths=2.0,
                linestyles=(0, (4, 3)),
                label="gaps",
                zorder=7,
            )
        )
    marks = break_marks(result)
    if marks:
        joins = [
            [(p.lon[b.previous], p.lat[b.previous]), (p.lon[b.start], p.lat[b.start])]
            for b in marks
            if b.previous >= 0
        ]
        ax.add_collection(
            LineCollection(
                joins, colors=MARK_COLOURS["break"], linewidths=2.0, linestyles="--", zorder=7
            )
        )
        starts = np.array([b.start for b in marks])
        ax.scatter(
            p.lon[starts],
            p.lat[starts],
            s=200,
            facecolors="none",
            edgecolors=MARK_COLOURS["break"],
            linewidths=2.0,
            label="breaks",
            zorder=8,
        )
    # a triangle per arrow, turned to its bearing (marker angles are counter-clockwise)
    for k, arrow in enumerate(direction_arrows(result, net)):
        ax.scatter(
            [arrow.lon],
            [arrow.lat],
            s=38,
            c=SEGMENT_COLOURS[arrow.segment % len(SEGMENT_COLOURS)],
            marker=(3, 0, round(-arrow.bearing_deg)),
            edgecolors="#ffffff",
            linewidths=0.8,
            label="direction" if k == 0 else "_direction",
            zorder=9,
        )
    (start_lon, start_lat, _), (end_lon, end_lat, _) = endpoints(result)
    for lon, lat, kind, marker in (
        (start_lon, start_lat, "start", "o"),
        (end_lon, end_lat, "end", "s"),
    ):
        ax.scatter(
            [lon],
            [lat],
            s=70,
            c=MARK_COLOURS[kind],
            marker=marker,
            edgecolors="#ffffff",
            linewidths=1.5,
            label=kind,
            zorder=10,
        )

    if candidates_of is not None:
        table = candidate_table(result, net, candidates_of)
        edges = [np.column_stack(edge_line(net, int(e))) for e in table["edge"]]
        colours = [confidence_colour(float(c)) for c in table["posterior"]]
        widths = [5.0 if c else 2.5 for c in table["chosen"]]
        ax.add_collection(
            LineCollection(edges, colors=colours, linewidths=widths, label="candidates", zorder=3)
        )
        fix = candidates_of % len(p.time_s)
        ax.scatter(
            [p.raw_lon[fix]],
            [p.raw_lat[fix]],
            s=160,
            facecolors="none",
            edgecolors="#000000",
            linewidths=2.0,
            label=f"fix {fix}",
            zorder=6,
        )

    lon0, lat0 = net.unproject(np.array([box[0]]), np.array([box[1]]))
    lon1, lat1 = net.unproject(np.array([box[2]]), np.array([box[3]]))
    ax.set_xlim(float(lon0[0]), float(lon1[0]))
    ax.set_ylim(float(lat0[0]), float(lat1[0]))
    ax.set_aspect(1.0 / math.cos(math.radians(0.5 * float(lat0[0] + lat1[0]))))
    ax.ticklabel_format(useOffset=False)
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    check = result.distance_check
    ax.set_title(
        f"{result.trace_id}: {result.matched_length_m:.0f} m matched, "
        f"{len(result.segments)} segment(s), distance check {check.verdict}"
    )
    ax.legend(loc="upper left", fontsize="small", framealpha=0.8)
    return figure
