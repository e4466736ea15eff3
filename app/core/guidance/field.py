"""The Lyapunov vector field (paper sections 3-4): field, inverse field, curvature, optimal c.

Frames. Positions are metres east/north *relative to the target* (``rel_east_m``,
``rel_north_m``). The paper's angles (psi, theta) are counter-clockwise from east; courses
(``course_rad``) are MAVLink's, clockwise from north. ``orbit_sign`` is +1 for a counter-clockwise
orbit seen from above (the paper's field) and -1 for a clockwise one (the mirror image).

Every function of the guidance package works on plain floats with ``math`` (they run every
control tick of a simulation with 10^5 steps), is pure and rejects non-finite input with
``ValueError`` (the ``*_unchecked`` kernels and ``course_and_rate`` of the inner loops excepted).

The field in polar form (eq. 4) has the heading psi_f = theta + orbit_sign * phi(r) with

    cos phi = (r_d^2 - r^2) / sqrt(D),   sin phi = c r r_d / sqrt(D),
    D = r^4 + (c^2 - 2) r^2 r_d^2 + r_d^4 = (r^2 - r_d^2)^2 + c^2 r^2 r_d^2,

which is eq. (8) divided by s; the inverse field (eq. 13/14) flips the radial part
(phi -> pi - phi). The centre r = 0 is singular: there the field has no defined direction
(eq. 8 is 0/0). Within ``CENTRE_RADIUS_FRACTION * r_d`` of the centre we return the outward
direction along the vehicle's own course (or due east when no course is known), so the vehicle
simply flies out of the centre; this is stated in every function that can reach it.
"""

import math
from dataclasses import dataclass

SQRT2 = math.sqrt(2.0)
#: below this fraction of r_d from the target the field direction is undefined (eq. 8 is 0/0)
CENTRE_RADIUS_FRACTION = 1e-9


def check_finite(**values: float) -> None:
    """Raise ``ValueError`` naming the first value that is not finite."""
    for name, value in values.items():
        if not math.isfinite(value):
            raise ValueError(f"{name} must be finite, got {value!r}")


def _check_field_params(radius_m: float, c: float) -> None:
    if not (math.isfinite(radius_m) and radius_m > 0.0):
        raise ValueError(f"radius_m (r_d) must be finite and > 0, got {radius_m!r}")
    if not (math.isfinite(c) and c > 0.0):
        raise ValueError(f"guidance parameter c must be finite and > 0, got {c!r}")


@dataclass(frozen=True, slots=True)
class FieldParams:
    """Which field: r_d ``radius_m`` (m, > 0), the guidance parameter ``c`` (> 0; 2 is Frew's),
    ``orbit_sign`` (+1 counter-clockwise, the paper's; -1 clockwise, the mirror image) and
    ``inverse`` (the inverse field of eq. 13/14, which leads away from the circle)."""

    radius_m: float
    c: float
    orbit_sign: int = 1
    inverse: bool = False

    def __post_init__(self) -> None:
        _check_field_params(self.radius_m, self.c)
        if self.orbit_sign not in (1, -1):
            raise ValueError(f"orbit_sign must be +1 or -1, got {self.orbit_sign!r}")


# --------------------------------------------------------------------------------------------
# the field


def field_direction(
    rel_east_m: float,
    rel_north_m: float,
    radius_m: float,
    c: float,
    orbit_sign: int = 1,
    inverse: bool = False,
) -> tuple[float, float]:
    """Unit direction (east, north) of the Lyapunov vector field, eq. (8), or of the inverse
    field, eq. (14).

    Parameters
    ----------
    rel_east_m, rel_north_m : float
        Vehicle position relative to the target, metres east and north.
    radius_m : float
        Standoff radius r_d, metres (> 0).
    c : float
        Guidance parameter (> 0); c = 2 is Frew's original field.
    orbit_sign : int
        +1 counter-clockwise orbit (the paper's), -1 clockwise (mirror image).
    inverse : bool
        The inverse field (ILVF, eq. 13/14), which leads away from the circle.

    Returns
    -------
    (float, float)
        Unit vector (east, north). At the centre (r < ``CENTRE_RADIUS_FRACTION`` r_d) the field
        is undefined and (1, 0), due east, is returned.
    """
    check_finite(rel_east_m=rel_east_m, rel_north_m=rel_north_m)
    _check_field_params(radius_m, c)
    return _direction(rel_east_m, rel_north_m, radius_m, c, orbit_sign, inverse)


