"""The figures of a mission run (the paper's Figs 21-22 as numbers), from sampled team states.

Pure: takes the samples the ground station recorded, returns a JSON-ready dict. Errors are
measured against the true target (the simulator's, or the scenario's scripted path), so they
include estimation error, as a user watching the vehicles would see it.

Vehicles are keyed as a user numbers them, from 1 (``vehicle_key``: the MAVLink system id, the
``vehicle-N.tlog``, the live view and the events), the samples' internal indices from 0.
"""

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from app.core.mission.team import TeamSample

#: the layout of summary.json; 2: ``schema_version``, the ``run`` block (``app.report.provenance``)
#: and vehicles keyed from 1
SUMMARY_SCHEMA_VERSION = 2


def vehicle_key(vehicle: int) -> str:
    """A vehicle's key in the summary: its number from 1 (internal index ``vehicle`` + 1)."""
    return str(vehicle + 1)


def _stats(values: Sequence[float]) -> dict[str, float]:
    a = np.asarray(values, dtype=float)
    return {"rms": float(np.sqrt(np.mean(a * a))), "max_abs": float(np.max(np.abs(a)))}


def _first_lasting(
    times: Sequence[float], ok: Sequence[bool], hold_s: float, end_t_s: float
) -> float | None:
    """First time from which ``ok`` holds for ``hold_s`` (or until ``end_t_s``)."""
    start: float | None = None
    for t, good in zip(times, ok, strict=True):
        if good:
            start = t if start is None else start
            if t - start >= hold_s or t >= end_t_s:
                return start
        else:
            start = None
    return start if start is not None and times and times[-1] >= end_t_s else None


def _settling(
    group: Sequence[TeamSample], radius_m: float, tolerance_m: float, hold_s: float
) -> dict[str, object]:
    """How a track segment began: the time from its start until every active vehicle stays
    within ``tolerance_m`` of the circle for ``hold_s`` (``time_to_circle_s``, None if never),
    and the distance and spacing errors from then to the segment's end (``settled``): the
    segment's figures without the transient its start (a turn of the target) causes."""
    near = [
        bool(errs) and all(abs(e) <= tolerance_m for e in errs.values())
        for errs in (s.distance_errors(radius_m) for s in group)
    ]
    t_on = _first_lasting([s.t_s for s in group], near, hold_s, math.inf)
    if t_on is None:
        return {"time_to_circle_s": None}
    rest = [s for s in group if s.t_s >= t_on]
    dist = [e for s in rest for e in s.distance_errors(radius_m).values()]
    spacing = [math.degrees(e) for s in rest for e in s.spacing_errors().values()]
    settled: dict[str, object] = {"distance_error_m": _stats(dist)}
    if spacing:
        settled["spacing_error_deg"] = _stats(spacing)
    return {"time_to_circle_s": t_on - group[0].t_s, "settled": settled}


def phase_key(sample: TeamSample) -> str:
    """Which part of the run a sample belongs to: the stage, and in track the target's segment."""
    if sample.stage == "track":
        return f"track:{sample.target_segment}"
    return sample.stage


