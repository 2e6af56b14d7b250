"""
The input columns of a trace, each declared once: name, aliases, unit, kind, bounds, doc.

(Over 400 lines on purpose: the declaration is the documentation of every column.)

Every place that knows the columns reads them from here: :class:`~mapmatch.trace.Trace`
validation (which column is required, the bounds and their messages), every reader (the
names a GPX tag, a GeoJSON property or a CSV header may use, the id columns a table is
grouped by) and the HTTP layer's point model (generated from :func:`columns`, see below).
:data:`~mapmatch.trace.FIELD_ALIASES` is derived from the same declaration.

A point column (:class:`Column`) is one per-fix value: ``time``, ``lat``, ``lon``,
``heading``, ``speed``, ``accuracy``, ``hdop``, ``odometer``, ``segment``. Names are matched
case-insensitively against :attr:`Column.names`; a column whose name is no alias is ignored.
An id column (:class:`IdColumn`) names the trace a table row belongs to (``trace_id``,
``vehicle_id`` ...); its names are compared ignoring case, ``_``, ``-``, spaces and dots.

How a web layer uses it
-----------------------
This module imports nothing beyond the standard library, so a web layer can build its
request model from it without pulling in numpy or pandas, and the matcher core stays free of
any web framework. For each :class:`Column` of :func:`columns`:

- the field name is :attr:`Column.name`, the accepted keys :attr:`Column.names` (give them to
  the framework's alias mechanism, e.g. pydantic ``AliasChoices(*col.names)``);
- the value type follows :attr:`Column.json_types` (``("number",)``, or ``("number",
  "string")`` for ``time``); :attr:`Column.required` says whether a point must carry it, and
  :attr:`Column.nullable` whether ``null`` means "unknown";
- the bounds are :attr:`Column.gt`, :attr:`Column.ge` and :attr:`Column.le` (``None``: no
  bound that side), always on finite values; the help text is :meth:`Column.describe`, the
  OpenAPI example :attr:`Column.example`.

For example, with pydantic (in the web layer, never here)::

    fields = {}
    for col in input_columns():
        kind = float | str if col.kind == "time" else float
        fields[col.name] = (
            kind if col.required else kind | None,
            Field(
                ... if col.required else None,
                validation_alias=AliasChoices(*col.names),
                gt=col.gt, ge=col.ge, le=col.le,
                description=col.describe(),
                examples=[col.example] if col.example is not None else None,
            ),
        )
    PointIn = create_model("PointIn", **fields)

The generated model documents the points (OpenAPI) and may check a request's shape, but
the points themselves are handed as they came (a list of dicts) to the library's reader,
``mapmatch.read_traces(body, format="json")`` or ``Trace.from_records(points)``: it is the
authority on every rule (names in any case, epoch units, whole-trace rules such as "all
times or none", sorting and merging) and its :class:`~mapmatch.errors.InvalidTraceError`
carries ``field`` and ``rows`` for the HTTP error body. Checking the bounds twice is
harmless; checking different bounds is what this module exists to prevent.

Examples
--------
>>> [c.name for c in input_columns(required_only=True)]
['lat', 'lon']
>>> column("Longitude").name, column("lng").names
('lon', ('lon', 'lng', 'longitude'))
>>> column("speed").rule(), column("lat").rule()
('>= 0', '>= -90 and <= 90')
>>> canonical("Heading_Deg"), canonical("elevation")
('heading', None)
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final, Literal

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = [
    "COLUMNS",
    "FIELD_ALIASES",
    "ID_COLUMNS",
    "TRACE_ID_COLUMNS",
    "Column",
    "ColumnKind",
    "IdColumn",
    "canonical",
    "column",
    "id_kind",
    "input_columns",
    "normal_id_name",
]

ColumnKind = Literal["time", "number", "label"]


@dataclass(frozen=True, slots=True)
class Column:
    """
    One per-fix input column.

    Attributes
    ----------
    name
        Canonical name, as in error messages (``InvalidTraceError.field``) and
        ``Trace.to_dataframe``.
    aliases
        Other accepted names (matched case-insensitively, like ``name``).
    kind
        ``"time"`` (epoch seconds, ms, us or ns told apart by size, or ISO-8601 text, or
        datetimes), ``"number"`` (a real value in ``unit``) or ``"label"`` (a number naming
        a known piece of the trace: equal neighbours are one piece).
    unit
        Unit of the value: ``"s"``, ``"deg"``, ``"m/s"``, ``"m"``; empty for a pure number.
    description
        What the value is and how the matcher uses it (one or two sentences).
    required
        Whether every trace must have the column (``lat`` and ``lon``).
    nullable
        Whether a row may leave the value blank (``None``/NaN/empty text) to mean unknown.
        ``time`` is all-or-none: blank in every row (no times) or in none.
    gt, ge, le
        Bounds on the value: greater than, at least, at most (``None``: none that side).
        Infinite values are refused, except where ``wraps`` (an infinite heading is unknown).
    wraps
        The value is taken modulo this (``heading``: 360), so it has no bounds.
    attribute
        The :class:`~mapmatch.trace.Trace` attribute holding the validated values
        (``time_s``, ``heading_deg`` ...); ``None`` for ``hdop`` (it fills ``accuracy_m``).
    example
        A typical value, for documentation.
    """

    name: str
    aliases: tuple[str, ...]
    kind: ColumnKind
    unit: str
    description: str
    required: bool = False
    nullable: bool = True
    gt: float | None = None
    ge: float | None = None
    le: float | None = None
    wraps: float | None = None
    attribute: str | None = None
    example: float | str | None = None

    @property
    def names(self) -> tuple[str, ...]:
        """Every accepted name, the canonical one first."""
        return (self.name, *self.aliases)

    @property
    def json_types(self) -> tuple[str, ...]:
        """The JSON types a value may have: ``("number", "string")`` for time, else number."""
        return ("number", "string") if self.kind == "time" else ("number",)

    @property
    def bounded(self) -> bool:
        """Whether the column has a bound (``gt``, ``ge`` or ``le``)."""
        return self.gt is not None or self.ge is not None or self.le is not None

    def rule(self) -> str:
        """
        The bounds as words (``"> 0"``, ``">= -90 and <= 90"``); empty without bounds.

        Examples
        --------
        >>> column("accuracy").rule(), column("odometer").rule()
        ('> 0', '')
        """
        parts = []
        if self.gt is not None:
            parts.append(f"> {self.gt:g}")
        if self.ge is not None:
            parts.append(f">= {self.ge:g}")
        if self.le is not None:
            parts.append(f"<= {self.le:g}")
        return " and ".join(parts)

    def describe(self) -> str:
        """
        Help text: the description, the unit, the bounds and the aliases.

        Examples
        --------
        >>> column("speed").describe()
        'Speed over ground; unknown when blank. Unit m/s; must be >= 0. Alias `speed_mps`.'
        """
        parts = [self.description]
        unit = f"Unit {self.unit}" if self.unit else ""
        rule = f"must be {self.rule()}" if self.rule() else ""
        if unit or rule:
            parts.append("; ".join(p for p in (unit, rule) if p) + ".")
        if self.aliases:
            names = ", ".join(f"`{a}`" for a in self.aliases)
            parts.append(f"Alias{'es' if len(self.aliases) > 1 else ''} {names}.")
        return " ".join(parts)


COLUMNS: Final[tuple[Column, ...]] = (
    Column(
        "time",
        ("t", "timestamp", "datetime", "ts"),
        "time",
        "s",
        "When the fix was taken: epoch seconds (milli-, micro- and nanosecond epochs are "
        "recognised by size and converted) or ISO-8601 text (no zone = UTC). Optional: "
        "without times the trace is matched by distance only; blank in some rows and not in "
        "others is an error. Rows out of time order are sorted, rows sharing a time are all "
        "kept in order, a row repeating an earlier one exactly is merged; all reported.",
        attribute="time_s",
        example=1700000000.0,
    ),
    Column(
        "lat",
        ("latitude",),
        "number",
        "deg",
        "Latitude, WGS84 degrees (or the frame named by crs: GCJ-02, BD-09).",
        required=True,
        nullable=False,
        ge=-90.0,
        le=90.0,
        attribute="lat",
        example=43.7384,
    ),
    Column(
        "lon",
        ("lng", "longitude"),
        "number",
        "deg",
        "Longitude, WGS84 degrees (or the frame named by crs: GCJ-02, BD-09).",
        required=True,
        nullable=False,
        ge=-180.0,
        le=180.0,
        attribute="lon",
        example=7.4246,
    ),
    Column(
        "heading",
        ("bearing", "course", "heading_deg"),
        "number",
        "deg",
        "Direction of travel, degrees clockwise from north, any value (taken modulo 360); "
        "unknown when blank or not finite.",
        wraps=360.0,
        attribute="heading_deg",
        example=90.0,
    ),
    Column(
        "speed",
        ("speed_mps",),
        "number",
        "m/s",
        "Speed over ground; unknown when blank.",
        ge=0.0,
        attribute="speed_mps",
        example=8.5,
    ),
    Column(
        "accuracy",
        ("accuracy_m",),
        "number",
        "m",
        "1-sigma horizontal position error; widens the fix's search radius and replaces "
        "sigma_m when larger; unknown when blank.",
        gt=0.0,
        attribute="accuracy_m",
        example=4.0,
    ),
    Column(
        "hdop",
        (),
        "number",
        "",
        "Horizontal dilution of precision; fills an unknown accuracy as hdop x 5 m "
        "(mapmatch.trace.UERE_M); unknown when blank.",
        gt=0.0,
        example=0.9,
    ),
    Column(
        "odometer",
        ("odometer_m",),
        "number",
        "m",
        "Cumulative fused distance, never decreasing in time; the distance check uses "
        "last - first; unknown when blank.",
        attribute="odometer_m",
        example=12345.6,
    ),
    Column(
        "segment",
        (),
        "label",
        "",
        "Label of a known piece of the trace (a GPX trkseg ...): the matcher breaks where "
        "it changes between consecutive points (after sorting). A number in every row.",
        nullable=False,
        attribute="segment_starts",
        example=0,
    ),
)
"""Every point column, in the order of ``Trace`` keywords and ``Trace.to_dataframe``."""

_BY_NAME: Final[Mapping[str, Column]] = {name: c for c in COLUMNS for name in c.names}

FIELD_ALIASES: Final[Mapping[str, tuple[str, ...]]] = {c.name: c.names for c in COLUMNS}
"""Canonical field -> accepted column names (matched case-insensitively)."""


def input_columns(*, required_only: bool = False) -> tuple[Column, ...]:
    """
    The point columns with their metadata, in declaration order.

    Parameters
    ----------
    required_only
        Only the columns every trace must have (``lat``, ``lon``).

    Examples
    --------
    >>> [(c.name, c.unit) for c in input_columns()][:4]
    [('time', 's'), ('lat', 'deg'), ('lon', 'deg'), ('heading', 'deg')]
    """
    return tuple(c for c in COLUMNS if c.required or not required_only)


def canonical(name: object) -> str | None:
    """The canonical column a name (any case, outer spaces ignored) stands for, else None."""
    found = _BY_NAME.get(str(name).strip().lower())
    return None if found is None else found.name


def column(name: str) -> Column:
    """
    The column a name or alias (any case) stands for.

    Raises
    ------
    KeyError
        For a name that is no column's (the message lists the canonical names).
    """
    found = _BY_NAME.get(name.strip().lower())
    if found is None:
        known = ", ".join(c.name for c in COLUMNS)
        msg = f"{name!r} is no trace column; the columns are {known}"
        raise KeyError(msg)
    return found


@dataclass(frozen=True, slots=True)
class IdColumn:
    """
    A column naming the trace a table row belongs to.

    Attributes
    ----------
    name
        Canonical name (one of :data:`ID_COLUMNS`).
    aliases
        Other accepted names, compared like ``name`` by :func:`normal_id_name`.
    description
        What the id names.
    """

    name: str
    aliases: tuple[str, ...]
    description: str

    @property
    def names(self) -> tuple[str, ...]:
        """Every accepted name, the canonical one first."""
        return (self.name, *self.aliases)


TRACE_ID_COLUMNS: Final[tuple[IdColumn, ...]] = (
    IdColumn("trace_id", (), "The trace itself."),
    IdColumn("trip_id", (), "One trip (of a vehicle: trip numbers may restart per vehicle)."),
    IdColumn("track_id", (), "One recorded track."),
    IdColumn("vehicle_id", ("vehicle",), "The vehicle."),
    IdColumn("device_id", ("device", "imei"), "The logging device."),
    IdColumn(
        "id",
        (),
        "A plain id; used only without any other id column, and not when it holds a "
        "different value in every row (then it numbers rows).",
    ),
)
"""The id columns a table is grouped by, from the most to the least specific."""

ID_COLUMNS: Final = tuple(c.name for c in TRACE_ID_COLUMNS)
"""Names of the id columns a table is grouped by, from the most to the least specific."""

_SEPARATORS = re.compile(r"[\s_\-.]+")


def normal_id_name(name: object) -> str:
    """
    A column name for comparing with id names: lower case, without ``_``, ``-``, spaces, dots.

    Examples
    --------
    >>> normal_id_name(" Vehicle-ID "), normal_id_name("trip.id")
    ('vehicleid', 'tripid')
    """
    return _SEPARATORS.sub("", str(name).strip().lower())


_ID_BY_NORMAL: Final[Mapping[str, str]] = {
    normal_id_name(n): c.name for c in TRACE_ID_COLUMNS for n in c.names
}


def id_kind(name: object) -> str | None:
    """
    The id column (one of :data:`ID_COLUMNS`) a column name stands for, else None.

    Examples
    --------
    >>> id_kind("VehicleID"), id_kind("IMEI"), id_kind("lat")
    ('vehicle_id', 'device_id', None)
    """
    return _ID_BY_NORMAL.get(normal_id_name(name))
