"""What the adapters use of the real autopilots (issue 13): PX4's curvature feed-forward through
the offboard acceleration, which adapters fly the commanded speed, the telemetry rates asked
with SET_MESSAGE_INTERVAL, and the parameters changed before take-off and restored after."""

import json
import math
from dataclasses import replace

import pytest
from hypothesis import given
from hypothesis import strategies as st
from mavsdk.plugins.param import ParamResult
from pymavlink.dialects.v20 import common as mavlink

from app.adapters.vehicle.autopilots.arduplane import ArduPlaneAdapter
from app.adapters.vehicle.autopilots.base import VehicleState
from app.adapters.vehicle.autopilots.limits import SentSetpoint, SetpointLimits, limit_setpoint
from app.adapters.vehicle.autopilots.px4 import (
    PX4_TELEMETRY_RATES_HZ,
    Px4FixedWingAdapter,
    normal_acceleration_ned,
    px4_mission_rates,
)
from app.adapters.vehicle.autopilots.velocity import VelocityAdapter
from app.core.plant import VehicleEnvelope
from app.errors import LinkError
from app.runtime.ports.vehicle import CourseSpeedCommand
from tests.adapters.test_autopilots import (
    LIMITS,
    STOCK_ARDUPLANE,
    STOCK_PX4,
    CommandRecorder,
    NoSleep,
    OffboardRecorder,
    ParamRecorder,
)

MAX_RATE = LIMITS.envelope.max_course_rate_rad_s  # 0.2 rad/s
PX4_STATE = VehicleState(
    t_s=3.0, course_rad=0.0, relative_altitude_m=100.0, local_ned_m=(0.0, 0.0, -100.0)
)


def px4(**changes):
    offboard = OffboardRecorder()
    commands = changes.pop("commands", None) or CommandRecorder()
    params = changes.pop("params", None) or ParamRecorder(STOCK_PX4)
    adapter = Px4FixedWingAdapter(
        vehicle_id=3, offboard=offboard, commands=commands, params=params, limits=LIMITS, **changes
    )
    return adapter, offboard, commands, params


def arduplane(**changes):
    commands = changes.pop("commands", None) or CommandRecorder()
    params = changes.pop("params", None) or ParamRecorder(STOCK_ARDUPLANE)
    sleep = changes.pop("sleep", None) or NoSleep()
    adapter = ArduPlaneAdapter(
        vehicle_id=5, commands=commands, params=params, limits=LIMITS, sleep=sleep, **changes
    )
    return adapter, commands, params, sleep


# ---- the acceleration normal to the velocity ---------------------------------------------------


@pytest.mark.parametrize(
    ("course", "rate", "expected"),
    [
        (0.0, 0.1, (0.0, 1.5)),  # north, turning clockwise: to the east (right)
        (0.0, -0.1, (0.0, -1.5)),  # north, counter-clockwise: west (left)
        (math.pi / 2, 0.1, (-1.5, 0.0)),  # east, clockwise: south (right)
        (math.pi, 0.1, (0.0, -1.5)),  # south, clockwise: west
        (0.0, 0.0, (0.0, 0.0)),  # straight
    ],
)
def test_normal_acceleration_is_speed_times_course_rate_to_the_turns_side(course, rate, expected):
    north, east = normal_acceleration_ned(course, 15.0, rate, MAX_RATE)
    assert north == pytest.approx(expected[0], abs=1e-12)
    assert east == pytest.approx(expected[1], abs=1e-12)


def test_normal_acceleration_is_held_to_the_envelopes_turn_rate():
    north, east = normal_acceleration_ned(0.0, 15.0, 0.9, MAX_RATE)
    assert math.hypot(north, east) == pytest.approx(15.0 * MAX_RATE)  # 3 m/s^2, not 13.5
    north, east = normal_acceleration_ned(0.0, 15.0, -0.9, MAX_RATE)
    assert east == pytest.approx(-15.0 * MAX_RATE)


@given(
    course=st.floats(-10.0, 10.0),
    speed=st.floats(0.0, 40.0),
    rate=st.floats(-1e6, 1e6),
)
def test_normal_acceleration_is_finite_normal_and_within_the_envelope(course, speed, rate):
    north, east = normal_acceleration_ned(course, speed, rate, MAX_RATE)
    assert math.isfinite(north)
    assert math.isfinite(east)
    assert math.hypot(north, east) <= speed * MAX_RATE * (1 + 1e-9) + 1e-12
    # normal to the velocity (north, east) = speed (cos, sin)
    assert north * math.cos(course) + east * math.sin(course) == pytest.approx(0.0, abs=1e-9)