def _direction(
    x: float, y: float, rd: float, c: float, sign: int, inverse: bool
) -> tuple[float, float]:
    r = math.hypot(x, y)
    if r < CENTRE_RADIUS_FRACTION * rd:
        return 1.0, 0.0
    root_d = math.sqrt((r * r - rd * rd) ** 2 + (c * r * rd) ** 2)
    cos_phi = (rd * rd - r * r) / root_d
    if inverse:
        cos_phi = -cos_phi
    sin_phi = sign * c * r * rd / root_d
    cos_t, sin_t = x / r, y / r
    # psi_f = theta + sign * phi (paper angle, counter-clockwise from east)
    return cos_t * cos_phi - sin_t * sin_phi, sin_t * cos_phi + cos_t * sin_phi


def field_velocity(
    rel_east_m: float,
    rel_north_m: float,
    radius_m: float,
    c: float,
    speed_m_s: float,
    orbit_sign: int = 1,
    inverse: bool = False,
) -> tuple[float, float]:
    """Desired velocity (east, north) in m/s of eq. (8) (or eq. (14) with ``inverse``).

    Its magnitude is ``speed_m_s`` everywhere except the centre, where the field is undefined and
    the velocity is taken due east (see ``field_direction``).
    """
    check_finite(speed_m_s=speed_m_s)
    u_e, u_n = field_direction(rel_east_m, rel_north_m, radius_m, c, orbit_sign, inverse)
    return speed_m_s * u_e, speed_m_s * u_n


def field_polar_rates(
    r_m: float, radius_m: float, c: float, speed_m_s: float, inverse: bool = False
) -> tuple[float, float]:
    """(r_dot, r theta_dot) of eq. (4) (or eq. (13) with ``inverse``), m/s, counter-clockwise.

    At r = 0 eq. (4) gives r_dot = s, r theta_dot = 0, which is returned.
    """
    check_finite(r_m=r_m, speed_m_s=speed_m_s)
    _check_field_params(radius_m, c)
    if r_m < 0.0:
        raise ValueError(f"r_m must be >= 0, got {r_m!r}")
    root_d = math.sqrt((r_m * r_m - radius_m * radius_m) ** 2 + (c * r_m * radius_m) ** 2)
    radial = -(r_m * r_m - radius_m * radius_m) / root_d
    if inverse:
        radial = -radial
    return speed_m_s * radial, speed_m_s * c * r_m * radius_m / root_d


def field_course(
    rel_east_m: float,
    rel_north_m: float,
    rel_v_east_m_s: float,
    rel_v_north_m_s: float,
    field: FieldParams,
) -> tuple[float, float]:
    """Course of the field at a point and its rate of change along the vehicle's motion.

    With the field heading psi_f = theta + orbit_sign * phi(r) (module docstring),

        d psi_f / dt = theta_dot + orbit_sign * phi'(r) r_dot,
        phi'(r) = c r_d (r^2 + r_d^2) / D        (ordinary field; minus for the inverse),

    where theta_dot and r_dot are those of the vehicle's *actual* relative velocity. Along the
    field itself this is s * kappa, eq. (11), signed with the orbit. It is what a course loop must
    feed forward to follow the field without lag.

    Parameters
    ----------
    rel_east_m, rel_north_m : float
        Vehicle position relative to the target, m.
    rel_v_east_m_s, rel_v_north_m_s : float
        Vehicle velocity relative to the target, m/s.
    field : FieldParams
        r_d, c, orbit direction, ordinary or inverse field.

    Returns
    -------
    (float, float)
        Field course (rad, clockwise from north, in [-pi, pi]) and its rate (rad/s, clockwise
        positive). At the centre the field is undefined: the course is the vehicle's own (due
        east if it stands still) and the rate 0.
    """
    check_finite(
        rel_east_m=rel_east_m,
        rel_north_m=rel_north_m,
        rel_v_east_m_s=rel_v_east_m_s,
        rel_v_north_m_s=rel_v_north_m_s,
    )
    return course_and_rate(rel_east_m, rel_north_m, rel_v_east_m_s, rel_v_north_m_s, field)


