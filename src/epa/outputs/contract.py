"""The numeric contract (docs/reproducibility.md): when two results of the same inputs and settings
agree, whatever CPU made them.

Floating-point results differ in their last bits from one CPU to another (numpy's SIMD dispatch,
OpenBLAS's kernels, FFT code paths), never on one machine. So:

- a **printed output** (tables, ``error_comparison.txt``, ``summary.csv``, ``comparison.*``,
  ``success_curves.csv``, rpg's and ov_eval's text) is the same *text*. A printed digit may still
  flip where the full-precision value lies within the contract of a rounding boundary: two texts
  that differ only in numbers, each pair one unit apart in the last printed digit of the finer one
  (and never two integers: counts do not round), are *identical but for rounding* and each flip is
  reported with its place;
- a **record** (``metrics.json``, every stage artifact, ``consistency/<alg>/<dataset>.csv``) agrees
  number by number: ``|a - b| <= RTOL * max(|a|, |b|) + atol`` where ``atol`` is tied to the
  quantity's scale, so that a value that is zero up to rounding (a quaternion component of 1e-14, an
  off-diagonal covariance) does not fail on relative error:

  * in an array (a column of a CSV or TUM file, a numeric JSON list or matrix), ``SCALE_ATOL`` times
    the largest magnitude in that column or list (the 3x3 covariance blocks ``pr11..pr33`` and
    ``pt11..pt33`` share one scale: their diagonal);
  * a named JSON scalar, ``SCALAR_ATOL`` in its own unit;
  * a time stamp (a column ``t`` or ``t_*``, a JSON ``*_span_s``), ``STAMP_ATOL`` seconds plus four
    units in the last place: a stamp of 1.7e9 s is absolute, a relative 1e-8 of it would be 17 s;
  * and never less than ``FLOOR_ATOL`` in the value's own unit: a column or list that is zero up to
    rounding as a whole (every value about 1e-17) has no scale of its own to measure it by.

  Counts, strings, booleans, nulls and the structure (keys, lengths, headers) must be equal.

The constants come from measurement (docs/reproducibility.md, "The numeric contract"): the worst
difference between numpy's AVX-512 and baseline paths with OpenBLAS's SkylakeX and Sandybridge
kernels on the example, the .test configs and 52 EuRoC cases, with a margin, and far below a change
of 1e-6 relative, which every rule catches.
"""

from __future__ import annotations

import io
import json
import math
import re
from dataclasses import dataclass, field
from decimal import Decimal
from enum import StrEnum
from pathlib import Path

import numpy as np

from epa.metrics import accuracy

RTOL = 1e-8
SCALE_ATOL = 1e-8
# one quantity's statistics share its scale: a min near 0 is no more exact than the max
STATISTICS = frozenset(accuracy.STATISTICS)
SCALAR_ATOL = 1e-12
STAMP_ATOL = 1e-9
STAMP_ULPS = 4
FLOOR_ATOL = 1e-12  # the least tolerance of any number, in its own unit

# a number in printed text: not glued to a word (run1, MH_01, x86_64) nor to another number's dot
_NUMBER = re.compile(r"(?<![\w.])[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?(?![\w.])")
_COVARIANCE = re.compile(r"p[rt]\d\d")


class Verdict(StrEnum):
    IDENTICAL = "identical"
    ROUNDING = "identical but for rounding"
    WITHIN = "within the contract"
    DIFFERS = "differs"
    MISSING = "not regenerated"
    EXTRA = "only in the regenerated results"


PASSING = (Verdict.IDENTICAL, Verdict.ROUNDING, Verdict.WITHIN)


@dataclass(frozen=True)
class Place:
    """One value of a comparison: where it is, both texts, their difference and the tolerance."""

    where: str
    a: str
    b: str
    diff: float = math.nan
    tol: float = math.nan

    def describe(self) -> str:
        text = f"{self.where}: {self.a} vs {self.b}"
        if math.isfinite(self.diff):
            text += f" (|difference| {self.diff:.3g}, tolerance {self.tol:.3g})"
        return text


