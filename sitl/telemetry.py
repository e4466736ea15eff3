"""The MAVLink messages a simulated PX4 fixed-wing sends, built from its state (pure functions).

Every time field is simulated time: ``time_boot_ms`` is milliseconds since the simulation
started. Attitude follows the motion of eq. (2): yaw is the heading (the course through the
air), roll the coordinated-turn bank atan(V * course rate / g), pitch 0.
"""

import math
from typing import Final

from pymavlink.dialects.v20 import ardupilotmega
from pymavlink.dialects.v20 import common as mavlink

from app.core.frames import wrap_pi
from app.core.plant import FixedWingState
from sitl.camera import Observation

GRAVITY_M_S2: Final = 9.80665

SENSORS: Final = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_DIFFERENTIAL_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | mavlink.MAV_SYS_STATUS_AHRS
    | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
    | mavlink.MAV_SYS_STATUS_PREARM_CHECK
)
CAPABILITIES: Final = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
)
PX4_VERSION: Final = (1 << 24) | (16 << 16) | (0 << 8) | 255  # reports itself as PX4 v1.16.0


def boot_ms(t_s: float) -> int:
    return round(t_s * 1000.0) & 0xFFFFFFFF


def roll_rad(state: FixedWingState, turn_efficiency: float = 1.0) -> float:
    """The bank of a turn at the state's speed and course rate (right turn > 0), for an
    airframe that turns at ``turn_efficiency`` of the coordinated rate g tan(bank) / V."""
    return math.atan(state.speed_m_s * state.course_rate_rad_s / (turn_efficiency * GRAVITY_M_S2))


def heading_rad(state: FixedWingState) -> float:
    """The heading in [0, 2 pi)."""
    return state.course_rad % (2.0 * math.pi)


def heartbeat(custom_mode: int, armed: bool) -> mavlink.MAVLink_message:
    base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if armed:
        base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    status = mavlink.MAV_STATE_ACTIVE if armed else mavlink.MAV_STATE_STANDBY
    return mavlink.MAVLink_heartbeat_message(
        mavlink.MAV_TYPE_FIXED_WING, mavlink.MAV_AUTOPILOT_PX4, base, custom_mode, status, 3
    )


def autopilot_version(system_id: int) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_autopilot_version_message(
        CAPABILITIES,
        PX4_VERSION,
        0,
        0,
        0,
        [0] * 8,
        [0] * 8,
        [0] * 8,
        0,
        0,
        0x5354_4F00_0000_0000 + system_id,
    )


def home_position(
    lat_deg: float, lon_deg: float, alt_m: float, east_m: float, north_m: float, t_s: float
) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_home_position_message(
        round(lat_deg * 1e7),
        round(lon_deg * 1e7),
        round(alt_m * 1000.0),
        north_m,
        east_m,
        0.0,
        [1.0, 0.0, 0.0, 0.0],
        0.0,
        0.0,
        0.0,
        round(t_s * 1e6),
    )


def extended_sys_state(in_air: bool) -> mavlink.MAVLink_message:
    landed = mavlink.MAV_LANDED_STATE_IN_AIR if in_air else mavlink.MAV_LANDED_STATE_ON_GROUND
    return mavlink.MAVLink_extended_sys_state_message(mavlink.MAV_VTOL_STATE_UNDEFINED, landed)


def _voltage_mv(battery_fraction: float) -> int:
    return round(1000.0 * (14.0 + 2.8 * battery_fraction))  # a 4S pack, 16.8 V full


def sys_status(battery_fraction: float) -> mavlink.MAVLink_message:
    """Every sensor present, enabled and healthy, pre-arm checks passed."""
    return mavlink.MAVLink_sys_status_message(
        SENSORS, SENSORS, SENSORS, 100, _voltage_mv(battery_fraction), 500,
        round(100 * battery_fraction), 0, 0, 0, 0, 0, 0,
    )  # fmt: skip


def battery_status(battery_fraction: float) -> mavlink.MAVLink_message:
    cells = [65535] * 10
    cells[0] = _voltage_mv(battery_fraction)
    return mavlink.MAVLink_battery_status_message(
        0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, 2500, cells, 500,
        -1, -1, round(100 * battery_fraction),
    )  # fmt: skip


def attitude(
    state: FixedWingState, t_s: float, turn_efficiency: float = 1.0
) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_attitude_message(
        boot_ms(t_s), roll_rad(state, turn_efficiency), 0.0, wrap_pi(state.course_rad), 0.0, 0.0,
        state.course_rate_rad_s,
    )  # fmt: skip


def attitude_quaternion(
    state: FixedWingState, t_s: float, turn_efficiency: float = 1.0
) -> mavlink.MAVLink_message:
    """Yaw then roll (pitch 0): q = q_yaw * q_roll, scalar first."""
    half_roll = 0.5 * roll_rad(state, turn_efficiency)
    half_yaw = 0.5 * heading_rad(state)
    cr, sr = math.cos(half_roll), math.sin(half_roll)
    cy, sy = math.cos(half_yaw), math.sin(half_yaw)
    return mavlink.MAVLink_attitude_quaternion_message(
        boot_ms(t_s), cy * cr, cy * sr, sy * sr, sy * cr, 0.0, 0.0, state.course_rate_rad_s
    )


