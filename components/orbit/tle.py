"""Two-line element sets: strict format checks, SGP4 propagation, TEME -> GCRF.

Plain functions and one plain class; no bus. Reading a TLE file is the only I/O
(:func:`read_tle_file`). SI units out: m, m/s; angles rad.

Propagation uses the ``sgp4`` package (Vallado's SGP4/SDP4 with the WGS-72 constants TLEs are
fitted with) at UTC Julian dates. Its output is in TEME (True Equator, Mean Equinox of date).

TEME -> GCRF chain (IAU 2006/2000A through ERFA, equinox based):

    r_TOD  = R3(-(GAST - GMST82)) r_TEME      TEME -> true of date (true equator & equinox)
    r_GCRF = NPB^T r_TOD                      NPB = erfa.pnm06a: bias-precession-nutation

TEME's x axis is the "mean equinox" that SGP4 defines through the IAU-82 GMST
(r_PEF = R3(GMST82) r_TEME), and GAST = erfa.gst06a places the true equinox with respect to
the same Earth-fixed frame (r_PEF = R3(GAST) r_TOD), so the angle between them is
GAST - GMST82 (the equation of the equinoxes plus the tiny GMST82/GMST06 difference).
Time scales: TT from UTC via ERFA's leap-second table; UT1 is taken equal to UTC (no Earth
orientation data). The rotation depends on time only through precession-nutation, so the
|UT1-UTC| < 0.9 s approximation changes it by < 1e-11 rad. The chain ignores the
IAU-76/FK5 nutation corrections (dPsi, dEps) and the ambiguity in TEME's definition, which
are milliarcsecond effects at most: centimetres at LEO (Vallado's Example 3-15, IAU-76/FK5 with
EOP corrections, is reproduced to 4 mm at 8000 km), far below SGP4's own ~1 km error.
Velocity is rotated with the same matrix (the rotation rate of ~1e-11 rad/s is neglected:
< 1e-4 m/s).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import erfa
import numpy as np

LINE_LENGTH = 69


class TLEFormatError(ValueError):
    """A malformed TLE. ``line`` is 1 or 2 (0 for the pair as a whole), ``column`` the 1-based
    first column of the bad field (0 when it does not apply)."""

    def __init__(self, line: int, column: int, message: str, last_column: int | None = None):
        where = f"line {line}" if line else "TLE"
        if column:
            where += (
                f", column {column}"
                if not last_column or last_column == column
                else f", columns {column}-{last_column}"
            )
        super().__init__(f"{where}: {message}")
        self.line, self.column, self.message = line, column, message


# (first column, last column, field name, regex the field must match, its form for messages);
# 1-based inclusive columns, as in the Space-Track/CelesTrak TLE format description
_LINE1 = (
    (1, 1, "line number", r"1", "'1'"),
    (2, 2, "separator", r" ", "a blank"),
    (3, 7, "satellite number", r"[ 0-9]{4}[0-9]|[A-Z][0-9]{4}", "5 digits (or Alpha-5 like 'A1234')"),
    (8, 8, "classification", r"[UCS ]", "U, C or S"),
    (9, 9, "separator", r" ", "a blank"),
    (10, 17, "international designator", r"[ -~]{8}", "8 printable characters"),
    (18, 18, "separator", r" ", "a blank"),
    (19, 20, "epoch year", r"[0-9]{2}", "2 digits (YY)"),
    (21, 32, "epoch day of year", r"[ 0-9]{2}[0-9]\.[0-9]{8}", "DDD.DDDDDDDD"),
    (33, 33, "separator", r" ", "a blank"),
    (
        34,
        43,
        "first derivative of mean motion",
        r"[ +-]\.[0-9]{8}|[ +-][0-9]\.[0-9]{7}",
        "' .NNNNNNNN' or '-.NNNNNNNN'",
    ),
    (44, 44, "separator", r" ", "a blank"),
    (45, 52, "second derivative of mean motion", r"[ +-][ 0-9]{5}[+-][0-9]", "' NNNNN-N' (implied decimal point)"),
    (53, 53, "separator", r" ", "a blank"),
    (54, 61, "BSTAR drag term", r"[ +-][ 0-9]{5}[+-][0-9]", "' NNNNN-N' (implied decimal point)"),
    (62, 62, "separator", r" ", "a blank"),
    (63, 63, "ephemeris type", r"[ 0-9]", "a digit or blank"),
    (64, 64, "separator", r" ", "a blank"),
    (65, 68, "element set number", r"[ 0-9]{3}[0-9]", "up to 4 digits, right-aligned"),
    (69, 69, "checksum", r"[0-9]", "a digit"),
)
_LINE2 = (
    (1, 1, "line number", r"2", "'2'"),
    (2, 2, "separator", r" ", "a blank"),
    (3, 7, "satellite number", r"[ 0-9]{4}[0-9]|[A-Z][0-9]{4}", "5 digits (or Alpha-5 like 'A1234')"),
    (8, 8, "separator", r" ", "a blank"),
    (9, 16, "inclination (deg)", r"[ 0-9]{2}[0-9]\.[0-9]{4}", "DDD.DDDD"),
    (17, 17, "separator", r" ", "a blank"),
    (18, 25, "right ascension of the ascending node (deg)", r"[ 0-9]{2}[0-9]\.[0-9]{4}", "DDD.DDDD"),
    (26, 26, "separator", r" ", "a blank"),
    (27, 33, "eccentricity", r"[0-9]{7}", "7 digits (leading decimal point implied)"),
    (34, 34, "separator", r" ", "a blank"),
    (35, 42, "argument of perigee (deg)", r"[ 0-9]{2}[0-9]\.[0-9]{4}", "DDD.DDDD"),
    (43, 43, "separator", r" ", "a blank"),
    (44, 51, "mean anomaly (deg)", r"[ 0-9]{2}[0-9]\.[0-9]{4}", "DDD.DDDD"),
    (52, 52, "separator", r" ", "a blank"),
    (53, 63, "mean motion (rev/day)", r"[ 0-9][0-9]\.[0-9]{8}", "NN.NNNNNNNN"),
    (64, 68, "revolution number", r"[ 0-9]{4}[0-9]", "up to 5 digits, right-aligned"),
    (69, 69, "checksum", r"[0-9]", "a digit"),
)


def tle_checksum(line: str) -> int:
    """The TLE checksum of a line's first 68 columns: digits summed, each '-' counts 1, modulo 10."""
    return sum(int(c) if c.isdigit() else (1 if c == "-" else 0) for c in line[:68]) % 10


