"""The wind, estimated from what every autopilot reports: ground velocity and airspeed.

No heading is needed. For a wind w, the air velocity is the ground velocity g minus w, and its
magnitude is the airspeed a: |g - w|^2 = a^2, that is

    2 g_e w_e + 2 g_n w_n - |w|^2 = |g|^2 - a^2,

linear in (w_e, w_n, c) with c = |w|^2 taken as a third unknown. Least squares over the frames,
each weighted by exp(-age / ``time_constant_s``), solves it once the ground course has varied
enough (an orbit does it in less than half a turn); with the course unchanged the system is
singular and the estimate stays unknown (``ready`` False) rather than wrong.

What the mission does with it (``airspeed_for``): the guidance and the phase keeping ask for a
ground velocity (the course and the speed along it); the autopilot is given the airspeed that
flies it in the estimated wind, so the phase rate the spacing law asks for is the one the vehicle
gets on the upwind and on the downwind side of the circle alike. Two things the slow fit cannot
follow are added to it: the gust along the track now (``along_track_gust``: the ground speed
measured against the one the measured airspeed gives in the fitted wind, low-passed over
``gust_time_constant_s``), and the autopilot's speed-loop lag (the airspeed is the one needed
where the course will be one speed-loop time constant later).
"""

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class WindParams:
    """``time_constant_s``: the memory of the fit (vehicle s); ``min_spread``: how much the
    ground velocities must have varied within it before the fit is believed: the smallest
    eigenvalue of 4 Cov(g) over the mean |g|^2 (2 for a whole turn, 0.12 for about 140 degrees
    of one: a short arc leaves the along-track wind and the airspeed's scale apart unresolved);
    ``max_wind_m_s``: a fit beyond this is not believed (bad airspeed data), nor one whose
    airspeeds disagree with its wind by more than ``max_mismatch_m_s`` (see ``estimate``).
    ``gust_time_constant_s``: the low-pass of the along-track gust (s); ``max_gust_m_s``: the
    largest gust taken (beyond it the measurement is more likely wrong than the wind).
    ``hold_s``: how long the mission agent keeps flying the last believed wind while the fit
    is not believed (a straight leg, a gusty spell).
    ``air_frame``: in the track stage, fly the guidance in the air mass (the mission agent's
    ``control``: the vehicle's heading and airspeed, the target moving at its ground velocity
    less the wind), so that the optimal c, the planned orbit, the speed cap and the phase law
    see the turn the vehicle really has to fly; False: the ground-speed conversion
    (``airspeed_for``) in every stage."""

    time_constant_s: float = 30.0
    min_spread: float = 0.12
    max_wind_m_s: float = 15.0
    max_mismatch_m_s: float = 2.0
    gust_time_constant_s: float = 1.0
    max_gust_m_s: float = 4.0
    air_frame: bool = True
    hold_s: float = 60.0

    def __post_init__(self) -> None:
        names = (
            "time_constant_s",
            "min_spread",
            "max_wind_m_s",
            "max_mismatch_m_s",
            "gust_time_constant_s",
            "max_gust_m_s",
            "hold_s",
        )
        for name in names:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")


def _zeros(shape: tuple[int, ...]) -> FloatArray:
    return np.zeros(shape)


@dataclass(frozen=True, slots=True)
class WindState:
    """The weighted normal equations (A^T W A, A^T W b) of the fit, their summed weight and the
    time of the newest frame."""

    ata: FloatArray = field(default_factory=lambda: _zeros((3, 3)))
    atb: FloatArray = field(default_factory=lambda: _zeros((3,)))
    weight: float = 0.0
    t_s: float = -math.inf

    def estimate(self, params: WindParams) -> tuple[float, float] | None:
        """(east, north) wind m/s, or None while the courses flown do not determine it."""
        if self.weight <= 0.0:
            return None
        # normalised by the weight; eliminating c leaves 4 Cov(g) for the wind's two components
        m = self.ata / self.weight
        velocity = m[:2, :2] - np.outer(m[:2, 2], m[:2, 2]) / max(m[2, 2], 1e-12)
        smallest = float(np.linalg.eigvalsh(0.5 * (velocity + velocity.T))[0])
        speed2 = float(np.trace(m[:2, :2])) / 4.0  # the mean |g|^2
        if not speed2 > 0.0 or smallest < params.min_spread * speed2:
            return None
        try:
            w = np.linalg.solve(self.ata, self.atb)
        except np.linalg.LinAlgError:
            return None
        east, north, c = float(w[0]), float(w[1]), float(w[2])
        if not (math.isfinite(east) and math.isfinite(north) and math.isfinite(c)):
            return None
        speed = math.hypot(east, north)
        if speed > params.max_wind_m_s:
            return None
        # c is |w|^2 when the airspeeds agree with the ground velocities; an airspeed off by
        # a constant shows as a c that is not (a bad pitot, a wrong scale): not believed
        if abs(math.sqrt(max(c, 0.0)) - speed) > params.max_mismatch_m_s:
            return None
        return east, north