@dataclass(frozen=True)
class Comparison:
    """A file's verdict: its worst difference within the contract, the first that breaks it, or
    every printed digit that flipped at a rounding boundary."""

    name: str
    kind: str  # "printed" or "record"
    verdict: Verdict
    worst: Place | None = None
    flips: tuple[Place, ...] = field(default=())

    @property
    def ok(self) -> bool:
        return self.verdict in PASSING

    def line(self) -> str:
        if self.verdict == Verdict.IDENTICAL or self.worst is None:
            return f"{self.verdict}: {self.name}"
        if self.verdict == Verdict.ROUNDING:
            more = f" (+{len(self.flips) - 1} more)" if len(self.flips) > 1 else ""
            return f"{self.verdict}: {self.name}: {self.worst.describe()}{more}"
        label = "worst" if self.verdict == Verdict.WITHIN else "first"
        return f"{self.verdict}: {self.name}: {label} {self.worst.describe()}"

    def to_dict(self) -> dict:
        out: dict = {"file": self.name, "kind": self.kind, "verdict": str(self.verdict)}
        if self.worst is not None:
            out["where"] = self.worst.where
            out["values"] = [self.worst.a, self.worst.b]
            if math.isfinite(self.worst.diff):
                out["difference"] = self.worst.diff
                out["tolerance"] = self.worst.tol
        if self.flips:
            out["rounding_flips"] = [f"{p.where}: {p.a} vs {p.b}" for p in self.flips]
        return out


# ----------------------------------------------------------------------------- tolerances
def tolerance(a: float, b: float, scale: float, *, stamp: bool = False) -> float:
    """The contract's tolerance for two values of one quantity whose scale is ``scale`` (the largest
    magnitude of its column or list; ``None``-like 0 for a named scalar)."""
    big = max(abs(a), abs(b))
    if stamp:
        return STAMP_ATOL + STAMP_ULPS * math.ulp(big)
    if scale:
        return max(RTOL * big + SCALE_ATOL * scale, FLOOR_ATOL)
    return max(RTOL * big + SCALAR_ATOL, FLOOR_ATOL)


def _is_stamp(name: str) -> bool:
    return name == "t" or name.startswith("t_") or name.endswith("_span_s")


# ----------------------------------------------------------------------------- printed text
def _unit(token: str) -> Decimal:
    """One unit in the last printed digit of a number as text (0.089 -> 0.001, 1.2e-05 -> 1e-06),
    exactly: in binary floating point a one-unit flip could come out a hair above its unit."""
    mantissa, _, exponent = token.lower().partition("e")
    decimals = len(mantissa.split(".", 1)[1]) if "." in mantissa else 0
    return Decimal(1).scaleb(int(exponent or 0) - decimals)


def _is_integer(token: str) -> bool:
    return not any(c in token for c in ".eE")


def _where_printed(name: str, lines_a: list[str], i: int, start: int) -> str:
    where = f"line {i + 1}"
    if name.endswith(".csv") and lines_a:
        header = lines_a[0].split(",")
        col = lines_a[i][:start].count(",")
        if col < len(header):
            where += f", column {header[col]}"
    return where


