"""A planned orbit around a fast target and the flyable speed along it (improvements over the
paper): the ellipse closest to the circle r_d that the vehicle can fly, the field that converges
to it, and the ground-speed cap that keeps the turns along it within the course-rate limit."""

import functools
import math
from dataclasses import dataclass

from app.core.frames import TAU, wrap_pi
from app.core.guidance.field import FieldParams, check_finite, course_and_rate
from app.core.values import replace


@dataclass(frozen=True, slots=True)
class PlannedOrbit:
    """An ellipse centred on the target: semi-axis ``along_m`` along the unit vector
    (``motion_east``, ``motion_north``) of the target's motion and ``across_m`` across it, m
    (``along_m = across_m = r_d``: the circle)."""

    along_m: float
    across_m: float
    motion_east: float
    motion_north: float


def planned_orbit_axes(
    radius_m: float,
    target_speed_m_s: float,
    min_speed_m_s: float,
    max_course_rate_rad_s: float,
    margin: float = 1.0,
    max_stretch: float = 0.5,
) -> tuple[float, float]:
    """Semi-axes (along, across the target's motion), m, of the relative orbit the team flies
    around a target moving at ``target_speed_m_s``: the ellipse closest to the circle r_d (least
    RMS of r - r_d along it) that the vehicle can fly at ``margin`` of its course-rate limit.

    A vehicle on a relative path with unit tangent d and curvature kappa, at speed lambda
    relative to a target moving at v_t, has the ground velocity v_g = v_t + lambda d, whose course
    turns at lambda^2 kappa (lambda + v_t . d) / |v_g|^2. Where it flies against the target's
    motion its ground speed cannot drop below v_min, which forces lambda >= lambda_lo(d) (the
    root of |v_t + lambda d| = v_min); the turn rate at lambda_lo is the least the path can ask
    there. The circle r_d is flyable while that stays within margin * W everywhere (about 3.4 m/s
    of target speed with Table 2 and margin 1); beyond, an ellipse longer along the motion has
    flatter sides where the vehicle flies against the target, at the cost of a distance error.
    The ellipse is found by a grid search over the semi-axes (2 m steps, up to ``max_stretch``
    r_d from r_d), cached per target speed rounded *up* to 0.25 m/s (so it stays flyable for the
    speeds below). A target at or above v_min cannot be orbited at all; it is treated as one
    just below v_min.

    Returns (a, b); (r_d, r_d) when the circle is flyable.
    """
    check_finite(target_speed_m_s=target_speed_m_s)
    for name, value in (
        ("radius_m", radius_m),
        ("min_speed_m_s", min_speed_m_s),
        ("max_course_rate_rad_s", max_course_rate_rad_s),
        ("margin", margin),
        ("max_stretch", max_stretch),
    ):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    v_bin = math.ceil(min(abs(target_speed_m_s), 0.95 * min_speed_m_s) / 0.25 - 1e-9) * 0.25
    return _orbit_axes(
        float(radius_m), v_bin, float(min_speed_m_s), margin * max_course_rate_rad_s, max_stretch
    )


def _turn_need(a, b, v: float, v_min: float, t):  # type: ignore[no-untyped-def]
    """Largest ground course rate (rad/s) each ellipse (a, b arrays, broadcast against the
    samples t of the parameter) asks at the least relative speed lambda_lo."""
    import numpy as np

    du, dw = -a * np.sin(t), b * np.cos(t)
    norm = np.hypot(du, dw)
    kappa = a * b / norm**3
    along = v * du / norm
    lam = -along + np.sqrt(along * along + v_min * v_min - v * v)
    g2 = lam * lam + 2.0 * lam * along + v * v
    return np.max(lam * lam * kappa * (lam + along) / g2, axis=-1), norm