def summarize(
    samples: Iterable[TeamSample],
    radius_m: float,
    tracking_command_t_s: float,
    radius_tolerance_m: float = 3.0,
    spacing_tolerance_rad: float = math.radians(2.0),
    hold_s: float = 5.0,
    loose_spacing_tolerance_rad: float = math.radians(5.0),
) -> dict[str, Any]:
    """Per part of the run and per vehicle: distance, spacing, speed and estimation figures.

    Returns ``{"schema_version": 2, "parts": {key: {"vehicles": {number: figures}, "team":
    figures}}, "convergence": {...}, "respace": [...]}`` (vehicles numbered from 1) with
    distances in metres, angles in degrees, speeds in m/s and times in seconds after the
    tracking command.

    ``convergence`` has the formation held (every vehicle within ``radius_tolerance_m`` and
    every spacing within ``spacing_tolerance_rad`` for ``hold_s``) and, in ``first_within``,
    the first instant every vehicle is within ``radius_tolerance_m`` and every spacing within
    ``loose_spacing_tolerance_rad`` (no hold). ``respace`` has one entry per loss of a vehicle
    after the tracking command (``respace_after_losses``).
    """
    rows = sorted(samples, key=lambda s: s.t_s)
    parts: dict[str, list[TeamSample]] = {}
    for sample in rows:
        parts.setdefault(phase_key(sample), []).append(sample)
    out_parts: dict[str, object] = {}
    for key, group in parts.items():
        dist: dict[int, list[float]] = {}
        spacing: dict[int, list[float]] = {}
        speed: dict[int, list[float]] = {}
        est_pos: list[float] = []
        est_vel: list[float] = []
        for s in group:
            for vehicle, e in s.distance_errors(radius_m).items():
                dist.setdefault(vehicle, []).append(e)
            for vehicle, e in s.spacing_errors().items():
                spacing.setdefault(vehicle, []).append(math.degrees(e))
            for v in s.vehicles:
                if v.active:
                    speed.setdefault(v.vehicle, []).append(v.speed_m_s)
            if s.estimate is not None:
                est_pos.append(
                    math.hypot(s.estimate[0] - s.target_east_m, s.estimate[1] - s.target_north_m)
                )
                est_vel.append(
                    math.hypot(
                        s.estimate[2] - s.target_v_east_m_s, s.estimate[3] - s.target_v_north_m_s
                    )
                )
        vehicles: dict[str, object] = {}
        for vehicle in sorted(dist):
            figures: dict[str, object] = {"distance_error_m": _stats(dist[vehicle])}
            if vehicle in spacing:
                figures["spacing_error_deg"] = _stats(spacing[vehicle])
            figures["speed_m_s"] = {"min": min(speed[vehicle]), "max": max(speed[vehicle])}
            vehicles[vehicle_key(vehicle)] = figures
        all_dist = [e for errs in dist.values() for e in errs]
        all_spacing = [e for errs in spacing.values() for e in errs]
        team: dict[str, object] = {
            "start_s": group[0].t_s - tracking_command_t_s,
            "end_s": group[-1].t_s - tracking_command_t_s,
        }
        if all_dist:
            team["distance_error_m"] = _stats(all_dist)
        if all_spacing:
            team["spacing_error_deg"] = _stats(all_spacing)
        if est_pos:
            team["estimation_rmse"] = {
                "position_m": _stats(est_pos)["rms"],
                "velocity_m_s": _stats(est_vel)["rms"],
            }
        if key.startswith("track:") and all_dist:
            team.update(_settling(group, radius_m, radius_tolerance_m, hold_s))
        out_parts[key] = {"vehicles": vehicles, "team": team}
    after = [s for s in rows if s.t_s >= tracking_command_t_s and s.stage != "standby"]
    track_start = next((s.t_s for s in after if s.stage == "track"), math.inf)
    times = [s.t_s for s in after]
    near = [
        bool(errs) and all(abs(e) <= radius_tolerance_m for e in errs.values())
        for errs in (s.distance_errors(radius_m) for s in after)
    ]
    spaced = [
        bool(errs) and all(abs(e) <= spacing_tolerance_rad for e in errs.values())
        for errs in (s.spacing_errors() for s in after)
    ]
    formed = [a and b for a, b in zip(near, spaced, strict=True)]

    def since_command(t: float | None) -> float | None:
        return None if t is None else t - tracking_command_t_s

    convergence = {
        "time_to_circle_s": since_command(_first_lasting(times, near, hold_s, track_start)),
        "time_to_spacing_s": since_command(_first_lasting(times, spaced, hold_s, track_start)),
        "time_to_formation_s": since_command(_first_lasting(times, formed, hold_s, track_start)),
        "radius_tolerance_m": radius_tolerance_m,
        "spacing_tolerance_deg": math.degrees(spacing_tolerance_rad),
        "hold_s": hold_s,
        "first_within": {
            "t_s": since_command(
                _first_instant(after, radius_m, radius_tolerance_m, loose_spacing_tolerance_rad)
            ),
            "radius_tolerance_m": radius_tolerance_m,
            "spacing_tolerance_deg": math.degrees(loose_spacing_tolerance_rad),
        },
    }
    out: dict[str, Any] = {
        "schema_version": SUMMARY_SCHEMA_VERSION,
        "parts": out_parts,
        "convergence": convergence,
        "respace": respace_after_losses(after, tracking_command_t_s, loose_spacing_tolerance_rad),
    }
    separation = closest_pair(rows)
    if separation is not None:
        out["separation"] = separation
    return out


