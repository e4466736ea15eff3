"""The turn-efficiency fit and the ArduPlane adapter that sizes its turn commands on it."""

import math
from dataclasses import replace

import numpy as np
import pytest

from app.adapters.vehicle.autopilots.arduplane import ArduPlaneAdapter
from app.adapters.vehicle.autopilots.turn_efficiency import (
    GRAVITY_M_S2,
    TurnEfficiency,
    TurnEfficiencyParams,
)
from app.runtime.ports.vehicle import CourseSpeedCommand
from tests.adapters.test_autopilots import (
    LIMITS,
    STATE,
    STOCK_ARDUPLANE,
    CommandRecorder,
    ParamRecorder,
)


def turning(
    efficiency: float,
    seconds: float,
    *,
    t0_s: float = 0.0,
    course0_rad: float = 0.0,
    speed_m_s: float = 14.0,
    seed: int = 0,
    course_noise_rad: float = 0.0,
    rate_hz: float = 10.0,
):
    """Frames (t, course, roll, speed) of an airframe banking through +-10..30 deg and turning
    at ``efficiency`` of the coordinated rate."""
    rng = np.random.default_rng(seed)
    course, frames = course0_rad, []
    dt = 1.0 / rate_hz
    for k in range(round(seconds * rate_hz)):
        t = t0_s + k * dt
        roll = math.radians(20.0) * math.sin(2.0 * math.pi * t / 40.0) + math.radians(10.0)
        noisy = course + rng.normal(0.0, course_noise_rad) if course_noise_rad else course
        frames.append((t, noisy, roll, speed_m_s))
        course += efficiency * GRAVITY_M_S2 * math.tan(roll) / speed_m_s * dt
    return frames


def fit(frames, params: TurnEfficiencyParams | None = None) -> TurnEfficiency:
    turn = TurnEfficiency(params or TurnEfficiencyParams())
    for frame in frames:
        turn = turn.update(*frame)
    return turn


@pytest.mark.parametrize("efficiency", [0.55, 0.7, 0.95])
def test_the_fit_finds_the_fraction_of_the_coordinated_turn_flown(efficiency):
    turn = fit(turning(efficiency, 120.0, course_noise_rad=math.radians(0.3)))
    assert turn.ready
    # the bank's mean over an interval against the course change over it: within 2 %
    assert turn.efficiency == pytest.approx(efficiency, rel=0.02)


def test_not_ready_before_enough_turning_and_then_the_coordinated_turn_is_assumed():
    params = TurnEfficiencyParams(min_turning_s=10.0)
    early = fit(turning(0.7, 8.0), params)
    assert not early.ready
    assert early.efficiency == 1.0
    assert fit(turning(0.7, 14.0), params).ready


def test_straight_and_level_flight_teaches_nothing():
    frames = [(0.1 * k, 0.4, math.radians(0.5), 14.0) for k in range(3000)]
    turn = fit(frames)
    assert (turn.samples, turn.turning_s, turn.ready, turn.efficiency) == (0, 0.0, False, 1.0)


@pytest.mark.parametrize(("flown", "expected"), [(1.3, 1.0), (0.2, 0.4)])
def test_the_estimate_is_clamped_to_a_level_turns_range(flown, expected):
    assert fit(turning(flown, 60.0)).efficiency == pytest.approx(expected)


def test_a_turn_through_north_is_not_taken_for_a_full_circle():
    frames = turning(0.7, 120.0, course0_rad=math.pi - 0.05)
    wrapped = [(t, math.remainder(c, 2.0 * math.pi), r, v) for t, c, r, v in frames]
    assert fit(wrapped).efficiency == pytest.approx(fit(frames).efficiency, abs=1e-9)


def test_bad_frames_restart_the_interval_and_spoil_nothing():
    frames = turning(0.7, 120.0)
    spoiled = list(frames)
    for k in range(50, len(frames), 97):
        t, c, r, v = frames[k]
        spoiled[k] = (t, c, [math.nan, None, r][k % 3], [v, v, math.inf][k % 3])
    spoiled.insert(300, (spoiled[299][0] - 5.0, 2.0, 0.3, 14.0))  # out of time order
    turn = fit(spoiled)
    assert turn.efficiency == pytest.approx(0.7, rel=0.02)
    assert math.isfinite(turn.sum_xy)
    assert math.isfinite(turn.sum_xx)


