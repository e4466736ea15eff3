"""Phase keeping by speed (paper section 4.3, eq. 22-28, generalised to n vehicles) and the
baseline of Frew, Lawrence and Morris (2008); plus the speed-limited lower bound on the time
any speed-based controller needs to space a team.

Phases are the paper's polar angles theta (eq. 1, counter-clockwise from east, about the target)
multiplied by ``orbit_sign`` (+1 counter-clockwise, -1 clockwise), so a phase always grows in the
direction of flight. Plain floats and ``math``: these run every control tick.
"""

import bisect
import functools
import itertools
import math
from collections.abc import Sequence

from app.core.frames import TAU


def orbit_order(phases_rad: Sequence[float]) -> tuple[int, ...]:
    """Vehicle indices in the order they sit around the orbit, starting from vehicle 0 and going
    in the direction of flight (ties keep index order)."""
    if not phases_rad:
        return ()
    ref = phases_rad[0]
    return tuple(sorted(range(len(phases_rad)), key=lambda i: ((phases_rad[i] - ref) % TAU, i)))


def seat_errors(phases_rad: Sequence[float]) -> tuple[float, ...]:
    """Delta theta_i = theta_di - theta_i of the paper's seat law (eq. 22-28), for n vehicles.

    Seats are evenly spaced 2 pi / n apart and assigned in orbit order (vehicle ranked j gets
    seat theta_d1 + 2 pi j / n, eq. 28's theta_d2 = theta_d1 + 2 pi / 3, ...). The paper's choice
    theta_d1 = (theta_1 + theta_2 + theta_3 - 2 pi) / 3 is the mean of the offsets
    o_j = theta_j - 2 pi j / n; it minimises V_p = sum (Delta theta_i)^2 of eq. (22) (the sum of
    |Delta theta_i| of eq. (28) is minimised by their median; for n = 3 the paper gives the mean,
    which is what is implemented). theta_j is unwrapped going round the orbit from vehicle 0
    (in [theta_0, theta_0 + 2 pi)); which vehicle starts the count only shifts every offset by
    the same amount, so the errors do not depend on it. They sum to zero.

    Returns
    -------
    tuple of float
        Delta theta_i in rad for every vehicle, in index order (positive: the seat is ahead,
        speed up).
    """
    n = len(phases_rad)
    if n == 0:
        return ()
    for value in phases_rad:
        if not math.isfinite(value):
            raise ValueError(f"phases must be finite, got {value!r}")
    order = orbit_order(phases_rad)
    ref = phases_rad[order[0]]
    offsets = [0.0] * n
    for rank, i in enumerate(order):
        offsets[i] = (phases_rad[i] - ref) % TAU - TAU * rank / n
    mean = sum(offsets) / n
    return tuple(mean - o for o in offsets)


def neighbour_errors(phases_rad: Sequence[float]) -> tuple[float, ...]:
    """Frew's symmetric phase error for n vehicles: half the difference between the gap ahead
    and the gap behind, (gap_ahead - gap_behind) / 2, rad, in index order.

    For two vehicles (Frew, Lawrence and Morris 2008) this is the phase difference minus pi; for
    n it drives every adjacent gap to 2 pi / n. Positive: the gap ahead is larger, speed up.
    """
    n = len(phases_rad)
    if n < 2:
        return (0.0,) * n
    for value in phases_rad:
        if not math.isfinite(value):
            raise ValueError(f"phases must be finite, got {value!r}")
    order = orbit_order(phases_rad)
    errors = [0.0] * n
    for rank, i in enumerate(order):
        ahead = order[(rank + 1) % n]
        behind = order[(rank - 1) % n]
        gap_ahead = (phases_rad[ahead] - phases_rad[i]) % TAU
        gap_behind = (phases_rad[i] - phases_rad[behind]) % TAU
        errors[i] = 0.5 * (gap_ahead - gap_behind)
    return tuple(errors)


def phase_speed(
    phase_error_rad: float,
    r_m: float,
    radius_m: float,
    cruise_speed_m_s: float,
    gain_per_s: float,
    min_speed_m_s: float,
    max_speed_m_s: float,
    distance_weight: bool = True,
) -> float:
    """Speed command of eq. (27): v = k (r_d / r)^2 Delta theta r_d + v_cruise, within limits.

    The (r_d / r)^2 weight (Frew's) restrains phase keeping far from the target; it is omitted
    with ``distance_weight=False`` (used with predicted phases, which already account for the
    distance). The speed limits are physical, so the command is clamped to them; the
    acceleration limit is the vehicle's speed loop (eq. 2 with an acceleration bound).
    """
    values = (phase_error_rad, r_m, radius_m, cruise_speed_m_s, gain_per_s)
    if not math.isfinite(sum(values)):
        raise ValueError(f"phase_speed inputs must be finite, got {values!r}")
    weight = 1.0
    if distance_weight and r_m > radius_m:
        weight = (radius_m / r_m) ** 2
    v = cruise_speed_m_s + gain_per_s * weight * phase_error_rad * radius_m
    return min(max(v, min_speed_m_s), max_speed_m_s)


