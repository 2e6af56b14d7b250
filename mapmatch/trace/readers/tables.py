"""
Tables as a source: pandas DataFrames, GeoPandas GeoDataFrames of Points, Parquet files.

A GeoDataFrame's active geometry must be a Point in every row; it is converted to WGS84 and
replaces any ``lon``/``lat`` columns. A table's rows are numbered from 0 (``table row``),
a Parquet file's records from 1.
"""

from __future__ import annotations

import io
import sys

import numpy as np
import pandas as pd

from mapmatch.errors import InvalidTraceError
from mapmatch.trace.readers.grouping import group_rows
from mapmatch.trace.readers.raw import COORD_NAMES, SHOW, TABLE_ROW, Context, RawTrace

__all__ = ["read_parquet", "read_table", "table_frame"]


def table_frame(frame: pd.DataFrame, *, source_name: str = "<table>") -> pd.DataFrame:
    """
    A table with ``lon``/``lat`` columns: a GeoDataFrame's Points in WGS84, else as given.

    A GeoDataFrame's active geometry must be a Point in every row; it is converted to WGS84
    from its CRS (none = WGS84 assumed), and replaces any ``lon``/``lat`` columns of the table.

    Raises
    ------
    InvalidTraceError
        A row's geometry is missing, empty or not a Point.
    """
    gpd = sys.modules.get("geopandas")  # only a caller that has geopandas can pass a GeoDataFrame
    if gpd is None or not isinstance(frame, gpd.GeoDataFrame):
        return frame
    try:
        geom = frame.geometry
    except AttributeError:  # a GeoDataFrame without an active geometry column
        return pd.DataFrame(frame)
    missing = geom.isna().to_numpy(dtype=bool)
    kinds = [None if gone else str(k) for k, gone in zip(geom.geom_type, missing, strict=True)]
    empty = geom.is_empty.to_numpy(dtype=bool) & ~missing
    bad = np.flatnonzero(np.array([k != "Point" for k in kinds], dtype=bool) | empty)
    if bad.size:
        shown = ", ".join(
            f"row {i} is "
            + (
                "missing"
                if kinds[i] is None
                else f"an empty {kinds[i]}"
                if empty[i]
                else f"a {kinds[i]}"
            )
            for i in bad[:SHOW]
        )
        more = f" and {bad.size - SHOW} more" if bad.size > SHOW else ""
        msg = (
            f"table {source_name}: the geometry must be a Point in every row ({shown}{more}); "
            "turn lines into their vertices first (gdf.get_coordinates() or gdf.explode())"
        )
        raise InvalidTraceError(msg, field="geometry", rows=bad.tolist())
    if frame.crs is not None:
        geom = geom.to_crs(4326)
    plain = pd.DataFrame(frame.drop(columns=[geom.name]))
    plain = plain.drop(columns=[c for c in plain.columns if str(c).strip().lower() in COORD_NAMES])
    plain["lon"] = geom.x.to_numpy(dtype=np.float64)
    plain["lat"] = geom.y.to_numpy(dtype=np.float64)
    return plain


def read_table(table: pd.DataFrame, ctx: Context) -> list[RawTrace]:
    """The traces of a DataFrame or GeoDataFrame, grouped by its id columns."""
    frame = table_frame(table, source_name=ctx.name)
    numbers = np.arange(len(frame), dtype=np.int64)
    return group_rows(frame, numbers=numbers, label=TABLE_ROW, ctx=ctx)


def read_parquet(data: bytes, ctx: Context) -> list[RawTrace]:
    """The traces of a Parquet file, grouped by its id columns."""
    try:
        frame = pd.read_parquet(io.BytesIO(data))
    except (OSError, ValueError, ImportError) as exc:
        msg = f"is not readable as Parquet: {exc}"
        raise ctx.error(msg) from exc
    numbers = np.arange(1, len(frame) + 1, dtype=np.int64)
    return group_rows(frame.reset_index(drop=True), numbers=numbers, label="record", ctx=ctx)