def local_position_ned(
    state: FixedWingState,
    altitude_m: float,
    v_north_m_s: float,
    v_east_m_s: float,
    t_s: float,
    climb_m_s: float = 0.0,
) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_local_position_ned_message(
        boot_ms(t_s), state.north_m, state.east_m, -altitude_m, v_north_m_s, v_east_m_s, -climb_m_s
    )


def vfr_hud(
    state: FixedWingState,
    ground_speed_m_s: float,
    in_air: bool,
    alt_amsl_m: float,
    throttle: float = 0.6,
    climb_m_s: float = 0.0,
) -> mavlink.MAVLink_message:
    """Airspeed (the airframe's speed through the air) and ground speed (with the wind's
    drift) apart, heading in degrees, throttle in percent (0 on the ground), climb up > 0."""
    return mavlink.MAVLink_vfr_hud_message(
        state.speed_m_s,
        ground_speed_m_s,
        round(math.degrees(heading_rad(state))) % 360,
        round(100.0 * throttle) if in_air else 0,
        alt_amsl_m,
        climb_m_s,
    )


def wind_cov(t_s: float, wind_east_m_s: float, wind_north_m_s: float) -> mavlink.MAVLink_message:
    """PX4's WIND_COV: its EKF's wind, wind_x north and wind_y east (m/s, where the air moves
    to; MavlinkStreamWindCov sends windspeed_north / windspeed_east so), the horizontal
    variance, altitudes and accuracies not known (NaN / 0)."""
    return mavlink.MAVLink_wind_cov_message(
        round(t_s * 1e6), wind_north_m_s, wind_east_m_s, 0.0, 0.01, 0.0, math.nan, 0.0, 0.0
    )


def ardupilot_wind(wind_east_m_s: float, wind_north_m_s: float) -> mavlink.MAVLink_message:
    """ArduPilot's WIND (ardupilotmega): the direction the wind comes *from* (degrees, as
    ArduPilot sends degrees(atan2(-wind.y, -wind.x))), its speed and vertical speed (m/s)."""
    direction = math.degrees(math.atan2(-wind_east_m_s, -wind_north_m_s))
    speed = math.hypot(wind_east_m_s, wind_north_m_s)
    return ardupilotmega.MAVLink_wind_message(direction, speed, 0.0)


def global_position_int(
    lla: tuple[float, float, float],
    altitude_m: float,
    v_north_m_s: float,
    v_east_m_s: float,
    state: FixedWingState,
    t_s: float,
    climb_m_s: float = 0.0,
) -> mavlink.MAVLink_message:
    lat, lon, alt = lla
    return mavlink.MAVLink_global_position_int_message(
        boot_ms(t_s),
        round(lat * 1e7),
        round(lon * 1e7),
        round(alt * 1000.0),
        round(altitude_m * 1000.0),
        round(v_north_m_s * 100.0),
        round(v_east_m_s * 100.0),
        round(-climb_m_s * 100.0),  # vz: down > 0
        round(math.degrees(heading_rad(state)) * 100.0) % 36000,
    )


def gps_raw_int(
    lla: tuple[float, float, float], v_north_m_s: float, v_east_m_s: float, t_s: float
) -> mavlink.MAVLink_message:
    lat, lon, alt = lla
    cog = math.atan2(v_east_m_s, v_north_m_s) % (2.0 * math.pi)
    return mavlink.MAVLink_gps_raw_int_message(
        round(t_s * 1e6),
        mavlink.GPS_FIX_TYPE_3D_FIX,
        round(lat * 1e7),
        round(lon * 1e7),
        round(alt * 1000.0),
        80,
        120,
        round(math.hypot(v_north_m_s, v_east_m_s) * 100.0),
        round(math.degrees(cog) * 100.0) % 36000,
        14,
    )


def statustext(severity: int, text: str) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_statustext_message(severity, text.encode("ascii", "replace")[:50], 0, 0)


def command_ack(command: int, result: int, requester: tuple[int, int]) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_command_ack_message(command, result, 0, 0, requester[0], requester[1])


def camera_tracking_geo_status(
    obs: Observation, lat_deg: float, lon_deg: float, alt_m: float
) -> mavlink.MAVLink_message:
    """A camera fix: position, claimed sigma (h_acc) and slant range; velocity unknown (NaN)."""
    nan = math.nan
    return mavlink.MAVLink_camera_tracking_geo_status_message(
        tracking_status=mavlink.CAMERA_TRACKING_STATUS_FLAGS_ACTIVE,
        lat=round(lat_deg * 1e7),
        lon=round(lon_deg * 1e7),
        alt=alt_m,
        h_acc=obs.sigma_m,
        v_acc=nan,
        vel_n=nan,
        vel_e=nan,
        vel_d=nan,
        vel_acc=nan,
        dist=obs.range_m,
        hdg=nan,
        hdg_acc=nan,
        camera_device_id=0,
    )