def circle_ground_speed_in_wind(wind_m_s: float, radius_m: float, max_rate_rad_s: float) -> float:
    """The fastest constant ground speed g at which a circle of ``radius_m`` can be flown all
    the way round in a steady wind of ``wind_m_s`` with the heading rate at most
    ``max_rate_rad_s``: the circle needs a heading rate g^2 / (r a) where the airspeed a is
    least, downwind (a = g - w), so g^2 - W r g + W r w <= 0, g <= (W r + sqrt((W r)^2 -
    4 W r w)) / 2 (W r in still air). 0 when no constant ground speed flies it (w > W r / 4)."""
    values = (wind_m_s, radius_m, max_rate_rad_s)
    if not (math.isfinite(sum(values)) and wind_m_s >= 0.0 and radius_m > 0.0):
        raise ValueError(f"circle_ground_speed_in_wind needs finite w >= 0, r > 0: {values!r}")
    wr = max_rate_rad_s * radius_m
    disc = wr * wr - 4.0 * wr * wind_m_s
    if wr <= 0.0 or disc < 0.0:
        return 0.0
    return 0.5 * (wr + math.sqrt(disc))


# --------------------------------------------------------------------------------------------
# predicted phase on arrival (improvement over the paper)

# 24-point Gauss-Legendre nodes and weights on [-1, 1]
_GL_NODES = (
    -0.9951872199970213,
    -0.9747285559713095,
    -0.9382745520027328,
    -0.8864155270044011,
    -0.8200019859739029,
    -0.7401241915785544,
    -0.6480936519369755,
    -0.5454214713888396,
    -0.4337935076260451,
    -0.3150426796961634,
    -0.1911188674736163,
    -0.0640568928626056,
    0.0640568928626056,
    0.1911188674736163,
    0.3150426796961634,
    0.4337935076260451,
    0.5454214713888396,
    0.6480936519369755,
    0.7401241915785544,
    0.8200019859739029,
    0.8864155270044011,
    0.9382745520027328,
    0.9747285559713095,
    0.9951872199970213,
)
_GL_WEIGHTS = (
    0.0123412297999872,
    0.0285313886289337,
    0.0442774388174198,
    0.0592985849154368,
    0.0733464814110803,
    0.0861901615319533,
    0.0976186521041139,
    0.1074442701159656,
    0.1155056680537256,
    0.1216704729278034,
    0.1258374563468283,
    0.1279381953467522,
    0.1279381953467522,
    0.1258374563468283,
    0.1216704729278034,
    0.1155056680537256,
    0.1074442701159656,
    0.0976186521041139,
    0.0861901615319533,
    0.0733464814110803,
    0.0592985849154368,
    0.0442774388174198,
    0.0285313886289337,
    0.0123412297999872,
)


def arrival_phase_lead(r_m: float, radius_m: float, c: float) -> float:
    """Phase (rad) a vehicle at distance r gains on a point circling at r_d at the same speed,
    by the time it has joined the circle along the field (eq. 4).

    Along eq. (4), theta_dot - s / r_d over r_dot is g(r) = (sqrt(D) / r_d - c r_d) / (r^2 - r_d^2),
    finite at r_d (-> c / (2 r_d)), so the lead is  Phi(r) = -integral_{r_d}^{r} g(r') dr'
    (negative outside the circle: the vehicle arrives behind where its polar angle suggests).
    Speed cancels. Steering phase on theta + Phi(r) instead of theta lets a team space itself
    while still gathering.

    Phi is tabulated once per (r_d, c) on a geometric grid in |r - r_d| (Gauss-Legendre on each
    cell, memoised: a pure function of its arguments) and interpolated; within 0.1 % of r_d the
    two-term expansion -(c d / (2 r_d) + d^2 / (2 c r_d^2)), d = r - r_d, is used. Beyond the
    table (r > 1000 r_d) g is 1 / r_d to within 1e-6.
    """
    if not (math.isfinite(r_m) and r_m >= 0.0):
        raise ValueError(f"r_m must be finite and >= 0, got {r_m!r}")
    if not (math.isfinite(radius_m) and radius_m > 0.0 and math.isfinite(c) and c > 0.0):
        raise ValueError(f"radius_m and c must be finite and > 0, got {radius_m!r}, {c!r}")
    rd = radius_m
    delta = r_m - rd
    if abs(delta) < 1e-3 * rd:
        # near the circle g(r_d + delta) = c / (2 r_d) + delta / (c r_d^2) + O(delta^2)
        return -(c * delta / (2.0 * rd) + delta * delta / (2.0 * c * rd * rd))
    q = abs(delta) / rd
    inside = delta < 0.0
    grid, outside_values, inside_values = _lead_table(rd, c)
    values = inside_values if inside else outside_values
    if q >= grid[-1]:
        # only outside: far away g = 1 / r_d
        return values[-1] - (q - grid[-1])
    k = bisect.bisect_right(grid, q) - 1
    w = (q - grid[k]) / (grid[k + 1] - grid[k])
    return values[k] + w * (values[k + 1] - values[k])


