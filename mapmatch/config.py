"""
Every matching parameter in one validated object, each declared once with its metadata.

(Over 400 lines on purpose: each parameter's declaration is the documentation of its default.)

A field of :class:`MatchConfig` carries, in :class:`Param` metadata, its description (what it
does and where its default comes from), its unit, its bounds and whether one request may
override it. Everything else is generated from that one declaration: validation
(:meth:`MatchConfig.__post_init__`), :data:`OVERRIDABLE`, the ``mapmatch match`` flags
(``--sigma-m``; :func:`add_config_flags`) and the HTTP ``options`` model (``api.schemas``). The
defaults were chosen by measuring on the accuracy matrix (``benchmarks/bench_accuracy.py``:
every shared extract x input class x sampling condition), not on one extract; docs/DESIGN.md
holds the model they belong to.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

from mapmatch.errors import ConfigError

if TYPE_CHECKING:
    import argparse
    from collections.abc import Iterator, Mapping

__all__ = [
    "OVERRIDABLE",
    "MatchConfig",
    "Param",
    "add_config_flags",
    "config_from_flags",
    "parameters",
]

Kind = Literal["float", "int", "bool", "band"]


@dataclass(frozen=True, slots=True)
class Param:
    """
    What one :class:`MatchConfig` field means and which values it takes.

    Attributes
    ----------
    doc
        What the parameter does, and the reason for its default.
    unit
        Unit of the value (``"m"``, ``"s"``, ``"nats"``, ...); empty for a pure number.
    kind
        ``float``, ``int``, ``bool`` or ``band`` (a ``(low, high)`` pair of fractions).
    gt, ge, le
        Bounds: greater than, at least, at most (``None``: none that side).
    overridable
        Whether one request (HTTP ``options``, CLI flags) may set it.
    """

    doc: str
    unit: str = ""
    kind: Kind = "float"
    gt: float | None = None
    ge: float | None = None
    le: float | None = None
    overridable: bool = False

    def describe(self, default: object) -> str:
        """One sentence for help texts: the doc, the unit and the default."""
        unit = f" ({self.unit})" if self.unit else ""
        return f"{self.doc}{unit}; default {_show(default)}."

    def rule(self) -> str:
        """The bounds as words, e.g. ``> 0 and <= 200``."""
        parts = []
        if self.gt is not None:
            parts.append(f"> {_show(self.gt)}")
        if self.ge is not None:
            parts.append(f">= {_show(self.ge)}")
        if self.le is not None:
            parts.append(f"<= {_show(self.le)}")
        return " and ".join(parts)


def _show(value: object) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, tuple):
        return ", ".join(_show(v) for v in value)
    return str(value)


def _param(default: Any, **meta: Any) -> Any:
    return field(default=default, metadata={"param": Param(**meta)})


@dataclass(frozen=True, slots=True, kw_only=True)
class MatchConfig:
    """
    Matcher parameters; defaults suit fused car traces at 1-30 s sampling.

    Each field documents itself (``parameters()`` lists them with their :class:`Param`);
    the groups are candidates, emission, transition, observations and outliers, loops, and
    the distance check. Invalid values raise :class:`~mapmatch.errors.ConfigError` naming the
    field (``error.field``), the rule and the value.

    Examples
    --------
    >>> MatchConfig(sigma_m=8.0).sigma_m
    8.0
    >>> MatchConfig(sigma_m=-1.0)
    Traceback (most recent call last):
    ...
    mapmatch.errors.ConfigError: sigma_m must be > 0 (got -1)
    """

    # --- candidates
    search_radius_m: float = _param(
        50.0,
        doc="roads farther from a fix are not considered; a fix whose position sigma (its "
        "accuracy, else sigma_m) asks for more widens its own radius to radius_accuracy_factor "
        "x sigma",
        unit="m",
        gt=0,
        le=200,
        overridable=True,
    )
    max_search_radius_m: float = _param(
        200.0, doc="widest radius a poor accuracy may ask for", unit="m", gt=0, le=5000
    )
    radius_accuracy_factor: float = _param(
        4.0,
        doc="a fix's search radius in its position sigmas, where wider than search_radius_m: "
        "a sigma_m of 20 m searches 80 m (50 m, 2.5 sigmas, left 1 % of such fixes and many "
        "of the outliers without their road)",
        gt=0,
        le=100,
    )
    core_radius_sigmas: float = _param(
        2.5,
        doc="a fix's core radius in its position sigmas, at least search_radius_m: every "
        "candidate within it enters the model, and of those beyond it (where the search "
        "radius reaches farther) only the far_candidates nearest (radius_accuracy_factor or "
        "more: every candidate searched)",
        gt=0,
        le=100,
    )
    far_candidates: int = _param(
        8,
        doc="directed edges beyond a fix's core radius that enter the model, the nearest (all "
        "of them where none is within the core): the wider search is for a fix whose road "
        "lies past the core, and the routes of every road out there cost more than they "
        "tell. On the 30 s / 20 m peer sets of the eleven extracts (40 trips each) 8 leaves "
        "every route mismatch as it was or lower (positions only 7.71 -> 7.68 %, full input "
        "3.85 -> 3.80 %) and takes 4 % off a Krems trace's matching; 4 takes 12 % (mismatch "
        "7.64 / 3.62 %) but lost the true road of a Krems trip's last fix, 63 m off behind "
        "six nearer edges (+4.6 % of its length); none (the core alone): 8.32 / 4.52 %",
        kind="int",
        ge=0,
        le=64,
    )
    max_candidates: int = _param(
        12,
        doc="road places kept per fix: those with the best emission among the twice as many "
        "nearest directed edges; a place is a point on the roads, so both directions of a "
        "two-way road, or the edges of the junction a fix is nearest to, are one. 16 directed "
        "edges by distance let a junction's edges crowd out the road the heading agreed with "
        "(+2 % on realistic-1s Melbourne with the odometer); with 12 places 88 of the "
        "accuracy matrix's 176 extract cells are within 1 % on 95 % of trips, against 84 "
        "(16 places: 89, and 8 % slower)",
        kind="int",
        ge=1,
        le=64,
        overridable=True,
    )
    candidate_margin: float = _param(
        10.0,
        doc="candidates whose emission is this much worse than the fix's best are dropped",
        unit="nats",
        ge=0,
        le=1000,
    )
    course_prune_deg: float = _param(
        90.0,
        doc="without a reported heading, a candidate whose road runs more than this far from "
        "the course between its observation's neighbours (at most 10 s and at least 10 m and "
        "4 sigma apart: the chord's direction is off by less than 45 degrees at 3 sigma, and a "
        "car turning at the observation drives within 90 degrees of it) is dropped (0: "
        "never): the wrong way of a road the car is clearly driving along, which only a "
        "U-turn could reach and the transitions rule out anyway, after routing it. "
        "Positions-only matching at 1 s 1.28-1.48x faster than without (Krems, Andorra, "
        "Monaco; 135 degrees: 1.19-1.21x); on the accuracy matrix 9 trips better (135: 3), "
        "none worse, the noise-free truth identical",
        unit="deg",
        ge=0,
        le=180,
        overridable=True,
    )
    # --- emission
    sigma_m: float = _param(
        5.0,
        doc="1-sigma position error of a fix (fused GNSS/INS reaches 3-4 m at 1 Hz; Newson & "
        "Krumm found 4.07 m for raw GNSS); a fix's own accuracy replaces it when larger",
        unit="m",
        gt=0,
        le=500,
        overridable=True,
    )
    estimate_sigma: bool = _param(
        True,
        doc="without an accuracy column, estimate the trace's own position error (1.4826 x "
        "the median distance to the nearest road, Newson & Krumm) when its fixes are "
        "sparse, and use it when it is larger than sigma_m",
        kind="bool",
        overridable=True,
    )
    max_emission_penalty: float = _param(
        8.0,
        doc="floor of the emission (at 4 sigma): an outlier cannot veto the true road",
        unit="nats",
        ge=0,
        le=1000,
    )
    heading_sigma_deg: float = _param(
        25.0,
        doc="spread of the heading around the road direction (three times the 8 deg of a "
        "phone GNSS/INS filter, room for lane changes and curves)",
        unit="deg",
        gt=0,
        le=180,
        overridable=True,
    )
    heading_min_speed_mps: float = _param(
        1.0, doc="speed below which the heading counts for nothing", unit="m/s", ge=0, le=100
    )
    heading_full_speed_mps: float = _param(
        10.0, doc="speed from which the heading counts fully", unit="m/s", gt=0, le=100
    )
    heading_max_penalty: float = _param(
        12.0,
        doc="most a wrong heading costs, so one bad sample cannot veto the true road",
        unit="nats",
        ge=0,
        le=1000,
    )
    service_penalty: float = _param(
        2.0,
        doc="what a candidate on a service road (parking aisle, driveway, access road) costs "
        "when the car is faster than service_speed_mps: such roads often run within the "
        "position noise of the road beside them (measured on the matrix: 30 trips changed, "
        "6 into 1 %, 1 out with a lower route mismatch, 30 with a lower mismatch, none "
        "higher; 3 nats put 4 out)",
        unit="nats",
        ge=0,
        le=100,
    )
    service_speed_mps: float = _param(
        8.0,
        doc="a car faster than this (29 km/h) by its speed and by its pace over 4 s is not on "
        "a service road (the speed from 1 s steps alone reads a car park's standing car as "
        "fast: 2 traces of the peers' clean sets got worse with it)",
        unit="m/s",
        ge=0,
        le=100,
    )
    # --- transition
    beta_m: float = _param(
        3.0,
        doc="scale of |great-circle - route distance| (Newson & Krumm's exponential)",
        unit="m",
        gt=0,
        le=1000,
        overridable=True,
    )
    beta_per_s: float = _param(
        0.3,
        doc="growth of that scale per second between fixes: chords cut curves more the longer "
        "the interval",
        unit="m/s",
        ge=0,
        le=100,
        overridable=True,
    )
    beta_per_sigma: float = _param(
        0.3,
        doc="growth of that scale per metre of position sigma: two noisy fixes are farther "
        "apart than the road between them (0.3 cut spurious U-turns at 1 s on the matrix)",
        ge=0,
        le=100,
    )
    route_factor: float = _param(
        2.0, doc="routes are searched up to this many times the great-circle", gt=0, le=100
    )
    route_slack_m: float = _param(300.0, doc="plus this much", unit="m", ge=0, le=100_000)
    route_reach_mps: float = _param(
        15.0,
        doc="or, when more, this speed times the interval: a detour round a banned turn "
        "between sparse fixes is far longer than their distance",
        unit="m/s",
        ge=0,
        le=100,
    )

    speed_factor: float = _param(
        1.5,
        doc="a route needing more than this many times its speed limit (plus speed_margin_mps) "
        "costs a Gaussian penalty",
        gt=0,
        le=100,
    )
    speed_margin_mps: float = _param(5.0, doc="see speed_factor", unit="m/s", ge=0, le=1000)
    speed_sigma_mps: float = _param(5.0, doc="spread of that penalty", unit="m/s", gt=0, le=1000)
    nominal_speed_mps: float = _param(
        10.0,
        doc="speed assumed for a step without a usable time (none given, or a repeated one): "
        "the interval that widens beta is the step over this speed",
        unit="m/s",
        gt=0,
        le=100,
    )
    max_speed_mps: float = _param(50.0, doc="faster than any car drives", unit="m/s", gt=0, le=1000)
    standstill_m: float = _param(
        10.0,
        doc="a fix this far behind the previous one (or standstill_sigmas x sigma, if more), on "
        "its edge or across edges, may be a held car's scatter instead of a U-turn or a loop",
        unit="m",
        ge=0,
        le=1000,
        overridable=True,
    )
    standstill_sigmas: float = _param(4.0, doc="see standstill_m", unit="sigmas", ge=0, le=100)
    uturn_penalty: float = _param(
        14.0,
        doc="cost of a U-turn without evidence (headings apart at speed, a dead end's end, "
        "or a trusted travel the turn explains): one must not explain a small backward move "
        "(6 let noise make 4 % of plain-GPS trips turn; 14 against 10 on the accuracy "
        "matrix: 96 against 94 cells within 1 %, 28 trips better, 3 worse, once travel "
        "counted as evidence: without that, 14 lost true U-turns of noise-free odometer trips)",
        unit="nats",
        ge=0,
        le=1000,
        overridable=True,
    )
    uturn_speed_mps: float = _param(
        5.0,
        doc="fastest a car turns round: a loop after Viterbi that turns round and could not "
        "be driven in the time its fixes give it, at travel_accel_mps2 down to and up from "
        "this speed, is taken out (a 14 m spur out and back between two fixes 1 s apart at "
        "8 m/s); generous on purpose, a turning circle at a dead end's end included: on the "
        "accuracy matrix it takes out two spurious U-turns (1 s, positions only) and changes "
        "nothing else, the noise-free truth included; 3 takes out nothing more",
        unit="m/s",
        gt=0,
        le=100,
    )
    uturn_evidence_penalty: float = _param(
        3.0,
        doc="cost of a U-turn whose fixes' headings point apart at speed",
        unit="nats",
        ge=0,
        le=1000,
    )
    loop_penalty: float = _param(
        6.0,
        doc="a loop or a drive back after a U-turn must explain its fixes this much better "
        "than holding where it began (priced after Viterbi; see mapmatch.hmm.loops)",
        unit="nats",
        ge=0,
        le=1000,
        overridable=True,
    )
    use_travel: bool = _param(
        True,
        doc="hold routes against the distance the trace says it travelled (odometer, else the "
        "reported speed integrated over every fix)",
        kind="bool",
        overridable=True,
    )
    travel_tolerance_m: float = _param(
        5.0,
        doc="a route within this much (plus travel_tolerance_frac of the travel) of the travel "
        "costs nothing: wide on purpose, so the fused distance never pulls the matched length, "
        "which the distance check judges independently",
        unit="m",
        ge=0,
        le=10_000,
    )
    travel_tolerance_frac: float = _param(0.15, doc="see travel_tolerance_m", ge=0, le=10)
    travel_tolerance_mps: float = _param(
        0.5, doc="error of a reported speed: adds this x dt of slack", unit="m/s", ge=0, le=100
    )
    travel_accel_mps2: float = _param(
        3.0,
        doc="a speed-integrated travel's slack per step is what the speed may change by "
        "between two samples at this acceleration (a x dt^2 / 4): about 1 m at 1 s, useless "
        "at 15 s",
        unit="m/s2",
        ge=0,
        le=100,
    )
    travel_beta_m: float = _param(
        2.0, doc="scale of the cost beyond the tolerance", unit="m", gt=0, le=10_000
    )
    min_log_transition: float = _param(
        -50.0,
        doc="a transition less likely than this (a loop round a block to go 30 m back) is "
        "taken as impossible: it comes from a displaced fix, not from driving",
        unit="nats",
        ge=-1e6,
        le=-1e-9,
    )
    max_break_repairs: int = _param(
        8,
        doc="where the trace breaks, this many times the fix at the break is left out if that "
        "joins the pieces",
        kind="int",
        ge=0,
        le=1000,
    )
    detour_outlier_nats: float = _param(
        20.0,
        doc="where the path holds a transition below minus this, the fixes near it are tried "
        "for a fix thrown onto another road (at sparse sampling the outlier tests do not "
        "judge it, and the path went round the block for it: Helsinki 15 s trip 14 +49 %), "
        "and one is left out when that scores the path this much better; more than a "
        "U-turn without evidence costs, so a drive to a dead end's end keeps its fix",
        unit="nats",
        gt=0,
        le=1e6,
    )
    detour_max_emission_loss: float = _param(
        5.0,
        doc="a fix is not left out for detour_outlier_nats when the other fixes' emissions "
        "then lose more than this: the gain came from moving them onto a wrong road (the "
        "emission floor makes that cheap), not from a detour gone (Monaco 30 s peer trip 11, "
        "odometer: 10 nats lost and 45 % mismatch; the accuracy matrix's drops change them "
        "by -4.4 .. +53)",
        unit="nats",
        ge=0,
        le=1e6,
    )
    max_detour_tries: int = _param(
        8,
        doc="fixes tried at most per match for detour_outlier_nats, each bridged by a "
        "two-fix trellis (0: never); on the accuracy matrix 4 tries find 7 of the 10 trips "
        "8 find, 16 no more",
        kind="int",
        ge=0,
        le=1000,
    )
    # --- observations and outliers
    thinning_sigmas: float = _param(
        2.0,
        doc="consecutive fixes within this many sigmas of their running centroid are one "
        "observation: a stopped or crawling car is one state (Newson & Krumm thin at 2 sigma)",
        unit="sigmas",
        ge=0,
        le=100,
        overridable=True,
    )
    odometer_end_sigmas: float = _param(
        2.0,
        doc="the path's first and last point move along their roads, by at most this many "
        "sigmas, to where the odometer readings of all the piece's fixes put them (a line "
        "through their places along the path against the readings, scale free): at 15 s "
        "one noisy end fix no longer sets the matched length alone (1 lost 0.7 points within "
        "1 % at 15 s on the accuracy matrix, 3 and 4 moved 26 of 330 trips by a hair); 0 keeps "
        "the ends at the end fixes' projections",
        unit="sigmas",
        ge=0,
        le=100,
        overridable=True,
    )
    outlier_sigmas: float = _param(
        5.0,
        doc="a fix this many sigmas from its neighbours that sticks out from them is an outlier",
        unit="sigmas",
        ge=0,
        le=100,
        overridable=True,
    )
    end_outlier_sigmas: float = _param(
        4.0,
        doc="with positions only, a first or last fix this many sigmas beyond where the next "
        "fixes' pace and direction put it is an outlier (a fix 40 m off at 1 s on a road that "
        "passes there starts the path 40 m early), judged only where the car can have come "
        "less far than that since, so a turn cannot explain it; positions-only trips within "
        "1 % on the accuracy matrix, 1s-5m / realistic-1s: none 96.4 / 90.9 %, 3 96.4 / "
        "91.0 % (it judges hardly any end), 4 97.6 / 92.7 %, 5 97.3 / 92.1 %; 0 turns it off",
        unit="sigmas",
        ge=0,
        le=100,
    )
    outlier_max_gap_s: float = _param(
        5.0,
        doc="outliers and strays are judged only between fixes this close in time: at sparse "
        "sampling a fix that sticks out is a car that went somewhere",
        unit="s",
        ge=0,
        le=100_000,
    )
    outlier_detour_ratio: float = _param(
        2.0,
        doc="an outlier sticks out farther than its neighbours are apart (the way through it "
        "this many times their distance); a right-angle corner is 1.41",
        gt=1,
        le=100,
    )
    outlier_max_run: int = _param(
        3,
        doc="longest run of fixes far from every road between on-road fixes taken as displaced",
        kind="int",
        ge=0,
        le=1000,
    )
    # --- distance check
    distance_band: tuple[float, float] = _param(
        (-0.04, 0.01),
        doc="relative error (fused - matched) / matched that passes: the metering tolerance "
        "of JJG 517 taximeters",
        kind="band",
        overridable=True,
    )

    def __post_init__(self) -> None:
        for name, meta in _PARAMS.items():
            _check(name, meta, getattr(self, name))
        if self.search_radius_m > self.max_search_radius_m:
            msg = (
                f"search_radius_m must be <= max_search_radius_m "
                f"(got {self.search_radius_m:g} > {self.max_search_radius_m:g})"
            )
            raise ConfigError(msg, field="search_radius_m")
        if self.heading_min_speed_mps >= self.heading_full_speed_mps:
            msg = (
                "heading_min_speed_mps must be below heading_full_speed_mps "
                f"(got {self.heading_min_speed_mps:g} >= {self.heading_full_speed_mps:g})"
            )
            raise ConfigError(msg, field="heading_min_speed_mps")

    def replace(self, overrides: Mapping[str, object]) -> MatchConfig:
        """
        A copy with some fields changed; only names in :data:`OVERRIDABLE` are accepted.

        A ``distance_band`` may be given as a list. Raises
        :class:`~mapmatch.errors.ConfigError` (with ``field`` set) for an unknown or
        non-overridable field, or a value that breaks its rule.
        """
        unknown = sorted(set(overrides) - OVERRIDABLE)
        if unknown:
            msg = f"unknown option(s) {unknown}; allowed: {sorted(OVERRIDABLE)}"
            raise ConfigError(msg, field=unknown[0])
        changes = dict(overrides)
        if "distance_band" in changes:
            band = changes["distance_band"]
            if not isinstance(band, list | tuple) or len(band) != 2:
                msg = f"distance_band must be a pair [low, high] (got {band!r})"
                raise ConfigError(msg, field="distance_band")
            changes["distance_band"] = tuple(band)
        return dataclasses.replace(self, **changes)  # type: ignore[arg-type]


def _check(name: str, meta: Param, value: object) -> None:
    """Raise :class:`ConfigError` unless ``value`` fits ``meta``'s kind and bounds."""
    if meta.kind == "bool":
        if not isinstance(value, bool):
            msg = f"{name} must be true or false (got {value!r})"
            raise ConfigError(msg, field=name)
        return
    if meta.kind == "band":
        pair = value if isinstance(value, tuple) and len(value) == 2 else (math.nan, math.nan)
        numbers = [
            float(v) if isinstance(v, int | float) and not isinstance(v, bool) else math.nan
            for v in pair
        ]
        low, high = numbers
        if not (math.isfinite(low) and math.isfinite(high) and -1 < low <= 0 <= high < 10):
            msg = f"{name} must be (low <= 0, high >= 0) fractions (got {value!r})"
            raise ConfigError(msg, field=name)
        return
    if isinstance(value, bool) or not isinstance(value, int | float):
        msg = f"{name} must be a finite number (got {value!r})"
        raise ConfigError(msg, field=name)
    if not math.isfinite(value):
        msg = f"{name} must be a finite number (got {value!r})"
        raise ConfigError(msg, field=name)
    if meta.kind == "int" and not isinstance(value, int):
        msg = f"{name} must be a whole number (got {value!r})"
        raise ConfigError(msg, field=name)
    v = float(value)
    for bound, ok, word in (
        (meta.gt, meta.gt is None or v > meta.gt, ">"),
        (meta.ge, meta.ge is None or v >= meta.ge, ">="),
        (meta.le, meta.le is None or v <= meta.le, "<="),
    ):
        if not ok:
            msg = f"{name} must be {word} {_show(bound)} (got {v:g})"
            raise ConfigError(msg, field=name)