def px4_v1_16_curvature(velocity, acceleration, *, fixed=False):
    """The path curvature PX4's fixed-wing position controller feeds forward for an offboard
    position+velocity+acceleration setpoint (FixedwingPositionControl::Run, v1.16, and
    control_auto_path): NPFG's convention, positive clockwise. ``fixed``: the sign as PX4
    corrected it after v1.16 (PR #27582)."""
    vn, ve = velocity
    an, ae = acceleration
    speed = math.hypot(vn, ve)
    un, ue = vn / speed, ve / speed
    dot = an * un + ae * ue
    nn, ne = an - dot * un, ae - dot * ue
    norm = math.hypot(nn, ne)
    if norm == 0.0:
        return 0.0  # PX4: 0/0 -> NaN radius -> no curvature
    cross = un * (ne / norm) - ue * (nn / norm)  # matrix::Vector2f::cross
    direction = cross if fixed else -cross
    radius = direction * speed * speed / norm
    return 1.0 / radius


@pytest.mark.parametrize("rate", [0.15, -0.15, 0.05])
@pytest.mark.parametrize("course", [0.0, 1.0, -2.5])
async def test_px4_v1_16_is_fed_the_wanted_curvature_with_its_sign(course, rate):
    # the acceleration PX4 v1.16 receives makes it feed forward curvature = rate / v, clockwise
    # positive, as the command asks; sent unmirrored, v1.16 would turn the other way
    adapter, offboard, _, _ = px4()
    await adapter.send(CourseSpeedCommand(course, 15.0, course_rate_rad_s=rate), 100.0, PX4_STATE)
    _, _, velocity, acceleration = offboard.calls[0]
    v = (velocity.north_m_s, velocity.east_m_s)
    a = (acceleration.north_m_s2, acceleration.east_m_s2)
    assert acceleration.down_m_s2 == 0.0
    assert math.hypot(*a) == pytest.approx(15.0 * abs(rate))
    assert px4_v1_16_curvature(v, a) == pytest.approx(rate / 15.0)
    assert px4_v1_16_curvature(v, a, fixed=True) == pytest.approx(-rate / 15.0)


async def test_px4_with_the_sign_fixed_gets_the_acceleration_unmirrored():
    adapter, offboard, _, _ = px4(mirror_normal_accel=False)
    await adapter.send(CourseSpeedCommand(0.0, 15.0, course_rate_rad_s=0.1), 100.0, PX4_STATE)
    _, _, velocity, acceleration = offboard.calls[0]
    assert (acceleration.north_m_s2, acceleration.east_m_s2) == (
        pytest.approx(0.0, abs=1e-12),
        pytest.approx(1.5),  # to the right: a clockwise turn
    )
    v, a = (velocity.north_m_s, velocity.east_m_s), (0.0, 1.5)
    assert px4_v1_16_curvature(v, a, fixed=True) == pytest.approx(0.1 / 15.0)


async def test_px4_lays_the_line_along_the_wanted_course_not_the_led_command() -> None:
    """A course command leads the wanted course by rate / k for a first-order course loop;
    NPFG turns onto the line and feeds the curvature forward itself, so with the feed-forward
    the line (its point, velocity and yaw) and the acceleration follow the wanted course; a led
    line would make PX4 turn tighter than the circle. Without the feed-forward (or without a
    wanted course) the led command is the line."""
    led = CourseSpeedCommand(0.3, 15.0, course_rate_rad_s=-0.15, path_course_rad=0.45)
    adapter, offboard, _, _ = px4()
    await adapter.send(led, 100.0, PX4_STATE)
    _, position, velocity, acceleration = offboard.calls[0]
    assert PX4_STATE.local_ned_m is not None
    north0, east0, _ = PX4_STATE.local_ned_m
    assert math.atan2(position.east_m - east0, position.north_m - north0) == pytest.approx(0.45)
    assert math.atan2(velocity.east_m_s, velocity.north_m_s) == pytest.approx(0.45)
    assert velocity.yaw_deg == pytest.approx(math.degrees(0.45))
    # the acceleration is normal to the line's velocity
    dot = acceleration.north_m_s2 * velocity.north_m_s + acceleration.east_m_s2 * velocity.east_m_s
    assert dot == pytest.approx(0.0, abs=1e-9)
    plain, offboard, _, _ = px4(curvature_feed_forward=False)
    await plain.send(led, 100.0, PX4_STATE)
    _, _, velocity = offboard.calls[0]
    assert math.atan2(velocity.east_m_s, velocity.north_m_s) == pytest.approx(0.3)
    adapter, offboard, _, _ = px4()
    await adapter.send(CourseSpeedCommand(0.3, 15.0, course_rate_rad_s=-0.15), 100.0, PX4_STATE)
    _, _, velocity, _ = offboard.calls[0]
    assert math.atan2(velocity.east_m_s, velocity.north_m_s) == pytest.approx(0.3)