def course_and_rate(
    x: float, y: float, vx: float, vy: float, field: FieldParams
) -> tuple[float, float]:
    """``field_course`` without the finiteness checks, for the inner loops (every control tick,
    every step of a prediction): (x, y) m and (vx, vy) m/s relative to the target."""
    rd, c, sign = field.radius_m, field.c, field.orbit_sign
    r2 = x * x + y * y
    rd2 = rd * rd
    if r2 < (CENTRE_RADIUS_FRACTION * rd) ** 2:
        if vx == 0.0 and vy == 0.0:
            return 0.5 * math.pi, 0.0
        return math.atan2(vx, vy), 0.0
    r = math.sqrt(r2)
    d = (r2 - rd2) ** 2 + c * c * r2 * rd2
    root_d = math.sqrt(d)
    cos_phi = (rd2 - r2) / root_d
    dphi_dr = c * rd * (r2 + rd2) / d
    if field.inverse:
        cos_phi = -cos_phi
        dphi_dr = -dphi_dr
    sin_phi = sign * c * r * rd / root_d
    cos_t, sin_t = x / r, y / r
    u_e = cos_t * cos_phi - sin_t * sin_phi
    u_n = sin_t * cos_phi + cos_t * sin_phi
    r_dot = (x * vx + y * vy) / r
    theta_dot = (x * vy - y * vx) / r2
    psi_dot = theta_dot + sign * dphi_dr * r_dot
    # MAVLink course = pi/2 - psi, so its rate is -psi_dot
    return math.atan2(u_e, u_n), -psi_dot


# --------------------------------------------------------------------------------------------
# curvature and the optimal c (section 4.1)


def curvature(
    r_m: float,
    radius_m: float,
    c: float,
    c_rate_per_s: float = 0.0,
    speed_m_s: float = 1.0,
) -> float:
    """Signed curvature of the field lines, eq. (10); eq. (11) when c is constant.

    kappa = psi_dot / s in 1/m, positive when the path turns in the orbit's direction (to the left
    for a counter-clockwise orbit). On the circle kappa = 1/r_d for every c. Defined for every
    r >= 0 (at r = 0 eq. (11) gives c (2 r_d^2) r_d^3 / r_d^6 = 2c / r_d).

    Parameters
    ----------
    r_m : float
        Distance from the target, m (>= 0).
    radius_m : float
        r_d, m.
    c : float
        Guidance parameter.
    c_rate_per_s : float
        c_dot of eq. (10), 1/s; 0 gives eq. (11).
    speed_m_s : float
        s, m/s (only used with c_rate_per_s != 0).
    """
    check_finite(r_m=r_m, c_rate_per_s=c_rate_per_s, speed_m_s=speed_m_s)
    _check_field_params(radius_m, c)
    if r_m < 0.0:
        raise ValueError(f"r_m must be >= 0, got {r_m!r}")
    r2, rd2 = r_m * r_m, radius_m * radius_m
    d = r2 * r2 + (c * c - 2.0) * rd2 * r2 + rd2 * rd2
    kappa = c * radius_m**3 * ((c * c - 2.0) * r2 + 2.0 * rd2) / (d * math.sqrt(d))
    if c_rate_per_s != 0.0:
        if not speed_m_s > 0.0:
            raise ValueError("speed_m_s must be > 0 with a non-zero c_rate_per_s (eq. 10)")
        kappa -= c_rate_per_s * radius_m * r_m * (r2 - rd2) / (speed_m_s * d)
    return kappa


def _curvature_normalised(u: float, c: float) -> float:
    """kappa * r_d as a function of u = (r / r_d)^2 (eq. 11)."""
    a = c * c - 2.0
    d = u * u + a * u + 1.0
    return c * (a * u + 2.0) / (d * math.sqrt(d))


