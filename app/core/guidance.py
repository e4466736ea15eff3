"""Lyapunov vector field guidance (paper sections 3-4): field, inverse field, curvature, optimal c,
the inverse-field switch rule, a lag-compensated course command and the moving-target correction.

Frames. Positions are metres east/north *relative to the target* (``rel_east_m``,
``rel_north_m``). The paper's angles (psi, theta) are counter-clockwise from east; courses
(``course_rad``) are MAVLink's, clockwise from north. ``orbit_sign`` is +1 for a counter-clockwise
orbit seen from above (the paper's field) and -1 for a clockwise one (the mirror image).

Every function here works on plain floats with ``math`` (they run every control tick of a
simulation with 10^5 steps), is pure and rejects non-finite input with ``ValueError``.

The field in polar form (eq. 4) has the heading psi_f = theta + orbit_sign * phi(r) with

    cos phi = (r_d^2 - r^2) / sqrt(D),   sin phi = c r r_d / sqrt(D),
    D = r^4 + (c^2 - 2) r^2 r_d^2 + r_d^4 = (r^2 - r_d^2)^2 + c^2 r^2 r_d^2,

which is eq. (8) divided by s; the inverse field (eq. 13/14) flips the radial part
(phi -> pi - phi). The centre r = 0 is singular: there the field has no defined direction
(eq. 8 is 0/0). Within ``CENTRE_RADIUS_FRACTION * r_d`` of the centre we return the outward
direction along the vehicle's own course (or due east when no course is known), so the vehicle
simply flies out of the centre; this is stated in every function that can reach it.
"""

import functools
import math

from app.core.frames import TAU, wrap_pi

SQRT2 = math.sqrt(2.0)
#: below this fraction of r_d from the target the field direction is undefined (eq. 8 is 0/0)
CENTRE_RADIUS_FRACTION = 1e-9


def _check_finite(**values: float) -> None:
    for name, value in values.items():
        if not math.isfinite(value):
            raise ValueError(f"{name} must be finite, got {value!r}")


def _check_field_params(radius_m: float, c: float) -> None:
    if not (math.isfinite(radius_m) and radius_m > 0.0):
        raise ValueError(f"radius_m (r_d) must be finite and > 0, got {radius_m!r}")
    if not (math.isfinite(c) and c > 0.0):
        raise ValueError(f"guidance parameter c must be finite and > 0, got {c!r}")


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
    _check_finite(rel_east_m=rel_east_m, rel_north_m=rel_north_m)
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
    _check_finite(speed_m_s=speed_m_s)
    u_e, u_n = field_direction(rel_east_m, rel_north_m, radius_m, c, orbit_sign, inverse)
    return speed_m_s * u_e, speed_m_s * u_n