@functools.lru_cache(maxsize=1024)
def _orbit_axes(
    rd: float, v: float, v_min: float, w: float, max_stretch: float
) -> tuple[float, float]:
    import numpy as np

    # the ellipse is symmetric under t -> -t and t -> pi - t: a quarter of it is enough
    t = np.linspace(0.0, 0.5 * math.pi, 46)
    need, _ = _turn_need(np.float64(rd), np.float64(rd), v, v_min, t)
    if v <= 0.0 or need <= w:
        return rd, rd
    span = max_stretch * rd
    a = np.arange(rd, rd + span + 1e-9, 2.0)[:, None, None]
    b = np.arange(rd - span, rd + 10.0 + 1e-9, 2.0)[None, :, None]
    need, arc = _turn_need(a, b, v, v_min, t)
    err = np.hypot(a * np.cos(t), b * np.sin(t)) - rd
    rms = np.sqrt(np.sum(err * err * arc, axis=-1) / np.sum(arc, axis=-1))
    rms = np.where(need <= w, rms, np.inf)
    k = int(np.argmin(rms))
    ia, ib = divmod(k, rms.shape[1])
    if not math.isfinite(float(rms[ia, ib])):
        return rd + span, rd
    return float(a[ia, 0, 0]), float(b[0, ib, 0])


def ellipse_course_and_rate(
    x: float, y: float, vx: float, vy: float, field: FieldParams, orbit: PlannedOrbit
) -> tuple[float, float]:
    """Course (clockwise from north) and its rate of the field that converges to the ellipse
    ``orbit``: the ordinary field (eq. 8; ``field.inverse`` is not used) in coordinates stretched
    by r_d/a and r_d/b (a along the target's motion, b across it), mapped back.
    (x, y), (vx, vy): position and velocity relative to the target (east, north). The linear
    map keeps the field's convergence; on the ellipse the field is its tangent. The rate is
    exact along the given relative velocity for a fixed ellipse (d psi / d phi of the map times
    the stretched field's own rate). With a = b = r_d this is ``field_course``'s course and rate.
    """
    ux, uy = orbit.motion_east, orbit.motion_north
    # coordinates along u and across it (w = u turned counter-clockwise)
    pu, pw = x * ux + y * uy, -x * uy + y * ux
    vu, vw = vx * ux + vy * uy, -vx * uy + vy * ux
    rd = field.radius_m
    alpha, beta = orbit.along_m / rd, orbit.across_m / rd
    ordinary = replace(field, inverse=False) if field.inverse else field
    course_q, rate_q = course_and_rate(pu / alpha, pw / beta, vu / alpha, vw / beta, ordinary)
    # math angle (counter-clockwise from u) of the stretched field, and its rate
    phi = 0.5 * math.pi - course_q
    phi_dot = -rate_q
    cp, sp = math.cos(phi), math.sin(phi)
    psi = math.atan2(beta * sp, alpha * cp)
    psi_dot = alpha * beta / (alpha * alpha * cp * cp + beta * beta * sp * sp) * phi_dot
    world = psi + math.atan2(uy, ux)
    return wrap_pi(0.5 * math.pi - world), -psi_dot


# --------------------------------------------------------------------------------------------
# the flyable speed along an orbit around a moving target (improvement over the paper)

#: samples of the orbit's parameter angle in a speed profile (5 degree steps)
PROFILE_SAMPLES = 72
#: ground-speed grid step of a speed profile, m/s
PROFILE_SPEED_STEP_M_S = 0.1


def orbit_speed_profile(
    semi_axis_along_m: float,
    semi_axis_across_m: float,
    target_speed_m_s: float,
    min_speed_m_s: float,
    max_speed_m_s: float,
    max_course_rate_rad_s: float,
) -> tuple[float, ...]:
    """Largest ground speed (m/s) at which a vehicle can follow the relative orbit, the ellipse
    with semi-axes a (along the target's motion) and b (across it; a = b = r_d is the circle),
    flown counter-clockwise, at each of ``PROFILE_SAMPLES`` parameter angles s: the point
    (a cos s, b sin s) in the frame of the target's motion, s = 2 pi k / ``PROFILE_SAMPLES``.

    At ground speed g the speed lambda along the orbit's tangent d, relative to the target,
    solves |v_t + lambda d| = g, and the ground course turns at
    lambda^2 kappa (lambda + v_t . d) / g^2 (the relation ``planned_orbit_axes`` uses). Flying
    against the target's motion this grows with g: on the 90 m circle around a 3 m/s target a
    vehicle needs 0.19 rad/s at 10 m/s but 0.23 rad/s at 14 m/s. The profile holds the largest g
    on a ``PROFILE_SPEED_STEP_M_S`` grid from ``min_speed_m_s`` whose turn need, and that of
    every slower grid speed, is within ``max_course_rate_rad_s``; ``min_speed_m_s`` where even
    that is beyond it. Cached per (axes, target speed rounded *up* to 0.25 m/s, limits). A
    clockwise orbit is the mirror image: its profile at s is this one at -s.
    """
    check_finite(target_speed_m_s=target_speed_m_s)
    for name, value in (
        ("semi_axis_along_m", semi_axis_along_m),
        ("semi_axis_across_m", semi_axis_across_m),
        ("min_speed_m_s", min_speed_m_s),
        ("max_course_rate_rad_s", max_course_rate_rad_s),
    ):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    if not (math.isfinite(max_speed_m_s) and max_speed_m_s >= min_speed_m_s):
        raise ValueError(f"need finite max_speed_m_s >= min_speed_m_s, got {max_speed_m_s!r}")
    v_bin = math.ceil(abs(target_speed_m_s) / 0.25 - 1e-9) * 0.25
    return _speed_profile(
        float(semi_axis_along_m),
        float(semi_axis_across_m),
        v_bin,
        float(min_speed_m_s),
        float(max_speed_m_s),
        float(max_course_rate_rad_s),
    )