def _check_line(number: int, line: str, layout) -> None:
    if not isinstance(line, str):
        raise TLEFormatError(number, 0, f"expected a string of {LINE_LENGTH} characters, got {line!r}")
    if len(line) != LINE_LENGTH:
        raise TLEFormatError(number, 0, f"expected {LINE_LENGTH} characters, got {len(line)}: {line!r}")
    for first, last, name, pattern, form in layout:
        text = line[first - 1 : last]
        if not re.fullmatch(pattern, text):
            raise TLEFormatError(number, first, f"{name}: expected {form}, got {text!r}", last)
    expected = tle_checksum(line)
    if int(line[68]) != expected:
        raise TLEFormatError(number, 69, f"checksum: expected {expected} (from columns 1-68), got {line[68]}")


def check_tle(line1: str, line2: str) -> tuple[str, str]:
    """Validate a TLE's column layout and checksums; return the two lines without line endings
    or trailing blanks. Raises :class:`TLEFormatError` naming the line and column."""
    lines = []
    for number, line, layout in ((1, line1, _LINE1), (2, line2, _LINE2)):
        if isinstance(line, str):
            line = line.rstrip("\r\n ")
        _check_line(number, line, layout)
        lines.append(line)
    if lines[0][2:7] != lines[1][2:7]:
        raise TLEFormatError(
            2, 3, f"satellite number: expected {lines[0][2:7]!r} as on line 1, got {lines[1][2:7]!r}", 7
        )
    ecc = float("0." + lines[1][26:33])
    if ecc >= 1.0:  # cannot happen with 7 digits, kept as documentation of the range
        raise TLEFormatError(2, 27, f"eccentricity: expected < 1, got {ecc}", 33)
    inc = float(lines[1][8:16])
    if not 0.0 <= inc <= 180.0:
        raise TLEFormatError(2, 9, f"inclination: expected 0 to 180 deg, got {inc}", 16)
    if float(lines[1][52:63]) <= 0.0:
        raise TLEFormatError(2, 53, f"mean motion: expected > 0 rev/day, got {lines[1][52:63].strip()}", 63)
    return lines[0], lines[1]