def test_a_limited_course_change_drops_the_wanted_course_too() -> None:
    previous = SentSetpoint(0.0, 0.0, 15.0)
    command = CourseSpeedCommand(1.0, 15.0, path_course_rad=1.1)
    limited, reasons = limit_setpoint(command, 1.0, previous, LIMITS)
    assert [r.kind for r in reasons] == ["course_rate"]
    assert limited.course_rad == pytest.approx(MAX_RATE)
    assert limited.path_course_rad is None  # the limited course is flown, not the path's
    small = CourseSpeedCommand(0.5 * MAX_RATE, 15.0, path_course_rad=0.07)
    kept, _ = limit_setpoint(small, 1.0, previous, LIMITS)
    assert kept.path_course_rad == 0.07


async def test_px4_acceleration_is_held_to_the_envelope():
    adapter, offboard, _, _ = px4()
    await adapter.send(CourseSpeedCommand(0.3, 16.0, course_rate_rad_s=-5.0), 100.0, PX4_STATE)
    _, _, _, acceleration = offboard.calls[0]
    assert math.hypot(acceleration.north_m_s2, acceleration.east_m_s2) == pytest.approx(
        16.0 * MAX_RATE
    )


async def test_px4_without_feed_forward_sends_position_and_velocity_only():
    adapter, offboard, _, _ = px4(curvature_feed_forward=False)
    await adapter.send(CourseSpeedCommand(0.0, 15.0, course_rate_rad_s=0.1), 100.0, PX4_STATE)
    assert offboard.calls[0][0] == "position+velocity"


def test_the_limiter_keeps_the_course_rate_and_holds_it_to_the_envelope():
    command = CourseSpeedCommand(0.5, 30.0, 80.0, course_rate_rad_s=0.1)
    out, why = limit_setpoint(command, 1.0, None, LIMITS)
    assert (out.speed_m_s, out.course_rate_rad_s, out.altitude_m) == (18.0, 0.1, 80.0)
    assert [r.kind for r in why] == ["speed_above_max"]
    fast = CourseSpeedCommand(0.5, 14.0, course_rate_rad_s=-0.35)
    out, why = limit_setpoint(fast, 1.0, None, LIMITS)
    assert out.course_rate_rad_s == pytest.approx(-MAX_RATE)
    assert [r.kind for r in why] == ["course_rate_feed_forward"]
    # the mission files turn the course-change limit off; the feed-forward is held all the same
    free = SetpointLimits(LIMITS.envelope, limit_course_change=False)
    out, _ = limit_setpoint(fast, 1.0, None, free)
    assert out.course_rate_rad_s == pytest.approx(-MAX_RATE)


# ---- which adapters fly the commanded speed ----------------------------------------------------


@pytest.mark.parametrize(
    ("build", "honours"),
    [
        (lambda: VelocityAdapter(vehicle_id=1, offboard=OffboardRecorder(), limits=LIMITS), True),
        (lambda: px4()[0], False),
        (lambda: px4(airspeed_via_trim_param=True)[0], True),
        (lambda: arduplane()[0], True),
    ],
    ids=["velocity", "px4", "px4-trim-param", "arduplane"],
)
def test_honours_speed_says_whether_the_speed_is_flown(build, honours):
    assert build().honours_speed is honours


