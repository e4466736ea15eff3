"""The speed-lag fit and the ArduPlane adapter's speed command led through it."""

import math
from dataclasses import replace

import pytest

from app.adapters.vehicle.autopilots.arduplane import ArduPlaneAdapter
from app.adapters.vehicle.autopilots.speed_lag import SpeedLag, SpeedLagParams
from app.runtime.ports.vehicle import CourseSpeedCommand
from tests.adapters.test_autopilots import (
    LIMITS,
    STATE,
    STOCK_ARDUPLANE,
    CommandRecorder,
    ParamRecorder,
)


def lagged(tau_s: float, seconds: float, rate_hz: float = 10.0, v0: float = 14.0):
    """Frames (t, airspeed, command) of an airspeed following a command stepping between 10
    and 18 m/s every 15 s through a first-order lag ``tau_s``."""
    frames, v, dt = [], v0, 1.0 / rate_hz
    for k in range(round(seconds * rate_hz)):
        t = k * dt
        command = (10.0, 18.0, 12.0, 16.0)[int(t // 15.0) % 4]
        frames.append((t, v, command))
        v += (command - v) * -math.expm1(-dt / tau_s)
    return frames


def fit(frames, params: SpeedLagParams | None = None) -> SpeedLag:
    lag = SpeedLag(params or SpeedLagParams())
    for frame in frames:
        lag = lag.update(*frame)
    return lag


@pytest.mark.parametrize("tau", [1.0, 4.0, 8.0])
def test_the_fit_finds_the_time_constant(tau):
    lag = fit(lagged(tau, 240.0))
    assert lag.ready
    # the error's mean over a 1 s interval against the change over it: within 10 %
    assert lag.tau_s == pytest.approx(tau, rel=0.1)


def test_not_ready_before_enough_active_time_and_steady_flight_teaches_nothing():
    assert fit(lagged(4.0, 10.0)).tau_s is None
    steady = fit([(0.1 * k, 14.0, 14.0) for k in range(3000)])
    assert (steady.samples, steady.ready) == (0, False)


def test_the_lead_closes_on_the_wanted_speed_at_the_target_time_constant():
    lag = fit(lagged(4.0, 240.0))
    tau = lag.tau_s
    assert tau is not None
    # through the airframe's own lag the led command closes as if with target_tau_s = 2 s
    lead = lag.lead(16.0, 12.0)
    assert lead == pytest.approx(12.0 + (tau / 2.0) * 4.0)
    assert (lead - 12.0) / tau == pytest.approx(4.0 / 2.0)
    # a fast airframe is not slowed down; a very slow one is led at most 3 times
    assert fit(lagged(1.0, 240.0)).lead(16.0, 12.0) == pytest.approx(16.0, rel=0.05)
    assert fit(lagged(14.0, 400.0)).lead(16.0, 12.0) == pytest.approx(12.0 + 3.0 * 4.0)
    # unknown airspeed: the wanted speed
    assert lag.lead(16.0, None) == 16.0


def test_bad_frames_restart_the_interval_and_spoil_nothing():
    frames = lagged(4.0, 240.0)
    spoiled = [
        (t, math.nan if k % 53 == 0 else (None if k % 71 == 0 else v), c)
        for k, (t, v, c) in enumerate(frames)
    ]
    spoiled.insert(500, (spoiled[499][0] - 3.0, 30.0, 10.0))
    lag = fit(spoiled)
    assert lag.tau_s == pytest.approx(4.0, rel=0.1)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"period_s": 0.0}, "period_s"),
        ({"period_s": 2.0, "max_period_s": 1.0}, "max_period_s"),
        ({"min_tau_s": 5.0, "max_tau_s": 2.0}, "max_tau_s"),
        ({"max_gain": 0.5}, "max_gain"),
        ({"target_tau_s": math.inf}, "target_tau_s"),
    ],
)
def test_bad_params_are_refused(changes, message):
    with pytest.raises(ValueError, match=message):
        SpeedLagParams(**changes)


# ---- the ArduPlane adapter -------------------------------------------------------------------


def adapter(commands: CommandRecorder, **changes) -> ArduPlaneAdapter:
    return ArduPlaneAdapter(
        vehicle_id=1,
        commands=commands,
        params=ParamRecorder(dict(STOCK_ARDUPLANE)),
        limits=LIMITS,
        telemetry_rates_hz=None,
        gcs_system_id=None,
        **changes,
    )


async def fly_lagged(plane: ArduPlaneAdapter, commands: CommandRecorder, tau_s: float) -> None:
    """Fly the adapter against a first-order airspeed: each frame's airspeed follows the
    last GUIDED_CHANGE_SPEED sent."""
    v, dt, sent = 14.0, 0.1, 14.0
    for k in range(2400):
        t = k * dt
        wanted = (10.0, 18.0, 12.0, 16.0)[int(t // 15.0) % 4]
        state = replace(STATE, t_s=t, flying_speed_m_s=v)
        await plane.send(CourseSpeedCommand(0.0, wanted), 100.0, state)
        speeds = [f["param2"] for *_, f in commands.sent if f["command"] == 43000]
        sent = speeds[-1] if speeds else sent
        v += (sent - v) * -math.expm1(-dt / tau_s)


async def test_the_adapter_leads_its_speed_command_within_the_envelope():
    commands = CommandRecorder()
    plane = adapter(commands, learn_speed_lag=True)
    await plane.prepare()
    await fly_lagged(plane, commands, 5.0)
    tau = plane.speed_lag_s
    assert tau == pytest.approx(5.0, rel=0.15)
    speeds = [f["param2"] for *_, f in commands.sent if f["command"] == 43000]
    assert min(speeds) >= 10.0
    assert max(speeds) <= 18.0
    # led: a step from 18 down to 12 asks for the floor first, not 12
    assert 10.0 in speeds
    # and goes out unslewed (param3 0: ArduPlane takes it at once)
    assert {f["param3"] for *_, f in commands.sent if f["command"] == 43000} == {0.0}


async def test_by_default_the_speed_goes_out_as_wanted():
    commands = CommandRecorder()
    plane = adapter(commands)
    await plane.prepare()
    await fly_lagged(plane, commands, 5.0)
    assert plane.speed_lag_s is None
    speeds = {f["param2"] for *_, f in commands.sent if f["command"] == 43000}
    assert speeds == {10.0, 18.0, 12.0, 16.0}
    # and ArduPlane slews its target at the envelope's acceleration (2 m/s^2)
    assert {f["param3"] for *_, f in commands.sent if f["command"] == 43000} == {2.0}