@functools.lru_cache(maxsize=1024)
def _speed_profile(
    a: float, b: float, v: float, v_min: float, v_max: float, w: float
) -> tuple[float, ...]:
    import numpy as np

    s = np.linspace(0.0, TAU, PROFILE_SAMPLES, endpoint=False)[:, None]
    du, dw = -a * np.sin(s), b * np.cos(s)
    norm = np.hypot(du, dw)
    kappa = a * b / norm**3
    along = v * du / norm  # v_t . d, the target moving along the first axis
    steps = max(1, math.ceil((v_max - v_min) / PROFILE_SPEED_STEP_M_S - 1e-9))
    g = np.minimum(v_min + PROFILE_SPEED_STEP_M_S * np.arange(steps + 1), v_max)[None, :]
    disc = along * along - v * v + g * g
    lam = np.maximum(0.0, -along + np.sqrt(np.maximum(disc, 0.0)))
    need = lam * lam * kappa * (lam + along) / (g * g)
    flyable = np.cumprod(need <= w * (1.0 + 1e-9), axis=1)  # at this and every slower speed
    count = flyable.sum(axis=1)
    best = np.where(count > 0, g[0, np.maximum(count - 1, 0)], v_min)
    return tuple(float(x) for x in best)


def orbit_speed_cap(
    rel_east_m: float,
    rel_north_m: float,
    rel_speed_m_s: float,
    orbit_sign: int,
    orbit: PlannedOrbit,
    profile: tuple[float, ...],
    brake_m_s2: float,
    horizon_rad: float = math.pi,
) -> float:
    """Largest ground speed (m/s) the vehicle may fly now so that, braking at ``brake_m_s2``,
    it is within ``profile`` (``orbit_speed_profile``) everywhere on the next ``horizon_rad`` of
    the orbit's parameter angle ahead of it.

    (``rel_east_m``, ``rel_north_m``): position relative to the target; ``rel_speed_m_s``: speed
    relative to the target; ``orbit``: the orbit and the target's motion; ``orbit_sign``: +1
    counter-clockwise, -1 clockwise. The vehicle is placed on the orbit at the parameter angle
    of its own position (its radial offset is ignored); a point an arc L ahead is reached
    after L / lambda seconds (lambda = the relative speed, at least 1 m/s), in which the speed
    can fall by ``brake_m_s2`` per second.
    """
    a, b = orbit.along_m, orbit.across_m
    motion_east, motion_north = orbit.motion_east, orbit.motion_north
    n = len(profile)
    step = TAU / n
    pu = rel_east_m * motion_east + rel_north_m * motion_north
    pw = orbit_sign * (-rel_east_m * motion_north + rel_north_m * motion_east)  # mirrored if cw
    k0 = int((math.atan2(pw / b, pu / a) % TAU) / step)
    lam = max(rel_speed_m_s, 1.0)
    cap = math.inf
    arc = 0.0
    for j in range(int(horizon_rad / step) + 2):
        k = (k0 + j) % n
        cap = min(cap, profile[k] + brake_m_s2 * arc / lam)
        s = (k + 0.5) * step
        arc += math.hypot(a * math.sin(s), b * math.cos(s)) * step
    return cap