async def test_px4_trim_airspeed_writes_are_rate_limited_and_restored():
    params = ParamRecorder(STOCK_PX4 | {"FW_AIRSPD_TRIM": 15.0, "COM_OBL_RC_ACT": 5})
    adapter, _, _, _ = px4(
        airspeed_via_trim_param=True, params=params, trim_min_interval_s=5.0, trim_deadband_m_s=0.5
    )
    await adapter.prepare()
    for t_s, speed in [(10.0, 16.0), (11.0, 17.0), (15.5, 17.0), (16.0, 17.2), (30.0, 14.0)]:
        state = replace(PX4_STATE, t_s=t_s)
        await adapter.send(CourseSpeedCommand(0.0, speed), 100.0, state)
    # 16 at t=10; 17 waits for t >= 15 (5 s of vehicle time); 17.2 is within the deadband
    assert [s for s in params.sets if s[0] == "FW_AIRSPD_TRIM"] == [
        ("FW_AIRSPD_TRIM", 16.0),
        ("FW_AIRSPD_TRIM", 17.0),
        ("FW_AIRSPD_TRIM", 14.0),
    ]
    params.sets.clear()
    await adapter.restore_params()
    assert params.sets == [("FW_AIRSPD_TRIM", 15.0)]
    assert isinstance(params.sets[0][1], float)


def test_trim_airspeed_intervals_must_be_sensible():
    with pytest.raises(ValueError, match="trim_min_interval_s must be finite and >= 0"):
        px4(trim_min_interval_s=math.nan)


# ---- telemetry rates ---------------------------------------------------------------------------


def intervals(commands: CommandRecorder) -> list[tuple[int, float, float]]:
    return [
        (int(f["param1"]), f["param2"], f["param3"])
        for *_, f in commands.sent
        if f["command"] == 511
    ]


async def test_arduplane_asks_for_the_messages_the_mission_needs_at_10_hz():
    adapter, commands, _, _ = arduplane()
    await adapter.prepare()
    # GLOBAL_POSITION_INT (33), ATTITUDE (30), VFR_HUD (74) every 100 ms, to this link (param3 0)
    assert intervals(commands) == [(33, 100000.0, 0.0), (30, 100000.0, 0.0), (74, 100000.0, 0.0)]
    assert all(sent[:3] == ("COMMAND_LONG", 5, 1) for sent in commands.sent)
    assert 0 not in [p1 for p1, _, _ in intervals(commands)]  # HEARTBEAT stays at 1 Hz


async def test_arduplane_telemetry_rates_are_configurable_or_off():
    adapter, commands, _, _ = arduplane(telemetry_rates_hz={"GLOBAL_POSITION_INT": 4.0})
    await adapter.prepare()
    assert intervals(commands) == [(33, 250000.0, 0.0)]
    adapter, commands, _, _ = arduplane(telemetry_rates_hz=None)
    await adapter.prepare()
    assert intervals(commands) == []


async def test_a_refused_telemetry_rate_is_logged_and_the_vehicle_still_prepared(caplog):
    adapter, commands, params, _ = arduplane(commands=CommandRecorder(result=2))  # DENIED
    with caplog.at_level("WARNING"):
        await adapter.prepare()
    assert len(intervals(commands)) == 3
    assert "SET_MESSAGE_INTERVAL not accepted" in caplog.text
    assert "MAV_RESULT_DENIED" in caplog.text
    assert ("FS_GCS_ENABL", 1) in params.sets


@pytest.mark.parametrize(
    ("rates", "message"),
    [
        ({"GLOBAL_POSITION_INT": 0.0}, "must be finite and > 0 Hz"),
        ({"GLOBAL_POSITION_INT": math.inf}, "must be finite and > 0 Hz"),
        ({"NO_SUCH_MESSAGE": 10.0}, "unknown MAVLink message 'NO_SUCH_MESSAGE'"),
    ],
)
def test_bad_telemetry_rates_are_refused_on_construction(rates, message):
    with pytest.raises(ValueError, match=message):
        arduplane(telemetry_rates_hz=rates)
    with pytest.raises(ValueError, match=message):
        px4(telemetry_rates_hz=rates)


async def test_px4_asks_for_no_rates_unless_told_and_for_position_when_told():
    adapter, _, commands, _ = px4()
    await adapter.prepare()
    assert intervals(commands) == []  # SITL's onboard link streams 50 Hz already
    adapter, _, commands, _ = px4(telemetry_rates_hz=PX4_TELEMETRY_RATES_HZ)
    await adapter.prepare()
    assert intervals(commands) == [(33, 100000.0, 0.0), (32, 100000.0, 0.0)]