def _first_instant(
    samples: Sequence[TeamSample], radius_m: float, radius_tol_m: float, spacing_tol_rad: float
) -> float | None:
    """The first sample time at which every active vehicle is within ``radius_tol_m`` of the
    circle and every spacing within ``spacing_tol_rad``; None if never."""
    for s in samples:
        dist, spacing = s.distance_errors(radius_m), s.spacing_errors()
        if (
            dist
            and spacing
            and all(abs(e) <= radius_tol_m for e in dist.values())
            and all(abs(e) <= spacing_tol_rad for e in spacing.values())
        ):
            return s.t_s
    return None


def respace_after_losses(
    samples: Sequence[TeamSample], tracking_command_t_s: float, tolerance_rad: float
) -> list[dict[str, Any]]:
    """How the team re-spaced after each loss of a vehicle (the number of active vehicles
    falling, to at least two): when the loss was seen (``t_s``, after the tracking command),
    how many flew before and after, ``first_within_s`` (seconds from the loss until every
    spacing is first within ``tolerance_rad`` of 2 pi / n; None if never before the next loss
    or the end) and, from then to the next loss or the end, the RMS and largest spacing error
    (deg) and the fraction of samples within the tolerance."""
    out: list[dict[str, Any]] = []
    counts = [sum(v.active for v in s.vehicles) for s in samples]
    losses = [i for i in range(1, len(samples)) if 2 <= counts[i] < counts[i - 1]]
    for k, i in enumerate(losses):
        end = losses[k + 1] if k + 1 < len(losses) else len(samples)
        worst = [
            max((abs(e) for e in s.spacing_errors().values()), default=0.0) for s in samples[i:end]
        ]
        first = next((j for j, w in enumerate(worst) if w <= tolerance_rad), None)
        entry: dict[str, Any] = {
            "t_s": samples[i].t_s - tracking_command_t_s,
            "vehicles_before": counts[i - 1],
            "vehicles_after": counts[i],
            "first_within_s": None if first is None else samples[i + first].t_s - samples[i].t_s,
            "tolerance_deg": math.degrees(tolerance_rad),
        }
        if first is not None:
            errs = [
                math.degrees(e)
                for s in samples[i + first : end]
                for e in s.spacing_errors().values()
            ]
            entry["after_first"] = {
                "spacing_error_deg": _stats(errs),
                "within_fraction": sum(w <= tolerance_rad for w in worst[first:])
                / len(worst[first:]),
                "duration_s": samples[end - 1].t_s - samples[i + first].t_s,
            }
        out.append(entry)
    return out


def closest_pair(samples: Sequence[TeamSample]) -> dict[str, Any] | None:
    """The least 3-D distance between two active vehicles over the samples (of those whose
    height is known; a lost vehicle's last report is not a position): metres, when (s of
    mission time), which pair (numbered from 1), and the horizontal and vertical parts; None
    without two heights at any one time."""
    best: tuple[float, float, int, int, float, float] | None = None
    for s in samples:
        known = [(v, v.up_m) for v in s.vehicles if v.up_m is not None and v.active]
        for i, (a, a_up) in enumerate(known):
            for b, b_up in known[i + 1 :]:
                h = math.hypot(a.east_m - b.east_m, a.north_m - b.north_m)
                z = abs(a_up - b_up)
                d = math.hypot(h, z)
                if best is None or d < best[0]:
                    best = (d, s.t_s, a.vehicle, b.vehicle, h, z)
    if best is None:
        return None
    d, t, a_id, b_id, h, z = best
    return {
        "min_distance_m": round(d, 2),
        "t_s": round(t, 2),
        "pair": sorted([vehicle_key(a_id), vehicle_key(b_id)]),
        "horizontal_m": round(h, 2),
        "vertical_m": round(z, 2),
    }
