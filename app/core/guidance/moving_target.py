"""The moving-target correction of eq. (15): the ground velocity that flies the field in the
target's frame, within the vehicle's speed limits."""

import math

from app.core.guidance.field import check_finite


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
    check_finite(
        rel_dir_east=rel_dir_east,
        rel_dir_north=rel_dir_north,
        target_v_east_m_s=target_v_east_m_s,
        target_v_north_m_s=target_v_north_m_s,
        speed_m_s=speed_m_s,
    )
    if not 0.0 < min_speed_m_s <= max_speed_m_s:
        raise ValueError("need 0 < min_speed_m_s <= max_speed_m_s")
    return moving_target_velocity_unchecked(
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


def moving_target_velocity_unchecked(
    dx: float,
    dy: float,
    tx: float,
    ty: float,
    s: float,
    s_min: float,
    s_max: float,
    relative: bool = True,
) -> tuple[float, float, float, bool]:
    """``moving_target_velocity`` without its checks, for the control tick."""
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