def peak_curvature(radius_m: float, c: float) -> tuple[float, float]:
    """The largest |kappa| over r >= r_d (eq. 11, section 4.1) and where it occurs, in closed form.

    With u = (r/r_d)^2 and a = c^2 - 2, d kappa / du = 0 reduces to
    4 a u^2 + (a^2 + 12) u + 4 a = 0, whose roots are u* and 1/u*. For c >= sqrt(2) kappa
    decreases from 1/r_d on the circle, so the peak is 1/r_d at r = r_d. For c < sqrt(2) kappa
    falls from 1/r_d on the circle to a negative minimum at u* > 1 (the join turn, against the
    orbit direction) and returns to 0; the peak is the larger of 1/r_d and that minimum's size.

    Returns
    -------
    (float, float)
        Peak |kappa| in 1/m, and the distance from the target where it occurs, m.
    """
    _check_field_params(radius_m, c)
    u_star = _negative_extremum_u(c)
    if u_star is None:
        return 1.0 / radius_m, radius_m
    k_neg = -_curvature_normalised(u_star, c)
    if k_neg <= 1.0:
        return 1.0 / radius_m, radius_m
    return k_neg / radius_m, radius_m * math.sqrt(u_star)


def _negative_extremum_u(c: float) -> float | None:
    a = c * c - 2.0
    if a >= 0.0:
        return None
    b = a * a + 12.0
    disc = b * b - 64.0 * a * a  # = (a-2)(a-6)(a+2)(a+6) > 0 for -2 < a < 0
    # larger root of 4a u^2 + b u + 4a = 0 (a < 0), written without cancellation
    return (b + math.sqrt(disc)) / (-8.0 * a)


def _join_peak(c: float) -> float:
    """|kappa| r_d at the negative extremum (0 for c >= sqrt 2); decreasing in c."""
    u_star = _negative_extremum_u(c)
    return 0.0 if u_star is None else -_curvature_normalised(u_star, c)


def optimal_c(
    radius_m: float,
    speed_m_s: float,
    max_course_rate_rad_s: float,
    curvature_margin: float = 1.0,
) -> float:
    """The optimal guidance parameter of section 4.1: the smallest c whose peak |kappa| over
    r >= r_d stays within ``curvature_margin`` * (max course rate) / speed (eq. 12).

    Solved as the exact root of  r_d |kappa(c, r*(c))| = K,  K = margin * W r_d / s, where r*(c)
    is the closed-form location of the join-turn extremum (``peak_curvature``); the left side
    falls monotonically from infinity (c -> 0) to 0 (c -> sqrt 2). Bisection on that closed form
    to 1e-12 takes a few tens of microseconds, so it can rerun every control tick.

    If K < 1 the circle itself is too tight to fly (kappa = 1/r_d there for every c). The best any
    c can do is then a peak of exactly 1/r_d, and the smallest c reaching that is returned; the
    caller can see the infeasibility from ``radius_m * max_course_rate_rad_s / speed_m_s < 1``.

    Parameters
    ----------
    radius_m : float
        r_d, m (> 0).
    speed_m_s : float
        Vehicle speed s, m/s (> 0).
    max_course_rate_rad_s : float
        Course-rate limit W, rad/s (> 0).
    curvature_margin : float
        Fraction (0, 1] of the limit the field may use; 1 is the paper's choice.

    Returns
    -------
    float
        c_opt in (0, sqrt 2).
    """
    for name, value in (
        ("radius_m", radius_m),
        ("speed_m_s", speed_m_s),
        ("max_course_rate_rad_s", max_course_rate_rad_s),
    ):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    if not (math.isfinite(curvature_margin) and 0.0 < curvature_margin <= 1.0):
        raise ValueError(f"curvature_margin must be in (0, 1], got {curvature_margin!r}")
    target = max(curvature_margin * max_course_rate_rad_s * radius_m / speed_m_s, 1.0)
    # |kappa| r_d at the extremum grows like 1/c as c -> 0: bracket [lo, hi] with g(lo) > target
    lo, hi = min(0.5 / target, 1e-3), SQRT2
    while _join_peak(lo) <= target:
        lo *= 0.5
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _join_peak(mid) > target:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-12:
            break
    return hi