def read_tle_file(path: str | Path) -> tuple[str, str]:
    """The TLE in a text file: two lines, optionally after a name line; blank lines ignored.

    Raises OSError if the file cannot be read and :class:`TLEFormatError` if it does not hold
    exactly one TLE or the TLE is malformed.
    """
    text = Path(path).read_text(encoding="ascii", errors="replace")
    lines = [ln.rstrip("\r\n ") for ln in text.splitlines() if ln.strip()]
    if len(lines) == 3 and not lines[0].startswith("1 "):
        lines = lines[1:]  # three-line form: name first
    if len(lines) != 2:
        raise TLEFormatError(
            0,
            0,
            f"expected one TLE in {path} (2 lines, optionally after a name line), got {len(lines)} non-blank lines",
        )
    return check_tle(lines[0], lines[1])


def teme_to_gcrf_matrix(tt: tuple[float, float], ut1: tuple[float, float]) -> np.ndarray:
    """C_gcrf_teme (3x3) at TT and UT1 two-part Julian dates; r_gcrf = C @ r_teme.

    NPB^T R3(-(GAST - GMST82)) with NPB = erfa.pnm06a(TT) and GAST = erfa.gst06a(UT1, TT):
    see the module docstring for the chain and its accuracy.
    """
    npb = erfa.pnm06a(*tt)
    angle = erfa.gst06a(*ut1, *tt) - erfa.gmst82(*ut1)  # rad, GAST - GMST82
    c, s = math.cos(angle), math.sin(angle)
    tod_from_teme = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return npb.T @ tod_from_teme


class SGP4Propagator:
    """SGP4 propagation of one validated TLE, with output in TEME and GCRF (SI units).

    ``teme((jd1, jd2))`` propagates to a UTC two-part Julian date (rotate to GCRF with
    :func:`teme_to_gcrf_matrix`); a propagation failure (decay, eccentricity out of range, ...)
    raises RuntimeError with sgp4's SGP4_ERRORS text.
    """

    def __init__(self, line1: str, line2: str):
        from sgp4.api import WGS72, Satrec

        self.line1, self.line2 = check_tle(line1, line2)
        self.satrec = Satrec.twoline2rv(self.line1, self.line2, WGS72)
        if self.satrec.error:
            raise RuntimeError(self._error_text(self.satrec.error, "at the TLE epoch"))

    @property
    def epoch_utc(self) -> tuple[float, float]:
        """The TLE's epoch as a UTC two-part Julian date."""
        return float(self.satrec.jdsatepoch), float(self.satrec.jdsatepochF)

    def _error_text(self, code: int, when: str) -> str:
        from sgp4.api import SGP4_ERRORS

        return (
            f"SGP4 error {code} {when} for satellite {self.line1[2:7].strip()}: "
            f"{SGP4_ERRORS.get(code, 'unknown error')}"
        )

    def teme(self, utc: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
        """TEME position (m) and velocity (m/s) at a UTC two-part Julian date (days)."""
        code, r, v = self.satrec.sgp4(float(utc[0]), float(utc[1]))
        if code != 0 or not all(map(math.isfinite, r)):
            when = f"at JD {utc[0] + utc[1]:.8f} UTC ({(utc[0] - self.epoch_utc[0]) + (utc[1] - self.epoch_utc[1]):+.6f} days from the TLE epoch)"
            raise RuntimeError(self._error_text(code, when))
        return np.asarray(r) * 1e3, np.asarray(v) * 1e3