def test_a_telemetry_gap_is_not_spanned():
    # 3 s without frames while the course jumps: no interval runs across the gap
    before = turning(0.7, 30.0)
    after = turning(0.7, 30.0, t0_s=33.0, course0_rad=before[-1][1] + 1.5)
    assert fit(before + after).efficiency == pytest.approx(0.7, rel=0.02)


def hunting(seconds: float, *, steady: float, changing: float, seed: int = 0):
    """Frames of ArduPlane 4.6.2's GUIDED turns as its tlogs showed them: banks held for a few
    seconds, and episodes where the bank hunts +-6.5 deg about its demand with a 1.5 s period.
    The course turns at ``steady`` of the coordinated rate at a held bank and, as read over the
    real episodes' intervals, at ``changing`` of it while the bank moves."""
    rng = np.random.default_rng(seed)
    course, frames, t, dt = 0.0, [], 0.0, 0.1
    while t < seconds:
        bank = math.radians(rng.uniform(10.0, 30.0)) * rng.choice([-1.0, 1.0])
        for _ in range(40):  # 4 s held
            frames.append((t, course, bank, 14.0))
            course += steady * GRAVITY_M_S2 * math.tan(bank) / 14.0 * dt
            t += dt
        for k in range(60):  # 6 s hunting
            roll = bank + math.radians(6.5) * math.sin(2.0 * math.pi * k * dt / 1.5)
            frames.append((t, course, roll, 14.0))
            course += changing * GRAVITY_M_S2 * math.tan(roll) / 14.0 * dt
            t += dt
    return frames


def test_the_intervals_where_the_bank_hunts_are_left_out():
    frames = hunting(300.0, steady=0.70, changing=0.86)
    turn = fit(frames)
    assert turn.ready
    assert turn.unsteady > turn.samples / 2
    assert turn.efficiency == pytest.approx(0.70, abs=0.01)
    # counting every interval reads what real ArduPlane's fit read, 0.75 or more
    everything = fit(frames, TurnEfficiencyParams(max_roll_rate_rad_s=100.0))
    assert everything.unsteady == 0
    assert everything.efficiency > 0.75


def test_old_turns_are_forgotten():
    params = TurnEfficiencyParams(memory_s=60.0)
    first = turning(1.0, 120.0)
    then = turning(0.6, 600.0, t0_s=120.1, course0_rad=first[-1][1])
    assert fit(first + then, params).efficiency == pytest.approx(0.6, abs=0.01)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"period_s": 0.0}, "period_s"),
        ({"memory_s": math.nan}, "memory_s"),
        ({"period_s": 1.0, "max_period_s": 0.5}, "max_period_s"),
        ({"min_efficiency": 1.5}, "min_efficiency"),
    ],
)
def test_bad_params_are_refused(changes, message):
    with pytest.raises(ValueError, match=message):
        TurnEfficiencyParams(**changes)


# ---- the ArduPlane adapter -------------------------------------------------------------------


def adapter(commands=None, **changes) -> ArduPlaneAdapter:
    return ArduPlaneAdapter(
        vehicle_id=1,
        commands=commands or CommandRecorder(),
        params=ParamRecorder(dict(STOCK_ARDUPLANE)),
        limits=LIMITS,
        telemetry_rates_hz=None,
        gcs_system_id=None,
        **changes,
    )


async def flown_through(plane: ArduPlaneAdapter, frames) -> None:
    """Fly ``frames`` through ``send``: each one a GUIDED tick the adapter steers on."""
    for t, course, roll, speed in frames:
        state = replace(STATE, t_s=t, course_rad=course, roll_rad=roll, flying_speed_m_s=speed)
        await plane.send(CourseSpeedCommand(course + 0.2, speed), 100.0, state)