def field_polar_rates(
    r_m: float, radius_m: float, c: float, speed_m_s: float, inverse: bool = False
) -> tuple[float, float]:
    """(r_dot, r theta_dot) of eq. (4) (or eq. (13) with ``inverse``), m/s, counter-clockwise.

    At r = 0 eq. (4) gives r_dot = s, r theta_dot = 0, which is returned.
    """
    _check_finite(r_m=r_m, speed_m_s=speed_m_s)
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
    radius_m: float,
    c: float,
    orbit_sign: int = 1,
    inverse: bool = False,
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
    radius_m, c, orbit_sign, inverse
        As in ``field_direction``.

    Returns
    -------
    (float, float)
        Field course (rad, clockwise from north, in [-pi, pi]) and its rate (rad/s, clockwise
        positive). At the centre the field is undefined: the course is the vehicle's own (due
        east if it stands still) and the rate 0.
    """
    _check_finite(
        rel_east_m=rel_east_m,
        rel_north_m=rel_north_m,
        rel_v_east_m_s=rel_v_east_m_s,
        rel_v_north_m_s=rel_v_north_m_s,
    )
    _check_field_params(radius_m, c)
    return _course_and_rate(
        rel_east_m, rel_north_m, rel_v_east_m_s, rel_v_north_m_s, radius_m, c, orbit_sign, inverse
    )


def _course_and_rate(
    x: float, y: float, vx: float, vy: float, rd: float, c: float, sign: int, inverse: bool
) -> tuple[float, float]:
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
    if inverse:
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
    _check_finite(r_m=r_m, c_rate_per_s=c_rate_per_s, speed_m_s=speed_m_s)
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


# --------------------------------------------------------------------------------------------
# course command that the eq. (2) vehicle can follow


def course_command(
    course_rad: float,
    field_course_rad: float,
    field_course_rate_rad_s: float,
    course_gain_per_s: float,
    max_course_rate_rad_s: float,
    feed_forward: bool = True,
) -> float:
    """A course command for the eq. (2) course loop, compensated for its lag.

    Eq. (2) turns at k * (command - course), saturated at W. Commanding the field course itself
    leaves a lag e = (field course rate) / k, so the vehicle settles c s / (2k) off the circle and
    overshoots where the field turns hard. With feed-forward the command is

        course + clamp(wrap(field_course - course) + field_course_rate / k, +-W/k),

    so unsaturated the course error obeys de/dt = -k e exactly. The clamp keeps the implied rate
    within W (the turn direction is the one of the field error, never an ambiguous wrap of a
    command half a turn away). Without feed-forward the command is the field course (the paper's
    literal law), still clamped.

    All angles are courses (rad, clockwise from north); the result is in [-pi, pi).
    """
    _check_finite(
        course_rad=course_rad,
        field_course_rad=field_course_rad,
        field_course_rate_rad_s=field_course_rate_rad_s,
    )
    if not (course_gain_per_s > 0.0 and max_course_rate_rad_s > 0.0):
        raise ValueError("course_gain_per_s and max_course_rate_rad_s must be > 0")
    return _course_command(
        course_rad,
        field_course_rad,
        field_course_rate_rad_s,
        course_gain_per_s,
        max_course_rate_rad_s,
        feed_forward,
    )


def _course_command(
    course: float, field_course: float, field_rate: float, k: float, w: float, ff: bool
) -> float:
    lead = wrap_pi(field_course - course)
    if ff:
        lead += field_rate / k
    limit = w / k
    lead = min(max(lead, -limit), limit)
    return wrap_pi(course + lead)


# --------------------------------------------------------------------------------------------
# the inverse-field switch rule (section 4.1)


def predict_min_distance_error(
    rel_east_m: float,
    rel_north_m: float,
    course_rad: float,
    speed_m_s: float,
    radius_m: float,
    c: float,
    course_gain_per_s: float,
    max_course_rate_rad_s: float,
    orbit_sign: int = 1,
    feed_forward: bool = True,
    step_s: float = 0.1,
    horizon_s: float = 60.0,
) -> float:
    """Smallest r - r_d (m) the vehicle would reach flying the *ordinary* field from here.

    The prediction integrates eq. (2) (course loop with gain k saturated at W, constant speed,
    target-relative frame) under ``course_command`` in steps of ``step_s``. It stops early when the
    outcome is decided:

    - the vehicle is inside the circle (r < r_d): the value is returned at once;
    - the course is aligned with the field (within 0.01 rad) while the field's peak curvature is
      within W / s: from there the vehicle follows a field line, and field lines never cross the
      circle ((r^2 - r_d^2)^2 does not increase along them);
    - with feed-forward, the vehicle is more than 2.2 turn radii outside the circle and moving
      away (a lagging literal loop is followed to the horizon instead: it may still come back
      and overshoot);
    - the horizon ends.

    This is the guidance's own model of the closed loop, used only for this prediction.
    """
    _check_finite(
        rel_east_m=rel_east_m, rel_north_m=rel_north_m, course_rad=course_rad, speed_m_s=speed_m_s
    )
    _check_field_params(radius_m, c)
    if not (speed_m_s > 0.0 and step_s > 0.0 and horizon_s > 0.0):
        raise ValueError("speed_m_s, step_s and horizon_s must be > 0")
    k, w = course_gain_per_s, max_course_rate_rad_s
    flyable = peak_curvature(radius_m, c)[0] <= w / speed_m_s * (1.0 + 1e-9)
    far_m = 2.2 * speed_m_s / w
    x, y, chi = rel_east_m, rel_north_m, course_rad
    min_err = math.hypot(x, y) - radius_m
    t = 0.0
    while t < horizon_s:
        vx, vy = speed_m_s * math.sin(chi), speed_m_s * math.cos(chi)
        f_course, f_rate = _course_and_rate(x, y, vx, vy, radius_m, c, orbit_sign, False)
        error = wrap_pi(f_course - chi)
        if flyable and abs(error) < 0.01:
            return min_err
        cmd = _course_command(chi, f_course, f_rate, k, w, feed_forward)
        rate = min(max(k * wrap_pi(cmd - chi), -w), w)
        mid = chi + 0.5 * rate * step_s
        x += speed_m_s * math.sin(mid) * step_s
        y += speed_m_s * math.cos(mid) * step_s
        chi += rate * step_s
        t += step_s
        err = math.hypot(x, y) - radius_m
        if err < min_err:
            min_err = err
            if err < 0.0:
                return min_err
        elif feed_forward and err > far_m and x * math.sin(chi) + y * math.cos(chi) > 0.0:
            return min_err
    return min_err


def inverse_field_wanted(
    using_inverse: bool,
    predicted_min_error_m: float,
    enter_below_m: float = 0.0,
    leave_above_m: float = 0.5,
) -> bool:
    """The ILVF switch rule with hysteresis (section 4.1).

    Switch to the inverse field when flying the ordinary field from here would take the vehicle
    inside the circle (predicted min r - r_d < ``enter_below_m``); switch back once it would stay
    at least ``leave_above_m`` outside. The gap keeps the switch from chattering.
    """
    _check_finite(predicted_min_error_m=predicted_min_error_m)
    if using_inverse:
        return predicted_min_error_m < leave_above_m
    return predicted_min_error_m < enter_below_m


# --------------------------------------------------------------------------------------------
# the moving-target correction (eq. 15)


def moving_target_velocity(
    rel_dir_east: float,
    rel_dir_north: float,
    target_v_east_m_s: float,
    target_v_north_m_s: float,
    speed_m_s: float,
    min_speed_m_s: float,
    max_speed_m_s: float,
    relative_speed: bool = True,
) -> tuple[float, float, float, bool]:
    """Ground velocity v_g = v_t + lambda v_d of eq. (15), v_d the unit field direction ``rel_dir``
    in the target's frame, with v_min <= |v_g| <= v_max.

    ``relative_speed=True`` (eq. 15 as written): lambda = ``speed_m_s``, so the vehicle flies the
    field at that speed *relative to the target* (every vehicle of a team circles the target at
    the same angular rate, whatever side it is on), unless |v_g| leaves the limits; then lambda
    is the larger root of |v_t + lambda d| = the limit it crossed.
    ``relative_speed=False`` (Frew's choice): lambda is the root giving |v_g| = ``speed_m_s``.
    When no lambda >= 0 reaches the wanted ground speed (a target faster than the vehicle), the
    lambda >= 0 that comes closest is used and |v_g| is clamped into the limits.

    Returns
    -------
    (float, float, float, bool)
        v_g east, v_g north (m/s), lambda (m/s along the field), and whether the ground speed
        is held at a fixed value (a limit, or ``speed_m_s`` with ``relative_speed=False``): then
        d|v_g|/dt = 0, else d lambda/dt = 0.
    """
    _check_finite(
        rel_dir_east=rel_dir_east,
        rel_dir_north=rel_dir_north,
        target_v_east_m_s=target_v_east_m_s,
        target_v_north_m_s=target_v_north_m_s,
        speed_m_s=speed_m_s,
    )
    if not 0.0 < min_speed_m_s <= max_speed_m_s:
        raise ValueError("need 0 < min_speed_m_s <= max_speed_m_s")
    return _moving_target_velocity(
        rel_dir_east,
        rel_dir_north,
        target_v_east_m_s,
        target_v_north_m_s,
        speed_m_s,
        min_speed_m_s,
        max_speed_m_s,
        relative_speed,
    )


def _lambda_for_ground_speed(along: float, t2: float, s: float) -> float:
    """The larger root of |v_t + lambda d| = s (|d| = 1), or the closest lambda >= 0."""
    disc = along * along - t2 + s * s
    return max(0.0, -along + math.sqrt(disc)) if disc >= 0.0 else max(0.0, -along)


def _moving_target_velocity(
    dx: float,
    dy: float,
    tx: float,
    ty: float,
    s: float,
    s_min: float,
    s_max: float,
    relative: bool = True,
) -> tuple[float, float, float, bool]:
    s = min(max(s, s_min), s_max)
    along = tx * dx + ty * dy
    t2 = tx * tx + ty * ty
    held = True
    if relative:
        lam = s
        g2 = (tx + lam * dx) ** 2 + (ty + lam * dy) ** 2
        if g2 > s_max * s_max:
            lam = _lambda_for_ground_speed(along, t2, s_max)
        elif g2 < s_min * s_min:
            lam = _lambda_for_ground_speed(along, t2, s_min)
        else:
            held = False
    else:
        lam = _lambda_for_ground_speed(along, t2, s)
    gx, gy = tx + lam * dx, ty + lam * dy
    g = math.hypot(gx, gy)
    if g > s_max or (0.0 < g < s_min):
        scale = (s_max if g > s_max else s_min) / g
        gx, gy = gx * scale, gy * scale
    elif g == 0.0:
        gx, gy = s_min * dx, s_min * dy
    return gx, gy, lam, held


# --------------------------------------------------------------------------------------------
# a planned orbit around a fast target (improvement over the paper)


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
    _check_finite(target_speed_m_s=target_speed_m_s)
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
    x: float,
    y: float,
    vx: float,
    vy: float,
    rd: float,
    c: float,
    sign: int,
    ux: float,
    uy: float,
    a: float,
    b: float,
) -> tuple[float, float]:
    """Course (clockwise from north) and its rate of the field that converges to the ellipse
    with semi-axis ``a`` along the unit vector (ux, uy) and ``b`` across it, centred on the
    target: the ordinary field (eq. 8) in coordinates stretched by r_d/a and r_d/b, mapped back.
    (x, y), (vx, vy): position and velocity relative to the target (east, north). The linear
    map keeps the field's convergence; on the ellipse the field is its tangent. The rate is
    exact along the given relative velocity for a fixed ellipse (d psi / d phi of the map times
    the stretched field's own rate). With a = b = r_d this is ``field_course``'s course and rate.
    """
    # coordinates along u and across it (w = u turned counter-clockwise)
    pu, pw = x * ux + y * uy, -x * uy + y * ux
    vu, vw = vx * ux + vy * uy, -vx * uy + vy * ux
    alpha, beta = a / rd, b / rd
    course_q, rate_q = _course_and_rate(
        pu / alpha, pw / beta, vu / alpha, vw / beta, rd, c, sign, False
    )
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
    _check_finite(target_speed_m_s=target_speed_m_s)
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
    motion_east: float,
    motion_north: float,
    semi_axis_along_m: float,
    semi_axis_across_m: float,
    profile: tuple[float, ...],
    brake_m_s2: float,
    horizon_rad: float = math.pi,
) -> float:
    """Largest ground speed (m/s) the vehicle may fly now so that, braking at ``brake_m_s2``,
    it is within ``profile`` (``orbit_speed_profile``) everywhere on the next ``horizon_rad`` of
    the orbit's parameter angle ahead of it.

    (``rel_east_m``, ``rel_north_m``): position relative to the target; ``rel_speed_m_s``: speed
    relative to the target; (``motion_east``, ``motion_north``): unit vector of the target's
    motion; the semi-axes: the orbit's along and across it; ``orbit_sign``: +1
    counter-clockwise, -1 clockwise. The vehicle is placed on the orbit at the parameter angle
    of its own position (its radial offset is ignored); a point an arc L ahead is reached
    after L / lambda seconds (lambda = the relative speed, at least 1 m/s), in which the speed
    can fall by ``brake_m_s2`` per second.
    """
    a, b = semi_axis_along_m, semi_axis_across_m
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