class RefusingCommands(CommandRecorder):
    """Acks every command, but refuses SET_MESSAGE_INTERVAL for one message id."""

    def __init__(self, refused_id: int) -> None:
        super().__init__()
        self.refused_id = refused_id

    async def send_command(self, command):
        fields = json.loads(command.fields_json)
        ack = await super().send_command(command)
        if fields["command"] == 511 and int(fields["param1"]) == self.refused_id:
            refused = {"command": 511, "result": mavlink.MAV_RESULT_FAILED}
            return type(ack)(message_name="COMMAND_ACK", fields_json=json.dumps(refused))
        return ack


async def test_px4_mission_rates_slow_what_is_read_and_what_is_not_and_are_put_back():
    rates = px4_mission_rates(10.0)
    assert rates == {
        "GLOBAL_POSITION_INT": 10.0,
        "LOCAL_POSITION_NED": 10.0,
        "ATTITUDE": 10.0,
        "HIGHRES_IMU": 1.0,
        "ATTITUDE_QUATERNION": 1.0,
        "ODOMETRY": 1.0,
        "RC_CHANNELS": 1.0,
    }
    odometry = mavlink.MAVLINK_MSG_ID_ODOMETRY
    commands = RefusingCommands(odometry)
    adapter, _, _, _ = px4(telemetry_rates_hz=rates, commands=commands)
    await adapter.prepare()
    asked = intervals(commands)
    assert asked[:3] == [(33, 100000.0, 0.0), (32, 100000.0, 0.0), (30, 100000.0, 0.0)]
    assert [a[1] for a in asked[3:]] == [1e6] * 4
    commands.sent.clear()
    await adapter.restore_params()
    # every accepted one back at PX4's own rate (interval 0); the refused one was never moved
    put_back = intervals(commands)
    assert {a[0] for a in put_back} == {33, 32, 30, 105, 31, 65}
    assert all(a[1] == 0.0 for a in put_back)
    commands.sent.clear()
    await adapter.restore_params()
    assert intervals(commands) == []  # once
    with pytest.raises(ValueError, match="telemetry rate"):
        px4_mission_rates(0.0)


# ---- the GCS failsafe: id first, our heartbeat counted, then the failsafe ----------------------


class Timeline:
    """Parameter writes and waits, in the order the adapter makes them."""

    def __init__(self) -> None:
        self.events: list[tuple[str, object]] = []


class TimelineParams(ParamRecorder):
    def __init__(self, values, timeline: Timeline, **kwargs) -> None:
        super().__init__(values, **kwargs)
        self.timeline = timeline

    async def set_param_int(self, name: str, value: int) -> None:
        self.timeline.events.append((name, value))
        await super().set_param_int(name, value)


class TimelineSleep(NoSleep):
    def __init__(self, timeline: Timeline) -> None:
        super().__init__()
        self.timeline = timeline

    async def __call__(self, seconds: float) -> None:
        self.timeline.events.append(("wait", seconds))
        await super().__call__(seconds)


async def test_the_failsafe_is_enabled_only_after_a_wait_for_our_heartbeat():
    timeline = Timeline()
    adapter, _, _, _ = arduplane(
        params=TimelineParams(STOCK_ARDUPLANE, timeline), sleep=TimelineSleep(timeline)
    )
    await adapter.prepare()
    assert timeline.events == [
        ("SYSID_MYGCS", 245),
        ("FS_LONG_ACTN", 1),
        ("wait", 2.5),  # > 1.5 periods of MAVSDK's 1 Hz heartbeat
        ("FS_GCS_ENABL", 1),
    ]


async def test_no_wait_when_the_failsafe_is_already_on():
    sleep = NoSleep()
    params = ParamRecorder(STOCK_ARDUPLANE | {"FS_GCS_ENABL": 1})
    adapter, _, _, _ = arduplane(params=params, sleep=sleep)
    await adapter.prepare()
    assert sleep.waits == []
    assert params.sets == [("SYSID_MYGCS", 245), ("FS_LONG_ACTN", 1)]