async def test_the_adapter_sizes_its_turn_limit_and_heading_command_on_what_it_learned():
    learned: list[tuple[float, float, int, float]] = []
    commands = CommandRecorder()
    plane = adapter(commands, on_turn_learned=lambda *args: learned.append(args))
    await plane.prepare()
    assert plane.turn_efficiency == 1.0
    assert plane.lateral_accel_limit(14.0, 14.0) == pytest.approx(14.0 * 0.2)
    await flown_through(plane, turning(0.7, 90.0))
    eta = plane.turn_efficiency
    assert eta == pytest.approx(0.7, rel=0.02)
    # told once, when first ready (eta hardly moves after that)
    assert len(learned) == 1
    assert learned[0][1] == pytest.approx(eta, rel=0.01)
    assert learned[0][3] >= 10.0
    # the turn limit: the bank that, at eta of the coordinated turn, turns at the envelope's rate
    accel = plane.lateral_accel_limit(14.0, 14.0)
    assert eta * accel / 14.0 == pytest.approx(0.2)
    (last,) = [f for *_, f in commands.sent if f["command"] == 43002][-1:]
    assert last["param3"] == pytest.approx(accel, rel=0.1)  # re-sent when it moved by 10 %
    # the heading command: GUIDED_P's bank turns at k e, k the envelope's 1 /s
    state = replace(STATE, course_rad=0.3, flying_speed_m_s=14.0)
    sent = plane.linearised_course(0.3 + 0.1, state, 14.0)
    bank = math.radians(5000.0 / 100.0) * (sent - 0.3)
    assert eta * GRAVITY_M_S2 * math.tan(bank) / 14.0 == pytest.approx(0.1, rel=1e-9)


async def test_without_learning_the_coordinated_turn_is_assumed():
    plane = adapter(learn_turn_efficiency=False)
    await plane.prepare()
    await flown_through(plane, turning(0.7, 90.0))
    assert plane.turn_efficiency == 1.0
    assert plane.lateral_accel_limit(14.0, 14.0) == pytest.approx(14.0 * 0.2)


async def test_a_vehicle_that_reports_no_bank_is_steered_on_the_coordinated_turn():
    plane = adapter()
    await plane.prepare()
    frames = [(t, c, None, v) for t, c, _, v in turning(0.7, 90.0)]
    for t, course, roll, speed in frames:
        state = replace(STATE, t_s=t, course_rad=course, roll_rad=roll, flying_speed_m_s=speed)
        await plane.send(CourseSpeedCommand(course + 0.2, speed), 100.0, state)
    assert plane.turn_efficiency == 1.0


def saturating_error(plane: ArduPlaneAdapter) -> float | None:
    return plane.course_error_limit_rad


async def test_the_linearised_command_saturates_at_the_envelopes_rate_over_its_gain():
    plane = adapter()
    assert saturating_error(plane) is None  # GUIDED_P not read yet: not linearised
    await plane.prepare()
    assert saturating_error(plane) == pytest.approx(0.2 / 1.0)
    # at that wanted error the bank asked for is the limit sent, at any speed and efficiency
    await flown_through(plane, turning(0.7, 30.0))
    saturating = saturating_error(plane)
    assert saturating is not None
    for speed in (10.0, 18.0):
        state = replace(STATE, course_rad=0.0, flying_speed_m_s=speed)
        sent = plane.linearised_course(saturating, state, speed)
        bank = math.radians(5000.0 / 100.0) * sent
        limit = math.atan(plane.lateral_accel_limit(speed, speed) / GRAVITY_M_S2)
        assert bank == pytest.approx(limit, rel=1e-9)


async def test_without_guided_p_no_saturating_error_is_claimed():
    params = ParamRecorder({k: v for k, v in STOCK_ARDUPLANE.items() if k != "GUIDED_P"})
    plane = ArduPlaneAdapter(
        vehicle_id=1,
        commands=CommandRecorder(),
        params=params,
        limits=LIMITS,
        telemetry_rates_hz=None,
        gcs_system_id=None,
    )
    await plane.prepare()
    assert plane.course_error_limit_rad is None
