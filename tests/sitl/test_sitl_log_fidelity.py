"""What the built-in simulator sends that a flight log shows (no sockets): each personality's
heartbeat read by pymavlink as that autopilot's modes, arming and take-off STATUSTEXTs, a
throttle and climb that follow the flight, airspeed apart from ground speed in the wind, the bank
in ATTITUDE, and the camera's component id from the config."""

import math
from dataclasses import replace

import numpy as np
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from app.compose.parts import link_config
from app.config import load_config
from app.config.loading import validate_config
from app.config.mission import MissionConfig
from app.config.plan import build_plan, sim_config
from sitl.camera import Observation, TrackingCamera
from sitl.config import SimConfig, default_vehicles
from sitl.geodesy import Geodesy
from sitl.server import autopilot_for
from sitl.vehicle import SimVehicle

ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
SET_MODE = mavlink.MAV_CMD_DO_SET_MODE
GEO = (47.397742, 8.545594, 588.0)


def vehicle(autopilot: str = "px4", **overrides: object) -> SimVehicle:
    sim = SimConfig(vehicles=default_vehicles(1), autopilot=autopilot, takeoff="launch")  # type: ignore[arg-type]
    sim = replace(sim, **overrides)  # type: ignore[arg-type]
    camera = TrackingCamera(sim.camera, np.random.default_rng(0))
    geodesy = Geodesy(sim.origin_lat_deg, sim.origin_lon_deg, sim.origin_alt_m)
    return SimVehicle(0, sim.vehicles[0], sim, camera, geodesy, autopilot_for(sim.vehicles[0], sim))


def command(v: SimVehicle, cmd: int, *params: float) -> list[mavlink.MAVLink_message]:
    p = [*params, *([0.0] * (7 - len(params)))]
    msg = mavlink.MAVLink_command_long_message(1, 1, cmd, 0, *p)
    data = msg.pack(mavlink.MAVLink(None, 245, 190))
    (wired,) = mavlink.MAVLink(None, 1, 1).parse_buffer(data) or []
    return [m for _, m in v.handle(wired, 0.0, 0.0)]


def texts(out: list[mavlink.MAVLink_message]) -> list[str]:
    return [m.text for m in out if m.get_type() == "STATUSTEXT"]


def due(v: SimVehicle, t_s: float) -> dict[str, mavlink.MAVLink_message]:
    """The streams due at ``t_s`` (each is sent once: ask once per instant)."""
    return {m.get_type(): m for _, m in v.telemetry(t_s, lambda: GEO)}


def streamed(v: SimVehicle, t_s: float, kind: str) -> mavlink.MAVLink_message:
    return due(v, t_s)[kind]


def fly_for(v: SimVehicle, seconds: float, t0: float = 0.0, wind_east_m_s: float = 0.0) -> float:
    t, dt = t0, 0.02
    while t < t0 + seconds:
        t += dt
        v.advance(dt, t, t, wind_east_m_s, 0.0)
    return t


def test_px4_heartbeat_reads_as_px4_modes_and_arming_is_in_the_log():
    v = vehicle("px4")
    out = command(v, ARM, 1.0)
    assert texts(out) == ["Armed by external command"]
    assert texts(command(v, ARM, 1.0)) == []  # already armed
    hb = streamed(v, 1.0, "HEARTBEAT")
    assert (hb.autopilot, hb.type) == (mavlink.MAV_AUTOPILOT_PX4, mavlink.MAV_TYPE_FIXED_WING)
    assert mavutil.mode_string_v10(hb) == "LOITER"  # PX4's hold
    out = command(v, mavlink.MAV_CMD_NAV_TAKEOFF)
    assert mavutil.mode_string_v10(streamed(v, 2.0, "HEARTBEAT")) == "TAKEOFF"
    events = [m for _, m in v.advance(0.02, 2.02, 2.02, 0.0, 0.0)]
    assert "Takeoff detected" in texts(events)


def test_arduplane_heartbeat_reads_as_arduplane_modes_and_arming_is_in_the_log():
    v = vehicle("arduplane")
    hb = streamed(v, 1.0, "HEARTBEAT")
    assert hb.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert mavutil.mode_string_v10(hb) == "MANUAL"
    assert texts(command(v, ARM, 1.0)) == ["Throttle armed"]
    assert texts(command(v, ARM, 1.0)) == []  # already armed: nothing to say
    command(v, SET_MODE, 1, 13)  # TAKEOFF (launches)
    command(v, SET_MODE, 1, 15)
    assert mavutil.mode_string_v10(streamed(v, 2.0, "HEARTBEAT")) == "GUIDED"
    v.disarm()
    v.armed = True
    assert texts(command(v, ARM, 0.0)) == ["Throttle disarmed"]


def test_throttle_and_climb_follow_the_flight_and_airspeed_is_apart_from_ground_speed():
    v = vehicle("px4")
    assert streamed(v, 0.5, "VFR_HUD").throttle == 0  # on the ground
    command(v, ARM, 1.0)  # launches (takeoff = "launch")
    v.air_altitude_m = 0.0  # climbing from the launch to its altitude
    t = fly_for(v, 1.0, 1.0, wind_east_m_s=5.0)
    now = due(v, t)
    climbing = now["VFR_HUD"]
    assert climbing.climb > 1.0
    assert climbing.throttle > 80
    assert now["GLOBAL_POSITION_INT"].vz < -100  # cm/s, down > 0
    t = fly_for(v, 60.0, t, wind_east_m_s=5.0)
    now = due(v, t)
    level = now["VFR_HUD"]
    assert abs(level.climb) < 0.01
    assert 30 <= level.throttle <= 90
    assert level.throttle != climbing.throttle
    assert abs(level.airspeed - level.groundspeed) > 0.5  # 5 m/s of wind
    attitude = now["ATTITUDE"]
    # holding: it loiters, banked as a coordinated turn at its speed and course rate
    expected = math.atan(v.state.speed_m_s * v.state.course_rate_rad_s / 9.80665)
    assert attitude.roll == np.float32(expected)
    assert abs(attitude.roll) > math.radians(5.0)


def test_the_cameras_component_id_is_the_mission_files():
    raw = load_config("test-short", MissionConfig).model_dump()
    raw["link"]["camera_component_id"] = 154
    plan = build_plan(validate_config(raw, MissionConfig, "test"))
    assert sim_config(plan, 20000).camera_component_id == 154
    assert link_config(plan, builtin=True).camera_component_id == 154
    v = vehicle("px4", camera_component_id=154)
    component, msg = v.tracking_message(
        Observation(1.0, 2.0, 3.0, 1.0, 50.0, False, 2.0, 3.0), *GEO
    )
    assert (component, msg.get_type()) == (154, "CAMERA_TRACKING_GEO_STATUS")