def update(
    state: WindState,
    t_s: float,
    v_east_m_s: float,
    v_north_m_s: float,
    airspeed_m_s: float | None,
    params: WindParams,
) -> WindState:
    """The fit with one more frame (ground velocity, airspeed) of time ``t_s``; a frame without
    an airspeed, non-finite, or older than the newest is left out."""
    values = (t_s, v_east_m_s, v_north_m_s)
    if airspeed_m_s is None or not all(math.isfinite(v) for v in (*values, airspeed_m_s)):
        return state
    if airspeed_m_s <= 0.0 or t_s <= state.t_s:
        return state
    decay = (
        1.0
        if not math.isfinite(state.t_s)
        else math.exp(-(t_s - state.t_s) / params.time_constant_s)
    )
    row = np.array([2.0 * v_east_m_s, 2.0 * v_north_m_s, -1.0])
    rhs = v_east_m_s**2 + v_north_m_s**2 - airspeed_m_s**2
    return WindState(
        ata=decay * state.ata + np.outer(row, row),
        atb=decay * state.atb + row * rhs,
        weight=decay * state.weight + 1.0,
        t_s=t_s,
    )


def airspeed_for(
    course_rad: float,
    ground_speed_m_s: float,
    wind: tuple[float, float],
    min_airspeed_m_s: float,
    max_airspeed_m_s: float,
) -> float:
    """The airspeed that flies ground speed ``ground_speed_m_s`` along ``course_rad`` in the
    wind (|g - w|), held to the airframe's airspeed limits."""
    g_east = ground_speed_m_s * math.sin(course_rad)
    g_north = ground_speed_m_s * math.cos(course_rad)
    air = math.hypot(g_east - wind[0], g_north - wind[1])
    return min(max(air, min_airspeed_m_s), max_airspeed_m_s)


def along_track_gust(
    course_rad: float,
    ground_speed_m_s: float,
    airspeed_m_s: float | None,
    wind: tuple[float, float],
) -> float | None:
    """The wind along the ground track beyond the fitted ``wind`` (m/s, positive with the
    track): the ground speed measured minus the one the measured airspeed flies along
    ``course_rad`` in ``wind`` (w . t + sqrt(a^2 - (w x t)^2)). None without a usable airspeed
    or where the cross wind exceeds it."""
    if airspeed_m_s is None or not (math.isfinite(airspeed_m_s) and airspeed_m_s > 0.0):
        return None
    t_east, t_north = math.sin(course_rad), math.cos(course_rad)
    along = wind[0] * t_east + wind[1] * t_north
    cross = wind[0] * t_north - wind[1] * t_east
    inside = airspeed_m_s * airspeed_m_s - cross * cross
    if not inside > 0.0:
        return None
    gust = ground_speed_m_s - (along + math.sqrt(inside))
    return gust if math.isfinite(gust) else None


def filtered_gust(
    previous_m_s: float, previous_t_s: float, gust_m_s: float, t_s: float, params: WindParams
) -> float:
    """The low-passed along-track gust after a new measurement ``gust_m_s`` of time ``t_s``
    (first order, ``gust_time_constant_s``; a first measurement or time going back restarts
    it), held within ``max_gust_m_s``."""
    limit = params.max_gust_m_s
    gust = min(max(gust_m_s, -limit), limit)
    dt = t_s - previous_t_s
    if not (0.0 < dt < math.inf):
        return gust if not math.isfinite(previous_t_s) or dt < 0.0 else previous_m_s
    blend = 1.0 - math.exp(-dt / params.gust_time_constant_s)
    return previous_m_s + blend * (gust - previous_m_s)