_PARAMS: dict[str, Param] = {
    f.name: f.metadata["param"] for f in dataclasses.fields(MatchConfig) if "param" in f.metadata
}
_DEFAULTS: dict[str, Any] = {f.name: f.default for f in dataclasses.fields(MatchConfig)}

#: Fields a single request (HTTP ``options``, CLI flags) may override.
OVERRIDABLE = frozenset(name for name, meta in _PARAMS.items() if meta.overridable)


def parameters(*, overridable_only: bool = False) -> Iterator[tuple[str, Param, Any]]:
    """
    Every parameter of :class:`MatchConfig`: ``(name, metadata, default)``, in field order.

    Examples
    --------
    >>> name, meta, default = next(parameters(overridable_only=True))
    >>> name, meta.unit, default
    ('search_radius_m', 'm', 50.0)
    """
    for name, meta in _PARAMS.items():
        if meta.overridable or not overridable_only:
            yield name, meta, _DEFAULTS[name]


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def add_config_flags(parser: argparse.ArgumentParser) -> None:
    """
    Add one flag per overridable parameter (``--sigma-m``), its help generated from the field.

    Values are parsed and checked with :meth:`MatchConfig.replace`
    (:func:`config_from_flags`), so the CLI takes exactly what HTTP ``options`` take.
    """
    group = parser.add_argument_group("matcher options (each a MatchConfig field)")
    for name, meta, default in parameters(overridable_only=True):
        bounds = f" Must be {meta.rule()}." if meta.rule() else ""
        sentence = meta.describe(default)
        text = (sentence[:1].upper() + sentence[1:] + bounds).replace("%", "%%")
        if meta.kind == "bool":
            group.add_argument(
                _flag(name),
                dest=name,
                default=None,
                metavar="true|false",
                help=text,
            )
            continue
        metavar = "LOW,HIGH" if meta.kind == "band" else meta.unit.upper() or "N"
        group.add_argument(
            _flag(name),
            dest=name,
            default=None,
            metavar=metavar.replace("/", "_"),
            help=text,
        )


def config_from_flags(
    values: Mapping[str, str | None], base: MatchConfig | None = None
) -> MatchConfig:
    """
    The configuration the flags of :func:`add_config_flags` ask for.

    Raises
    ------
    ConfigError
        A value that is not of the field's kind or breaks its rule; ``field`` names it.
    """
    overrides: dict[str, object] = {}
    for name, meta, _default in parameters(overridable_only=True):
        text = values.get(name)
        if text is None:
            continue
        overrides[name] = _parse(name, meta, text)
    return (base or MatchConfig()).replace(overrides)


def _parse(name: str, meta: Param, text: str) -> object:
    try:
        if meta.kind == "bool":
            return {"true": True, "false": False}[text.strip().lower()]
        if meta.kind == "band":
            low, high = (float(v) for v in text.split(","))
            return (low, high)
        if meta.kind == "int":
            return int(text)
        return float(text)
    except (KeyError, ValueError):
        shape = {"bool": "true or false", "band": "LOW,HIGH", "int": "a whole number"}
        msg = f"{name} must be {shape.get(meta.kind, 'a number')} (got {text!r})"
        raise ConfigError(msg, field=name) from None
