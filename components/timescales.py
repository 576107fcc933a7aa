"""UTC instants as two-part Julian dates, and elapsed SI seconds across leap seconds.

Zenorbit's clock counts integer nanoseconds of elapsed SI time since ``run.epoch`` (UTC).
Adding elapsed seconds to a UTC date must go through TAI, or a leap second inside the run
shifts everything after it by 1 s: :func:`utc_to_tai`, add the seconds, :func:`tai_to_utc`
(ERFA's leap-second table), as ``orbit.sgp4`` does.

A date is a pair ``(jd1, jd2)`` of floats whose sum is the Julian date (ERFA's convention;
``jd1`` holds the large part so ``jd2`` keeps sub-microsecond resolution).
No function here reads the wall clock.
"""

from __future__ import annotations

import datetime as _dt
import re
import warnings

import erfa
import numpy as np

SECONDS_PER_DAY = 86400.0
TT_MINUS_TAI = 32.184  # s, by definition


_ISO = re.compile(
    r"^\s*(\d{4})-(\d{2})-(\d{2})"  # date
    r"(?:[T ](\d{2}):(\d{2})(?::(\d{2}(?:\.\d*)?))?)?"  # time, seconds optional
    r"\s*(Z|[+-]00:?00|UTC)?\s*$",
    re.IGNORECASE,
)


def parse_utc(value) -> tuple[float, float]:
    """A UTC instant -> two-part Julian date (UTC), days.

    Accepts an ISO-8601 string such as ``"2022-09-18T12:00:00Z"`` (``Z``, ``+00:00``, ``UTC``
    or no zone; ``T`` or a space; fractional seconds; ``23:59:60`` on a leap-second day) or a
    :class:`datetime.datetime` (naive = UTC; aware ones are converted to UTC), as YAML gives.
    Raises ValueError naming the expected form next to what was given.
    """
    if isinstance(value, _dt.datetime):
        if value.tzinfo is not None:
            value = value.astimezone(_dt.UTC).replace(tzinfo=None)
        parts = (value.year, value.month, value.day, value.hour, value.minute, value.second + value.microsecond * 1e-6)
    elif isinstance(value, _dt.date):
        parts = (value.year, value.month, value.day, 0, 0, 0.0)
    elif isinstance(value, str):
        m = _ISO.match(value)
        if not m:
            raise ValueError(f"expected a UTC time like '2022-09-18T12:00:00Z', got {value!r}")
        y, mo, d, hh, mm, ss = m.group(1, 2, 3, 4, 5, 6)
        parts = (int(y), int(mo), int(d), int(hh or 0), int(mm or 0), float(ss or 0.0))
    else:
        raise ValueError(f"expected a UTC time like '2022-09-18T12:00:00Z', got {value!r}")
    try:
        with warnings.catch_warnings(record=True) as caught, np.errstate(all="ignore"):
            warnings.simplefilter("always", erfa.ErfaWarning)
            jd1, jd2 = erfa.dtf2d("UTC", *parts)
    except (erfa.ErfaError, ValueError) as e:
        raise ValueError(f"expected a valid UTC time like '2022-09-18T12:00:00Z', got {value!r} ({e})") from None
    for w in caught:  # "time is after end of day": second 60 on a day without a leap second
        if "dubious year" not in str(w.message):
            raise ValueError(f"expected a valid UTC time like '2022-09-18T12:00:00Z', got {value!r} ({w.message})")
    return float(jd1), float(jd2)


def utc_to_tai(utc: tuple[float, float]) -> tuple[float, float]:
    """UTC two-part Julian date -> TAI two-part Julian date (days).

    Past the end of ERFA's leap-second table the last TAI-UTC is kept (the best guess for a
    future date; ERFA's "dubious year" status is not an error here).
    """
    a, b, status = erfa.ufunc.utctai(*utc)
    if status < 0:
        raise ValueError(f"expected a valid UTC Julian date, got {utc!r}")
    return float(a), float(b)


def tai_to_utc(tai: tuple[float, float]) -> tuple[float, float]:
    """TAI two-part Julian date -> UTC two-part Julian date (days)."""
    a, b, status = erfa.ufunc.taiutc(*tai)
    if status < 0:
        raise ValueError(f"expected a valid TAI Julian date, got {tai!r}")
    return float(a), float(b)


def tai_to_tt(tai: tuple[float, float]) -> tuple[float, float]:
    """TAI -> TT = TAI + 32.184 s, two-part Julian dates (days)."""
    return tai[0], tai[1] + TT_MINUS_TAI / SECONDS_PER_DAY


def seconds_between(utc_from: tuple[float, float], utc_to: tuple[float, float]) -> float:
    """Elapsed SI seconds from ``utc_from`` to ``utc_to`` (negative if earlier)."""
    a1, b1 = utc_to_tai(utc_from)
    a2, b2 = utc_to_tai(utc_to)
    return ((a2 - a1) + (b2 - b1)) * SECONDS_PER_DAY


def utc_to_tt(utc: tuple[float, float]) -> tuple[float, float]:
    """UTC -> TT (= TAI + 32.184 s), two-part Julian dates (days)."""
    return tai_to_tt(utc_to_tai(utc))