def compare_printed(name: str, a: str, b: str) -> Comparison:
    """Printed outputs: the same text, or the same but for digits flipped at a rounding boundary."""
    if a == b:
        return Comparison(name, "printed", Verdict.IDENTICAL)
    la, lb = a.splitlines(), b.splitlines()
    if len(la) != len(lb):
        i = next((k for k, (x, y) in enumerate(zip(la, lb)) if x != y), min(len(la), len(lb)))
        place = Place(f"line {i + 1}", _line(la, i), _line(lb, i))
        return Comparison(name, "printed", Verdict.DIFFERS, place)
    flips = []
    for i, (x, y) in enumerate(zip(la, lb)):
        if x == y:
            continue
        mx, my = list(_NUMBER.finditer(x)), list(_NUMBER.finditer(y))
        if _NUMBER.sub("#", x) != _NUMBER.sub("#", y) or len(mx) != len(my):
            return Comparison(name, "printed", Verdict.DIFFERS, Place(f"line {i + 1}", x, y))
        for p, q in zip(mx, my):
            ta, tb = p.group(), q.group()
            if ta == tb:
                continue
            place = Place(_where_printed(name, la, i, p.start()), ta, tb)
            unit = min(_unit(ta), _unit(tb))
            diff = abs(Decimal(ta) - Decimal(tb))  # exact, like the text
            if (_is_integer(ta) and _is_integer(tb)) or diff > unit:
                place = Place(place.where, ta, tb, float(diff), float(unit))
                return Comparison(name, "printed", Verdict.DIFFERS, place)
            flips.append(place)
    return Comparison(name, "printed", Verdict.ROUNDING, flips[0], tuple(flips))


def _line(lines: list[str], i: int) -> str:
    return lines[i] if i < len(lines) else "(end of file)"


# ----------------------------------------------------------------------------- records
class _Breach(Exception):
    def __init__(self, place: Place):
        self.place = place


class _Worst:
    """The worst value pair seen so far, by difference over tolerance."""

    def __init__(self):
        self.ratio, self.place = -1.0, None

    def see(self, ratio: float, place: Place) -> None:
        if ratio > self.ratio:
            self.ratio, self.place = ratio, place