class ArduPlaneGcsFailsafe(ParamRecorder):
    """ArduPlane's GCS failsafe as its source has it (system.cpp ``check_long_failsafe``,
    GCS_Common.cpp ``handle_heartbeat``): the last heartbeat from SYSID_MYGCS is set at boot
    and by every HEARTBEAT from that id; with FS_GCS_ENABL 1 or 2 the failsafe fires when it is
    more than FS_LONG_TIMEOUT (5 s) old. MAVSDK (system 245) sends HEARTBEAT at 1 Hz from
    ``first_beat_s``; each parameter write takes ``write_s``; ``sleep`` advances the clock."""

    def __init__(self, values, now_s: float, first_beat_s: float, write_s: float = 0.1) -> None:
        super().__init__(values)
        self.now_s = now_s
        self.last_seen_s = 0.0  # boot
        self.next_beat_s = first_beat_s
        self.write_s = write_s
        self.fired_at: float | None = None

    def advance(self, seconds: float) -> None:
        end = self.now_s + seconds
        while self.next_beat_s <= end:
            self.check(self.next_beat_s)
            if self.values.get("SYSID_MYGCS") == 245:
                self.last_seen_s = self.next_beat_s
            self.next_beat_s += 1.0
        self.now_s = end
        self.check(end)

    def check(self, t_s: float) -> None:
        enabled = self.values.get("FS_GCS_ENABL") in (1, 2)
        if enabled and t_s - self.last_seen_s > 5.0 and self.fired_at is None:
            self.fired_at = t_s

    async def set_param_int(self, name: str, value: int) -> None:
        await super().set_param_int(name, value)
        self.advance(self.write_s)

    async def sleep(self, seconds: float) -> None:
        self.advance(seconds)


@pytest.mark.parametrize("first_beat_s", [60.25, 60.5, 60.95])
async def test_the_real_failsafe_does_not_fire_with_the_wait_and_does_without(first_beat_s):
    # a vehicle booted 60 s ago, no GCS at 255 (so the last heartbeat it counted is the boot);
    # the three writes take 0.3 s. Without the wait the failsafe fires the moment FS_GCS_ENABL
    # is on, unless one of MAVSDK's heartbeats happens to fall between the id's write and it
    # (these phases: none does); with the wait it never fires, whatever the phase
    racing = ArduPlaneGcsFailsafe(STOCK_ARDUPLANE, now_s=60.0, first_beat_s=first_beat_s)
    adapter, _, _, _ = arduplane(params=racing, gcs_heartbeat_wait_s=0.0)
    adapter.sleep = racing.sleep
    await adapter.prepare()
    assert racing.fired_at is not None

    vehicle = ArduPlaneGcsFailsafe(STOCK_ARDUPLANE, now_s=60.0, first_beat_s=first_beat_s)
    adapter, _, _, _ = arduplane(params=vehicle)
    adapter.sleep = vehicle.sleep
    await adapter.prepare()
    vehicle.advance(30.0)  # and it keeps hearing us
    assert vehicle.values["FS_GCS_ENABL"] == 1
    assert vehicle.fired_at is None


@pytest.mark.parametrize("phase_s", [i / 20 for i in range(20)])
async def test_with_the_wait_no_heartbeat_phase_fires_the_failsafe(phase_s):
    vehicle = ArduPlaneGcsFailsafe(STOCK_ARDUPLANE, now_s=60.0, first_beat_s=60.0 + phase_s)
    adapter, _, _, _ = arduplane(params=vehicle)
    adapter.sleep = vehicle.sleep
    await adapter.prepare()
    vehicle.advance(10.0)
    assert vehicle.fired_at is None


def test_the_heartbeat_wait_must_be_sensible():
    with pytest.raises(ValueError, match="gcs_heartbeat_wait_s must be finite and >= 0"):
        arduplane(gcs_heartbeat_wait_s=-1.0)


async def test_arduplane_warns_when_other_ground_stations_will_be_ignored(caplog):
    params = ParamRecorder(STOCK_ARDUPLANE | {"SYSID_ENFORCE": 1})
    adapter, _, _, _ = arduplane(params=params)
    with caplog.at_level("WARNING"):
        await adapter.prepare()
    assert "SYSID_ENFORCE is 1" in caplog.text
    assert "a QGroundControl at 255" in caplog.text


# ---- restoring what was changed ----------------------------------------------------------------


async def test_arduplane_restores_its_originals_failsafe_first_id_last():
    timeline = Timeline()
    params = TimelineParams(STOCK_ARDUPLANE, timeline)
    adapter, _, _, _ = arduplane(params=params)
    await adapter.prepare()
    timeline.events.clear()
    await adapter.restore_params()
    assert timeline.events == [("FS_GCS_ENABL", 0), ("FS_LONG_ACTN", 0), ("SYSID_MYGCS", 255)]
    assert params.values == STOCK_ARDUPLANE
    timeline.events.clear()
    await adapter.restore_params()  # nothing left to restore
    assert timeline.events == []


