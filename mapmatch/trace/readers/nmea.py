"""
NMEA 0183 logs: RMC and GGA sentences, checksums checked, one trace per file.

Any talker (``$GPRMC`` / ``$GPGGA``, ``GN``, ``GL``, ``GA``, ``BD``). Every sentence's
checksum is checked; a sentence with a wrong checksum, without a position, or reporting no
fix (RMC status ``V``, GGA quality 0) is dropped and counted. RMC and GGA sentences of one
epoch (same time of day, one after the other) make one fix: RMC gives the date, speed
(knots, converted to m/s) and course; GGA the HDOP. GGA sentences take their date from the
nearest RMC (rolling over at midnight); a log without any RMC has no date, and its times
are seconds of day from 1970-01-01 (with a note).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Final

import numpy as np
import pandas as pd

from mapmatch.trace.readers.raw import SHOW, Context, RawTrace, with_notes

__all__ = ["read_nmea"]

_KNOT_MPS: Final = 1852.0 / 3600.0


_NMEA_TIME = re.compile(r"^(\d{2})(\d{2})(\d{2}(?:\.\d+)?)$")


_DAY_S: Final = 86400.0


@dataclass(slots=True)
class _Fix:
    line: int
    tod: str  # time of day as written (hhmmss.ss): sentences of one epoch share it
    tod_s: float
    date_s: float | None  # epoch seconds of the date's midnight (RMC only)
    lat: float
    lon: float
    speed: float = math.nan
    course: float = math.nan
    hdop: float = math.nan


def _nmea_checksum(body: str) -> int:
    """
    XOR of the characters between ``$`` and ``*``.

    Examples
    --------
    >>> f"{_nmea_checksum('GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,'):02X}"
    '47'
    """
    value = 0
    for ch in body.encode("ascii", errors="replace"):
        value ^= ch
    return value


def _nmea_degrees(value: str, hemi: str, width: int) -> float:
    """``ddmm.mmmm`` (``dddmm.mmmm`` for longitude) and N/S/E/W to signed degrees (NaN if bad)."""
    value, hemi = value.strip(), hemi.strip().upper()
    if len(value) < width + 2 or hemi not in ("N", "S", "E", "W"):
        return math.nan
    try:
        deg = int(value[:width]) + float(value[width:]) / 60.0
    except ValueError:
        return math.nan
    return -deg if hemi in ("S", "W") else deg


def _nmea_float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return math.nan


def _nmea_tod(text: str) -> float | None:
    m = _NMEA_TIME.match(text.strip())
    if m is None:
        return None
    h, mi, s = int(m.group(1)), int(m.group(2)), float(m.group(3))
    if h > 23 or mi > 59 or s >= 61:
        return None
    return h * 3600.0 + mi * 60.0 + s


def _nmea_date_s(text: str) -> float | None:
    text = text.strip()
    if len(text) != 6 or not text.isdigit():
        return None
    day, month, yy = int(text[:2]), int(text[2:4]), int(text[4:])
    year = 2000 + yy if yy < 80 else 1900 + yy
    try:
        stamp = np.datetime64(f"{year:04d}-{month:02d}-{day:02d}", "D")
    except ValueError:
        return None
    return float(stamp.astype("datetime64[s]").astype(np.int64))


class _NmeaTally:
    """Lines of an NMEA log that did not become fixes, by reason."""

    def __init__(self) -> None:
        self.reasons: dict[str, list[int]] = {}
        self.unchecked = 0

    def drop(self, reason: str, line: int) -> None:
        self.reasons.setdefault(reason, []).append(line)

    @property
    def dropped(self) -> int:
        return sum(len(v) for v in self.reasons.values())

    def notes(self) -> tuple[str, ...]:
        out = []
        for reason, lines in self.reasons.items():
            shown = ", ".join(str(n) for n in lines[:SHOW])
            more = f" and {len(lines) - SHOW} more" if len(lines) > SHOW else ""
            many = len(lines) != 1
            out.append(
                f"{len(lines)} NMEA sentence{'s' if many else ''} {reason} "
                f"{'were' if many else 'was'} dropped (line{'s' if many else ''} {shown}{more})"
            )
        if self.unchecked:
            out.append(
                f"{self.unchecked} NMEA sentence(s) carry no checksum (*hh) and were used unchecked"
            )
        return tuple(out)


def _nmea_sentence(line: str, number: int, tally: _NmeaTally) -> list[str] | None:
    """The fields of one RMC or GGA sentence with a valid checksum, else ``None``."""
    start = line.find("$")
    if start < 0:
        return None
    text = line[start + 1 :].strip()
    body, star, check = text.partition("*")
    kind = body.split(",", 1)[0]
    if len(kind) != 5 or kind[2:] not in ("RMC", "GGA"):
        return None  # other sentences (GSV, GSA, VTG, proprietary) carry no fix
    if star:
        given = check[:2]
        try:
            ok = int(given, 16) == _nmea_checksum(body)
        except ValueError:
            ok = False
        if not ok:
            tally.drop("with a wrong checksum", number)
            return None
    else:
        tally.unchecked += 1
    return body.split(",")


def _nmea_fix(fields: list[str], number: int, tally: _NmeaTally) -> _Fix | None:
    kind = fields[0][2:]
    need = 10 if kind == "RMC" else 9
    if len(fields) < need:
        tally.drop(f"({kind}) with too few fields", number)
        return None
    tod_s = _nmea_tod(fields[1])
    if kind == "RMC":
        valid = fields[2].strip().upper() == "A"
        lat = _nmea_degrees(fields[3], fields[4], 2)
        lon = _nmea_degrees(fields[5], fields[6], 3)
    else:
        valid = fields[6].strip() not in ("", "0")
        lat = _nmea_degrees(fields[2], fields[3], 2)
        lon = _nmea_degrees(fields[4], fields[5], 3)
    if not valid:
        status = "status V" if kind == "RMC" else "fix quality 0"
        tally.drop(f"({kind}) reporting no fix ({status})", number)
        return None
    if tod_s is None or math.isnan(lat) or math.isnan(lon):
        tally.drop(f"({kind}) without a readable time or position", number)
        return None
    fix = _Fix(number, fields[1].strip(), tod_s, None, lat, lon)
    if kind == "RMC":
        fix.date_s = _nmea_date_s(fields[9])
        fix.speed = _nmea_float(fields[7]) * _KNOT_MPS
        fix.course = _nmea_float(fields[8])
    else:
        fix.hdop = _nmea_float(fields[8])
    return fix


def read_nmea(data: bytes, ctx: Context) -> list[RawTrace]:
    """The one trace of an NMEA log; unusable sentences dropped and counted."""
    text = data.decode("ascii", errors="replace")
    tally = _NmeaTally()
    fixes: list[_Fix] = []
    sentences = 0
    for number, line in enumerate(text.splitlines(), start=1):
        fields = _nmea_sentence(line, number, tally)
        if fields is None:
            continue
        sentences += 1
        fix = _nmea_fix(fields, number, tally)
        if fix is None:
            continue
        last = fixes[-1] if fixes else None
        if last is not None and last.tod == fix.tod:  # RMC + GGA of one epoch
            last.date_s = last.date_s if last.date_s is not None else fix.date_s
            for name in ("speed", "course", "hdop"):
                if math.isnan(getattr(last, name)):
                    setattr(last, name, getattr(fix, name))
            continue
        fixes.append(fix)
    if not fixes:
        what = "no $..RMC or $..GGA sentence" if sentences == 0 and not tally.dropped else "no fix"
        dropped = f"; {'; '.join(tally.notes())}" if tally.notes() else ""
        msg = f"holds {what} with a position{dropped}"
        raise ctx.error(msg)
    notes = list(tally.notes())
    time_s = _nmea_times(fixes, notes)
    frame = pd.DataFrame(
        {
            "time": time_s,
            "lat": [f.lat for f in fixes],
            "lon": [f.lon for f in fixes],
            "speed": [f.speed for f in fixes],
            "course": [f.course for f in fixes],
            "hdop": [f.hdop for f in fixes],
        }
    )
    for name in ("speed", "course", "hdop"):
        if frame[name].isna().all():
            frame = frame.drop(columns=name)
    numbers = np.array([f.line for f in fixes], dtype=np.int64)
    raw = RawTrace(ctx.default_id, frame, numbers, "line", ctx.name)
    return [with_notes(raw, tuple(notes), tally.dropped)]


def _nmea_times(fixes: list[_Fix], notes: list[str]) -> list[float]:
    """Epoch seconds of every fix: its RMC date, else the nearest RMC's, rolling at midnight."""
    dated = [i for i, f in enumerate(fixes) if f.date_s is not None]
    if not dated:
        notes.append(
            "no RMC sentence gives a date: times are seconds of day counted from 1970-01-01 "
            "(the order and the intervals are right, the date is not)"
        )
    first_date = fixes[dated[0]].date_s if dated else None
    day = 0.0 if first_date is None else first_date
    # Walk back from the first dated fix so that leading GGA fixes get its date (or the day
    # before when they are before midnight), then forward.
    out = [math.nan] * len(fixes)
    first = dated[0] if dated else 0
    current, prev_tod = day, fixes[first].tod_s
    for i in range(first, -1, -1):
        tod = fixes[i].tod_s
        if tod > prev_tod + _DAY_S / 2:
            current -= _DAY_S
        prev_tod = tod
        out[i] = current + tod
    current, prev_tod = day, fixes[first].tod_s
    for i in range(first + 1, len(fixes)):
        fix = fixes[i]
        if fix.date_s is not None:
            current = fix.date_s
        elif fix.tod_s < prev_tod - _DAY_S / 2:
            current += _DAY_S
        prev_tod = fix.tod_s
        out[i] = current + fix.tod_s
    return out