def _numeric(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _numeric_array(x) -> bool:
    """A JSON list of numbers, or of such lists (a vector, a matrix)."""
    return isinstance(x, list) and bool(x) and all(_numeric(v) or _numeric_array(v) for v in x)


def _flat(x) -> list[float]:
    return (
        [float(v) for v in x] if all(_numeric(v) for v in x) else [f for v in x for f in _flat(v)]
    )


def _shape(x) -> tuple[int, ...] | None:
    """A numeric array's shape; None when it is ragged."""
    try:
        return np.shape(x)
    except ValueError:
        return None


def _statistics_scale(d: dict) -> float:
    """The scale of a record of one quantity's statistics (min, max, mean, ...: two or more of
    them): their largest magnitude; 0 for any other record."""
    values = [abs(v) for k, v in d.items() if k in STATISTICS and isinstance(v, float)]
    return max(values) if len(values) >= 2 else 0.0


def _json_path(path: str) -> str:
    return "$" + path


def _compare_values(a, b, path: str, scale: float, stamp: bool, worst: _Worst) -> None:
    if _numeric(a) and _numeric(b):
        if a == b:
            return
        diff, tol = abs(a - b), tolerance(a, b, scale, stamp=stamp)
        if not diff <= tol:
            raise _Breach(Place(_json_path(path), repr(a), repr(b), diff, tol))
        worst.see(diff / tol, Place(_json_path(path), repr(a), repr(b), diff, tol))
    elif a != b or type(a) is not type(b):
        raise _Breach(Place(_json_path(path), json.dumps(a), json.dumps(b)))


def _compare_json(a, b, path: str, worst: _Worst, stamp: bool = False) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        if list(a) != list(b):
            odd = next((k for k in [*a, *b] if (k in a) != (k in b)), None)
            if odd is None:  # the same keys in another order
                raise _Breach(
                    Place(_json_path(path), "keys " + ", ".join(a), "keys " + ", ".join(b))
                )
            said = ("present" if odd in a else "absent", "present" if odd in b else "absent")
            raise _Breach(Place(_json_path(f"{path}.{odd}"), *said))
        scale = max(_statistics_scale(a), _statistics_scale(b))
        for k in a:
            if scale and k in STATISTICS:
                _compare_values(a[k], b[k], f"{path}.{k}", scale, False, worst)
            else:
                _compare_json(a[k], b[k], f"{path}.{k}", worst, _is_stamp(k))
    elif _numeric_array(a) and _numeric_array(b) and _shape(a) == _shape(b) is not None:
        fa, fb = _flat(a), _flat(b)
        scale = max(max(map(abs, fa)), max(map(abs, fb)))
        shape = np.shape(a)  # not ragged: _shape(a) is not None
        for k, (x, y) in enumerate(zip(fa, fb)):
            index = "".join(f"[{i}]" for i in np.unravel_index(k, shape))
            _compare_values(x, y, path + index, scale, stamp, worst)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            raise _Breach(Place(_json_path(path), f"{len(a)} items", f"{len(b)} items"))
        for k, (x, y) in enumerate(zip(a, b)):
            _compare_json(x, y, f"{path}[{k}]", worst, stamp)
    else:
        _compare_values(a, b, path, 0.0, stamp, worst)


def _table(text: str) -> tuple[list[str], list[str], list[str], str | None]:
    """A CSV or TUM-like artifact: its header lines, column names, data lines and separator."""
    lines = text.splitlines()
    head = []
    while lines and (lines[0].startswith("#") or not lines[0].strip()):
        head.append(lines.pop(0))
    sep = "," if any("," in line for line in lines[:2] + head[-1:]) else None
    if lines and not head and not _all_numbers(lines[0].split(sep)):
        head.append(lines.pop(0))
    names = [n.strip() for n in head[-1].lstrip("#").split(sep)] if head else []
    lines = [line for line in lines if line.strip()]
    width = len(lines[0].split(sep)) if lines else len(names)
    if len(names) != width:
        names = [f"column {k + 1}" for k in range(width)]
    return head, names, lines, sep


def _all_numbers(fields: list[str]) -> bool:
    try:
        [float(f) for f in fields]
    except ValueError:
        return False
    return True


def _floats(lines: list[str], sep: str | None, width: int) -> np.ndarray:
    """The cells as numbers (pandas' C parser: 20x Python's float() on a 7,500-row artifact); a
    cell that is no number (empty, True, a word) is NaN and its text is compared instead."""
    import pandas as pd

    text = io.StringIO("\n".join(lines))
    frame = pd.read_csv(text, sep=sep or r"\s+", header=None, names=range(width))
    out = np.empty(frame.shape)
    for k in range(width):
        out[:, k] = pd.to_numeric(frame[k], errors="coerce").to_numpy(dtype=float, na_value=np.nan)
    return out


def _scales(names: list[str], xa: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """Each column's largest magnitude; a covariance block's columns share their block's."""
    with np.errstate(invalid="ignore"):
        col = np.nanmax(np.maximum(np.abs(xa), np.abs(xb)), axis=0, initial=0.0)
    scale = col.copy()
    for block in ("pr", "pt"):
        members = [k for k, n in enumerate(names) if _COVARIANCE.fullmatch(n) and n[:2] == block]
        if members:
            scale[members] = col[members].max()
    return scale


def _compare_table(a: str, b: str, worst: _Worst) -> None:
    head_a, names, rows_a, sep = _table(a)
    head_b, _, rows_b, _ = _table(b)
    if head_a != head_b:
        raise _Breach(Place("header", " | ".join(head_a), " | ".join(head_b)))
    if len(rows_a) != len(rows_b):
        raise _Breach(Place("rows", f"{len(rows_a)} rows", f"{len(rows_b)} rows"))
    if rows_a == rows_b:
        return
    try:
        xa, xb = _floats(rows_a, sep, len(names)), _floats(rows_b, sep, len(names))
    except ValueError as exc:  # pandas: a row with more fields than the first
        raise _Breach(Place("rows", "rows of different widths", str(exc).strip())) from None
    scale = _scales(names, xa, xb)
    stamp = np.array([_is_stamp(n) for n in names])
    big = np.maximum(np.abs(xa), np.abs(xb))
    with np.errstate(invalid="ignore", over="ignore"):
        tol = np.where(
            stamp,
            STAMP_ATOL + STAMP_ULPS * np.spacing(big),
            np.maximum(RTOL * big + SCALE_ATOL * scale, FLOOR_ATOL),
        )
        diff = np.abs(xa - xb)
    finite = np.isfinite(xa) & np.isfinite(xb)
    differ = ~((xa == xb) | (np.isnan(xa) & np.isnan(xb)))
    bad = differ & ~(diff <= tol)
    for r, c in np.argwhere(~finite):  # words, empty cells, nan, inf, a short row: the same text
        fields_a, fields_b = rows_a[r].split(sep), rows_b[r].split(sep)
        if len(fields_a) != len(names) or len(fields_b) != len(names):
            raise _Breach(Place(f"row {r + 1}", rows_a[r], rows_b[r]))
        bad[r, c] = fields_a[c].strip().lower() != fields_b[c].strip().lower()
    if bad.any():
        r, c = np.argwhere(bad)[0]
        cell_a, cell_b = rows_a[r].split(sep)[c].strip(), rows_b[r].split(sep)[c].strip()
        place = Place(f"row {r + 1}, column {names[c]}", cell_a, cell_b)
        if finite[r, c]:
            place = Place(place.where, place.a, place.b, float(diff[r, c]), float(tol[r, c]))
        raise _Breach(place)
    ratio = np.where(differ & finite, diff / np.where(tol > 0, tol, np.inf), -1.0)
    r, c = np.unravel_index(np.argmax(ratio), ratio.shape)
    if ratio[r, c] >= 0:
        where = f"row {r + 1}, column {names[c]}"
        cell_a, cell_b = rows_a[r].split(sep)[c].strip(), rows_b[r].split(sep)[c].strip()
        place = Place(where, cell_a, cell_b, float(diff[r, c]), float(tol[r, c]))
        worst.see(float(ratio[r, c]), place)


def compare_record(name: str, a: str, b: str) -> Comparison:
    """A record (JSON) or an array (CSV, TUM): every number within the contract."""
    if a == b:
        return Comparison(name, "record", Verdict.IDENTICAL)
    worst = _Worst()
    try:
        if name.endswith(".json"):
            _compare_json(json.loads(a), json.loads(b), "", worst)
        elif name.endswith((".yaml", ".yml")):  # rpg's statistics files
            import yaml

            _compare_json(yaml.safe_load(a), yaml.safe_load(b), "", worst)
        else:
            _compare_table(a, b, worst)
    except _Breach as breach:
        return Comparison(name, "record", Verdict.DIFFERS, breach.place)
    except (ValueError, ImportError) as exc:  # not JSON: the text is all there is to compare
        return Comparison(name, "record", Verdict.DIFFERS, Place("file", "?", str(exc)))
    return Comparison(name, "record", Verdict.WITHIN, worst.place)


def rewritten(data: bytes, rewrites) -> bytes:
    """``data`` with each ``(new, recorded)`` text of ``rewrites`` put back as recorded."""
    for new, recorded in rewrites:
        data = data.replace(new.encode(), recorded.encode())
    return data


def compare_files(a: Path, b: Path, name: str, kind: str, rewrites=()) -> Comparison:
    """``a/name`` (the results) against ``b/name`` (the regenerated ones) as ``kind``; in the
    regenerated text each ``(new, recorded)`` of ``rewrites`` is put back as recorded."""
    pa, pb = Path(a) / name, Path(b) / name
    if not pb.is_file():
        return Comparison(name, kind, Verdict.MISSING)
    if not pa.is_file():
        return Comparison(name, kind, Verdict.EXTRA)
    ba, bb = pa.read_bytes(), rewritten(pb.read_bytes(), rewrites)
    if ba == bb:
        return Comparison(name, kind, Verdict.IDENTICAL)
    ta, tb = ba.decode("utf-8", "replace"), bb.decode("utf-8", "replace")
    return compare_printed(name, ta, tb) if kind == "printed" else compare_record(name, ta, tb)