async def test_arduplane_restore_leaves_the_operators_own_settings_alone():
    values: dict[str, int | float] = {"SYSID_MYGCS": 245, "FS_GCS_ENABL": 2, "FS_LONG_ACTN": 2}
    params = ParamRecorder(values | {"AIRSPEED_MIN": 9, "AIRSPEED_MAX": 22})
    adapter, _, _, _ = arduplane(params=params)
    await adapter.prepare()
    await adapter.restore_params()
    assert params.sets == []


async def test_restore_logs_a_failed_write_and_goes_on(caplog):
    params = ParamRecorder(STOCK_ARDUPLANE)
    adapter, _, _, _ = arduplane(params=params)
    await adapter.prepare()
    params.sets.clear()
    params.refuse = {"FS_LONG_ACTN": ParamResult.TIMEOUT}
    with caplog.at_level("ERROR"):
        await adapter.restore_params()  # does not raise
    assert params.sets == [("FS_GCS_ENABL", 0), ("FS_LONG_ACTN", 0), ("SYSID_MYGCS", 255)]
    assert "could not restore FS_LONG_ACTN to 0" in caplog.text
    # what failed is tried again on the next call, what succeeded is not
    params.sets.clear()
    params.refuse = {}
    await adapter.restore_params()
    assert params.sets == [("FS_LONG_ACTN", 0)]


async def test_restore_swallows_any_error_of_the_transport(caplog):
    class Broken(ParamRecorder):
        async def set_param_int(self, name: str, value: int) -> None:
            if value in (0, 255):  # the restoring writes
                raise LinkError("link closed")
            await super().set_param_int(name, value)

    params = Broken(STOCK_ARDUPLANE)
    adapter, _, _, _ = arduplane(params=params)
    await adapter.prepare()
    with caplog.at_level("ERROR"):
        await adapter.restore_params()
    assert caplog.text.count("could not restore") == 3


async def test_px4_restores_the_offboard_loss_action():
    adapter, _, _, params = px4()
    await adapter.prepare()
    assert params.values["COM_OBL_RC_ACT"] == 5
    await adapter.restore_params()
    assert params.sets == [("COM_OBL_RC_ACT", 5), ("COM_OBL_RC_ACT", 0)]
    assert params.values["COM_OBL_RC_ACT"] == 0


async def test_px4_with_a_correct_offboard_loss_action_restores_nothing():
    adapter, _, _, params = px4(params=ParamRecorder(STOCK_PX4 | {"COM_OBL_RC_ACT": 5}))
    await adapter.prepare()
    await adapter.restore_params()
    assert params.sets == []


async def test_velocity_adapter_has_nothing_to_restore():
    adapter = VelocityAdapter(vehicle_id=1, offboard=OffboardRecorder(), limits=LIMITS)
    await adapter.restore_params()


def test_envelope_used_is_the_vehicles():
    # the heading's and the acceleration's limit both come from the envelope's course rate
    slow = SetpointLimits(VehicleEnvelope(14.0, 10.0, 18.0, 2.0, 0.1))
    adapter = ArduPlaneAdapter(
        vehicle_id=5, commands=CommandRecorder(), params=ParamRecorder({}), limits=slow
    )
    assert adapter.heading_command(0.0, 15.0).fields_json.count('"param3": 1.5') == 1


async def test_px4_take_off_names_the_altitude_so_mis_takeoff_alt_is_not_flown():
    adapter, _, commands, params = px4()
    await adapter.take_off(47.3977, 8.5456, 488.0 + 135.0)
    [(name, system, component, fields)] = commands.sent
    assert (name, system, component) == ("COMMAND_LONG", 3, 1)
    assert fields["command"] == mavlink.MAV_CMD_NAV_TAKEOFF
    # param7 is the AMSL altitude PX4's navigator climbs to; param5/6 the take-off point
    assert fields["param7"] == pytest.approx(623.0)
    assert (fields["param5"], fields["param6"]) == pytest.approx((47.3977, 8.5456))
    assert params.sets == []


async def test_px4_take_off_refused_is_a_link_error():
    adapter, _, commands, _ = px4()
    commands.result = mavlink.MAV_RESULT_DENIED
    with pytest.raises(LinkError, match="NAV_TAKEOFF"):
        await adapter.take_off(47.3977, 8.5456, 600.0)