def _lead_integrand(x: float, rd: float, c: float) -> float:
    x2, rd2 = x * x, rd * rd
    diff = x2 - rd2
    return (math.sqrt(diff * diff + c * c * x2 * rd2) / rd - c * rd) / diff


def _gauss_legendre(a: float, b: float, rd: float, c: float) -> float:
    half, mid = 0.5 * (b - a), 0.5 * (b + a)
    total = 0.0
    for node, weight in zip(_GL_NODES, _GL_WEIGHTS, strict=True):
        total += weight * _lead_integrand(mid + half * node, rd, c)
    return total * half


@functools.lru_cache(maxsize=256)
def _lead_table(
    rd: float, c: float
) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
    """Grid of q = |r - r_d| / r_d (1e-3 .. 1000, ratio 1.15; inside only up to 1) and Phi at
    r_d (1 + q) and r_d (1 - q)."""
    grid = [1e-3]
    while grid[-1] < 1000.0:
        grid.append(grid[-1] * 1.15)
    q0 = grid[0]
    start_out = -(c * q0 * rd / (2.0 * rd) + (q0 * rd) ** 2 / (2.0 * c * rd * rd))
    start_in = -(-c * q0 * rd / (2.0 * rd) + (q0 * rd) ** 2 / (2.0 * c * rd * rd))
    outside = [start_out]
    inside = [start_in]
    for lo, hi in itertools.pairwise(grid):
        outside.append(outside[-1] - _gauss_legendre(rd * (1 + lo), rd * (1 + hi), rd, c))
        if hi <= 1.0:
            # Phi(r) = -integral_{r_d}^{r} g: going inward the integral runs backwards
            inside.append(inside[-1] + _gauss_legendre(rd * (1 - hi), rd * (1 - lo), rd, c))
        else:
            inside.append(inside[-1])
    return tuple(grid), tuple(outside), tuple(inside)


# --------------------------------------------------------------------------------------------
# speed-limited lower bound


def arc_shift_m(
    duration_s: float,
    cruise_speed_m_s: float,
    limit_speed_m_s: float,
    max_accel_m_s2: float,
) -> float:
    """Largest change of distance flown (m) against cruising within ``duration_s``, by a vehicle
    that leaves cruise speed at t = 0 with |a| <= max_accel for a speed limit ``limit_speed_m_s``:
    ramp to the limit, then hold it. (The need to come back to cruise speed is ignored, so the
    bound built on it is a true lower bound.)"""
    if duration_s <= 0.0:
        return 0.0
    dv = abs(limit_speed_m_s - cruise_speed_m_s)
    t_ramp = dv / max_accel_m_s2
    if duration_s >= t_ramp:
        return dv * duration_s - 0.5 * dv * t_ramp
    return 0.5 * max_accel_m_s2 * duration_s * duration_s


def phase_time_lower_bound(
    offsets_rad: Sequence[float],
    radius_m: float,
    cruise_speed_m_s: float,
    min_speed_m_s: float,
    max_speed_m_s: float,
    max_accel_m_s2: float,
    tolerance_rad: float,
) -> float:
    """Shortest time (s) in which speed changes alone can bring every offset within tolerance.

    ``offsets_rad`` are o_j = theta_j - 2 pi j / n (in orbit order, unwrapped) of vehicles that
    all fly the circle r_d (vehicles still outside it move their phase less per metre, so the
    bound holds for them too). A vehicle can move its phase against cruising by at most
    arc_shift(T, max speed) / r_d forward and arc_shift(T, min speed) / r_d backward. Spacing
    needs every adjacent difference within ``tolerance_rad``, which needs the spread of the
    offsets within tolerance * floor(n / 2); the bound is the least T for which some common
    offset is reachable by all, found by bisection. For n <= 3 the spread condition is exact.
    """
    n = len(offsets_rad)
    if n < 2:
        return 0.0
    allowed = tolerance_rad * (n // 2)
    lo_o, hi_o = min(offsets_rad), max(offsets_rad)
    if hi_o - lo_o <= allowed:
        return 0.0

    def feasible(t: float) -> bool:
        fwd = arc_shift_m(t, cruise_speed_m_s, max_speed_m_s, max_accel_m_s2) / radius_m
        back = arc_shift_m(t, cruise_speed_m_s, min_speed_m_s, max_accel_m_s2) / radius_m
        # the laggards move forward by <= fwd, the leaders back by <= back
        return (hi_o - back) - (lo_o + fwd) <= allowed

    lo, hi = 0.0, 1.0
    while not feasible(hi):
        hi *= 2.0
        if hi > 1e7:
            return math.inf
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if feasible(mid):
            hi = mid
        else:
            lo = mid
    return hi
