"""Measurement, truth and estimate CSV files (design.md section 6), read strictly.

measurements: ``t_s,sensor,east_m,north_m`` (optional ``sigma_m``); truth:
``t_s,east_m,north_m,v_east_m_s,v_north_m_s`` (optional ``segment``); estimates:
``t_s,east_m,north_m,v_east_m_s,v_north_m_s`` then ``sigma_east_m,sigma_north_m``. Extra columns
are allowed after the required ones. A missing column, a row of the wrong length or a field
that is not a number raises ``InputError`` naming the file and line. Numbers such as ``nan`` or
``inf`` are read as they are: judging an observation is the estimator's job (it rejects and
counts them).
"""

import csv
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from app.core.estimation.messages import Observation
from app.errors import InputError

FloatArray = NDArray[np.float64]

MEASUREMENT_COLUMNS = ("t_s", "sensor", "east_m", "north_m")
TRUTH_COLUMNS = ("t_s", "east_m", "north_m", "v_east_m_s", "v_north_m_s")
ESTIMATE_COLUMNS = ("t_s", "east_m", "north_m", "v_east_m_s", "v_north_m_s")


@dataclass(frozen=True, slots=True)
class Truth:
    """True target states: times (n,), [east, north, v_east, v_north] (n, 4), segment labels."""

    t_s: FloatArray
    states: FloatArray
    segments: tuple[str, ...]


def _rows(path: Path, required: Sequence[str]) -> Iterator[tuple[int, dict[str, str]]]:
    try:
        handle = path.open(newline="", encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    with handle:
        reader = csv.reader(handle)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise InputError(f"{path}: empty file (expected a header)") from None
        except (csv.Error, UnicodeDecodeError) as exc:
            raise InputError(f"{path}: not a readable CSV: {exc}") from exc
        missing = [c for c in required if c not in header]
        if missing:
            raise InputError(
                f"{path}: header lacks {', '.join(missing)} (need {','.join(required)})"
            )
        try:
            for row in reader:
                if not row or all(not cell.strip() for cell in row):
                    continue
                if len(row) != len(header):
                    raise InputError(
                        f"{path}:{reader.line_num}: {len(row)} fields, header has {len(header)}"
                    )
                yield (
                    reader.line_num,
                    {h: cell.strip() for h, cell in zip(header, row, strict=True)},
                )
        except (csv.Error, UnicodeDecodeError) as exc:
            raise InputError(f"{path}: not a readable CSV: {exc}") from exc


def _float(path: Path, line: int, row: dict[str, str], key: str) -> float:
    text = row[key]
    try:
        return float(text)
    except ValueError:
        raise InputError(f"{path}:{line}: {key} is not a number: {text!r}") from None


def read_measurements(path: Path) -> list[Observation]:
    """All observations of a measurements file, in file order."""
    out: list[Observation] = []
    for line, row in _rows(path, MEASUREMENT_COLUMNS):
        sensor = row["sensor"]
        if not sensor:
            raise InputError(f"{path}:{line}: empty sensor")
        sigma_text = row.get("sigma_m", "")
        sigma = _float(path, line, row, "sigma_m") if sigma_text else None
        out.append(
            Observation(
                t_s=_float(path, line, row, "t_s"),
                sensor=sensor,
                east_m=_float(path, line, row, "east_m"),
                north_m=_float(path, line, row, "north_m"),
                sigma_m=sigma,
            )
        )
    if not out:
        raise InputError(f"{path}: no measurement rows")
    return out


def write_measurements(path: Path, observations: Iterable[Observation]) -> None:
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow([*MEASUREMENT_COLUMNS, "sigma_m"])
        for o in observations:
            sigma = "" if o.sigma_m is None else f"{o.sigma_m:.6g}"
            writer.writerow(
                [f"{o.t_s:.6f}", o.sensor, f"{o.east_m:.4f}", f"{o.north_m:.4f}", sigma]
            )


def read_truth(path: Path) -> Truth:
    """A truth file; rows must be finite and in increasing time."""
    times: list[float] = []
    states: list[list[float]] = []
    segments: list[str] = []
    for line, row in _rows(path, TRUTH_COLUMNS):
        values = [_float(path, line, row, key) for key in TRUTH_COLUMNS]
        if not all(math.isfinite(v) for v in values):
            raise InputError(f"{path}:{line}: non-finite value in the truth")
        if times and values[0] <= times[-1]:
            raise InputError(f"{path}:{line}: time {values[0]} does not increase")
        times.append(values[0])
        states.append(values[1:])
        segments.append(row.get("segment", "") or "all")
    if not times:
        raise InputError(f"{path}: no truth rows")
    return Truth(np.array(times), np.array(states), tuple(segments))


def write_truth(
    path: Path, t_s: FloatArray, states: FloatArray, segments: Sequence[str] | None = None
) -> None:
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow([*TRUTH_COLUMNS, "segment"])
        for k, t in enumerate(t_s):
            e, n, ve, vn = (float(v) for v in states[k, :4])
            label = segments[k] if segments is not None else ""
            writer.writerow([f"{t:.6f}", f"{e:.4f}", f"{n:.4f}", f"{ve:.4f}", f"{vn:.4f}", label])


def write_estimates(path: Path, t_s: FloatArray, x: FloatArray, p: FloatArray) -> None:
    """Estimates (n,), (n, 6) in the paper's state order, covariances (n, 6, 6)."""
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow([*ESTIMATE_COLUMNS, "sigma_east_m", "sigma_north_m"])
        for k, t in enumerate(t_s):
            row = x[k]
            writer.writerow(
                [
                    f"{t:.6f}",
                    f"{row[0]:.4f}",
                    f"{row[2]:.4f}",
                    f"{row[1]:.4f}",
                    f"{row[3]:.4f}",
                    f"{math.sqrt(max(p[k, 0, 0], 0.0)):.4f}",
                    f"{math.sqrt(max(p[k, 2, 2], 0.0)):.4f}",
                ]
            )


def read_estimates(path: Path) -> tuple[FloatArray, FloatArray]:
    """Times (n,) and [east, north, v_east, v_north] (n, 4) of an estimates file."""
    times: list[float] = []
    states: list[list[float]] = []
    for line, row in _rows(path, ESTIMATE_COLUMNS):
        values = [_float(path, line, row, key) for key in ESTIMATE_COLUMNS]
        times.append(values[0])
        states.append(values[1:])
    if not times:
        raise InputError(f"{path}: no estimate rows")
    return np.array(times), np.array(states)
