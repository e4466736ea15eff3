"""Guidance core: closed-form checks, property tests, optimal c, switch rule, course command."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq, minimize_scalar  # type: ignore[import-untyped]

from app.core.frames import wrap_pi
from app.core.guidance import course as gc
from app.core.guidance import field as g
from app.core.guidance import moving_target as gm
from app.core.guidance.course import CourseLoop
from app.core.guidance.field import FieldParams

RD = 300.0
finite_xy = st.floats(min_value=-5000.0, max_value=5000.0, allow_nan=False)
c_values = st.floats(min_value=0.05, max_value=4.0)
signs = st.sampled_from([1, -1])


# ---------------------------------------------------------------- closed form


@pytest.mark.parametrize("sign", [1, -1])
@pytest.mark.parametrize("c", [0.19, 0.7, 2.0, 3.0])
def test_on_the_circle_the_field_is_tangent_at_speed_s(c, sign):
    for theta in np.linspace(0.0, 2.0 * math.pi, 13):
        x, y = RD * math.cos(theta), RD * math.sin(theta)
        vx, vy = g.field_velocity(x, y, RD, c, 20.0, sign)
        assert math.hypot(vx, vy) == pytest.approx(20.0, rel=1e-12)
        assert x * vx + y * vy == pytest.approx(0.0, abs=1e-9)  # no radial part
        assert (x * vy - y * vx) * sign > 0.0  # circulates in the orbit's direction


def test_c_equal_2_is_frews_field():
    # Frew, Lawrence and Morris (2008):
    # v = -s / (r (r^2 + r_d^2)) [x (r^2 - r_d^2) + 2 r r_d y, y (r^2 - r_d^2) - 2 r r_d x]
    for x, y in [(600.0, 600.0), (-50.0, 10.0), (310.0, -4.0), (0.3, 2000.0)]:
        r = math.hypot(x, y)
        k = -20.0 / (r * (r * r + RD * RD))
        frew = (
            k * (x * (r * r - RD * RD) + 2 * r * RD * y),
            k * (y * (r * r - RD * RD) - 2 * r * RD * x),
        )
        assert g.field_velocity(x, y, RD, 2.0, 20.0) == pytest.approx(frew, rel=1e-12, abs=1e-12)


def test_field_matches_eq_8_literally():
    c, s = 0.6, 18.0
    for x, y in [(600.0, 600.0), (-50.0, 10.0), (250.0, -100.0)]:
        r = math.hypot(x, y)
        k = -s / (r * math.sqrt(r**4 + (c * c - 2) * RD * RD * r * r + RD**4))
        eq8 = (
            k * ((r * r - RD * RD) * x + c * r * RD * y),
            k * ((r * r - RD * RD) * y - c * r * RD * x),
        )
        assert g.field_velocity(x, y, RD, c, s) == pytest.approx(eq8, rel=1e-12)
        # eq. (14): the inverse field flips the radial part only
        inv = g.field_velocity(x, y, RD, c, s, inverse=True)
        eq14 = (
            -k * ((r * r - RD * RD) * x - c * r * RD * y),
            -k * ((r * r - RD * RD) * y + c * r * RD * x),
        )
        assert inv == pytest.approx(eq14, rel=1e-12)


@pytest.mark.parametrize("c", [0.19, 0.5, 1.0, 2.0])
def test_eq_11_equals_the_numerical_curvature_of_a_field_line(c):
    """Integrate a field line with RK4 and differentiate its heading along the arc."""
    ds = 0.05
    x, y = 900.0, -200.0
    headings, radii = [], []

    def unit(px, py):
        return g.field_direction(px, py, RD, c)

    for _ in range(30000):
        ux, uy = unit(x, y)
        headings.append(math.atan2(uy, ux))
        radii.append(math.hypot(x, y))
        k1 = unit(x, y)
        k2 = unit(x + 0.5 * ds * k1[0], y + 0.5 * ds * k1[1])
        k3 = unit(x + 0.5 * ds * k2[0], y + 0.5 * ds * k2[1])
        k4 = unit(x + ds * k3[0], y + ds * k3[1])
        x += ds / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        y += ds / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    numeric = np.gradient(np.unwrap(headings), ds)
    for j in range(100, len(radii) - 100, 997):
        assert numeric[j] == pytest.approx(g.curvature(radii[j], RD, c), rel=1e-4, abs=1e-7)


def test_curvature_is_one_over_rd_on_the_circle_for_every_c():
    for c in (0.1, 0.5, 1.0, 2.0, 5.0):
        assert g.curvature(RD, RD, c) == pytest.approx(1.0 / RD, rel=1e-12)


def test_eq_10_reduces_to_eq_11_and_has_the_c_dot_term():
    assert g.curvature(500.0, RD, 0.4, c_rate_per_s=0.0) == g.curvature(500.0, RD, 0.4)
    # on the circle r^2 - r_d^2 = 0, so c_dot does not matter there
    assert g.curvature(RD, RD, 0.4, 0.3, 20.0) == pytest.approx(1.0 / RD)
    assert g.curvature(500.0, RD, 0.4, 0.01, 20.0) < g.curvature(500.0, RD, 0.4)


def test_field_course_rate_along_the_field_is_speed_times_curvature():
    s = 20.0
    for c in (0.19, 0.8, 2.0):
        for x, y in [(700.0, 100.0), (320.0, -50.0), (-30.0, 410.0)]:
            vx, vy = g.field_velocity(x, y, RD, c, s)
            course, rate = g.field_course(x, y, vx, vy, FieldParams(RD, c))
            assert course == pytest.approx(math.atan2(vx, vy))
            # course is clockwise, curvature counter-clockwise positive
            assert -rate == pytest.approx(s * g.curvature(math.hypot(x, y), RD, c), rel=1e-9)


def test_the_centre_is_handled_explicitly():
    assert g.field_direction(0.0, 0.0, RD, 0.5) == (1.0, 0.0)
    course, rate = g.field_course(0.0, 0.0, 3.0, 4.0, FieldParams(RD, 0.5))
    assert course == pytest.approx(math.atan2(3.0, 4.0))
    assert rate == 0.0
    # just off the centre the field points outward
    ux, _ = g.field_direction(1e-3, 0.0, RD, 0.5)
    assert ux > 0.99
    assert g.field_polar_rates(0.0, RD, 0.5, 20.0) == pytest.approx((20.0, 0.0))


@pytest.mark.parametrize(
    "args",
    [(math.nan, 0.0, RD, 1.0), (0.0, math.inf, RD, 1.0), (1.0, 1.0, -RD, 1.0), (1.0, 1.0, RD, 0.0)],
)
def test_bad_input_is_rejected(args):
    with pytest.raises(ValueError):
        g.field_direction(*args)


def test_bad_input_is_rejected_everywhere():
    with pytest.raises(ValueError, match="speed_m_s"):
        g.optimal_c(RD, math.nan, 0.2)
    with pytest.raises(ValueError, match="course_rad"):
        gc.course_command(math.inf, 0.0, 0.0, CourseLoop(1.0, 0.2))
    with pytest.raises(ValueError, match="r_m"):
        g.curvature(-1.0, RD, 1.0)


# ---------------------------------------------------------------- properties


@settings(max_examples=300, deadline=None)
@given(finite_xy, finite_xy, c_values, signs, st.booleans())
def test_field_magnitude_is_s_away_from_the_centre(x, y, c, sign, inverse):
    if math.hypot(x, y) < 1e-3:
        return
    vx, vy = g.field_velocity(x, y, RD, c, 17.0, sign, inverse)
    assert math.hypot(vx, vy) == pytest.approx(17.0, rel=1e-9)


@settings(max_examples=300, deadline=None)
@given(finite_xy, finite_xy, st.floats(min_value=-math.pi, max_value=math.pi), c_values, signs)
def test_rotating_the_input_rotates_the_output(x, y, angle, c, sign):
    if math.hypot(x, y) < 1e-3:
        return
    ca, sa = math.cos(angle), math.sin(angle)
    vx, vy = g.field_velocity(x, y, RD, c, 20.0, sign)
    rx, ry = g.field_velocity(ca * x - sa * y, sa * x + ca * y, RD, c, 20.0, sign)
    assert (rx, ry) == pytest.approx((ca * vx - sa * vy, sa * vx + ca * vy), abs=1e-9)


@settings(max_examples=300, deadline=None)
@given(finite_xy, finite_xy, c_values, signs)
def test_lyapunov_function_never_increases_along_the_field(x, y, c, sign):
    """V = (r^2 - r_d^2)^2: dV/dt = 4 (r^2 - r_d^2) (x vx + y vy) <= 0, and over a step too."""
    if math.hypot(x, y) < 1e-3:
        return
    vx, vy = g.field_velocity(x, y, RD, c, 20.0, sign)
    r2 = x * x + y * y
    assert 4.0 * (r2 - RD * RD) * (x * vx + y * vy) <= 1e-9 * max(1.0, r2 * r2)
    v0 = (r2 - RD * RD) ** 2
    dt = 0.01
    x1, y1 = x + vx * dt, y + vy * dt
    ux, uy = g.field_velocity(x1, y1, RD, c, 20.0, sign)
    x2, y2 = x + 0.5 * dt * (vx + ux), y + 0.5 * dt * (vy + uy)  # Heun step
    v1 = (x2 * x2 + y2 * y2 - RD * RD) ** 2
    assert v1 <= v0 + 1e-6 * max(1.0, v0) + 1e-3


@settings(max_examples=200, deadline=None)
@given(finite_xy, finite_xy, c_values)
def test_clockwise_orbit_is_the_mirror_image(x, y, c):
    if math.hypot(x, y) < 1e-3:
        return
    vx, vy = g.field_velocity(x, y, RD, c, 20.0, 1)
    mx, my = g.field_velocity(x, -y, RD, c, 20.0, -1)
    assert (mx, my) == pytest.approx((vx, -vy), abs=1e-9)


# ---------------------------------------------------------------- optimal c


def _exact_optimal_c(rd, s, w):
    """Independent: numerical max of |eq. 11| over r >= r_d, root in c by Brent."""

    def peak(c):
        res = minimize_scalar(
            lambda lr: -abs(g.curvature(rd * math.exp(lr), rd, c)),
            bounds=(0.0, 4.0),
            method="bounded",
            options={"xatol": 1e-12},
        )
        grid = [abs(g.curvature(rd * math.exp(lr), rd, c)) for lr in np.linspace(0, 4, 4001)]
        return max(-res.fun, max(grid))

    return brentq(lambda c: peak(c) - w / s, 0.02, 1.4, xtol=1e-12)


@pytest.mark.parametrize(("rd", "s", "w"), [(300.0, 20.0, 0.2), (90.0, 14.0, 0.2)])
def test_optimal_c_agrees_with_the_exact_root(rd, s, w):
    c = g.optimal_c(rd, s, w)
    assert c == pytest.approx(_exact_optimal_c(rd, s, w), abs=1e-3)
    peak, where = g.peak_curvature(rd, c)
    assert peak == pytest.approx(w / s, rel=1e-9)
    assert where > rd


def test_peak_curvature_closed_form_matches_a_dense_grid():
    for c in (0.1, 0.19, 0.5, 1.0, 1.3, 1.5, 2.0):
        r = RD * np.exp(np.linspace(0.0, 5.0, 200001))
        grid = max(abs(g.curvature(float(x), RD, c)) for x in r[::20])
        assert g.peak_curvature(RD, c)[0] == pytest.approx(grid, rel=1e-5)


def test_optimal_c_is_smaller_for_a_more_agile_vehicle_and_larger_for_a_faster_one():
    base = g.optimal_c(300.0, 20.0, 0.2)
    assert g.optimal_c(300.0, 20.0, 0.4) < base < g.optimal_c(300.0, 25.0, 0.2)
    assert g.optimal_c(300.0, 20.0, 0.2, curvature_margin=0.9) > base


def test_optimal_c_when_the_circle_itself_is_too_tight():
    # 25 m/s on 90 m needs 0.28 rad/s > 0.2: the best c asks exactly what the circle asks
    c = g.optimal_c(90.0, 25.0, 0.2)
    assert g.peak_curvature(90.0, c)[0] == pytest.approx(1.0 / 90.0, rel=1e-9)
    assert g.peak_curvature(90.0, c * 0.99)[0] > 1.0 / 90.0


# ---------------------------------------------------------------- course command


def test_feed_forward_course_error_decays_at_rate_k():
    k, w = 1.0, 0.2
    course, field_course, field_rate = 0.3, 0.35, -0.05
    cmd = gc.course_command(course, field_course, field_rate, CourseLoop(k, w))
    rate = k * wrap_pi(cmd - course)
    # de/dt = field_rate - rate = -k e
    assert field_rate - rate == pytest.approx(-k * (field_course - course))
    plain = gc.course_command(
        course, field_course, field_rate, CourseLoop(k, w, feed_forward=False)
    )
    assert plain == pytest.approx(field_course)


def test_course_command_implied_rate_is_within_the_limit_and_turns_the_short_way():
    k, w = 1.0, 0.2
    cmd = gc.course_command(0.0, 3.0, 0.1, CourseLoop(k, w))
    assert cmd == pytest.approx(w / k)
    cmd = gc.course_command(0.0, -3.0, 0.0, CourseLoop(k, w))
    assert cmd == pytest.approx(-w / k)


# ---------------------------------------------------------------- inverse-field switch


def test_switch_rule_hysteresis():
    assert gc.inverse_field_wanted(False, -0.1)
    assert not gc.inverse_field_wanted(False, 0.2)
    assert gc.inverse_field_wanted(True, 0.2)  # not yet far enough to go back
    assert not gc.inverse_field_wanted(True, 0.6)


def test_prediction_sees_the_crossing_of_simulation_b_and_not_of_simulation_a():
    loop = CourseLoop(1.0, 0.2)
    c = g.optimal_c(300.0, 18.0, 0.2)
    # sim-b: 300 m east, 300 m north, heading south at 18 m/s
    # (the prediction stops as soon as it is inside, so it is only known to be negative)
    assert (
        gc.predict_min_distance_error(300.0, 300.0, math.pi, 18.0, FieldParams(300.0, c), loop)
        < 0.0
    )
    # sim-a: 600, 600 heading at the target: joins without crossing
    assert (
        gc.predict_min_distance_error(
            600.0, 600.0, -0.75 * math.pi, 18.0, FieldParams(300.0, c), loop
        )
        > -0.5
    )
    # Frew's field from sim-b crosses too (the paper's Fig. 11)
    assert (
        gc.predict_min_distance_error(300.0, 300.0, math.pi, 18.0, FieldParams(300.0, 2.0), loop)
        < 0.0
    )


# ---------------------------------------------------------------- moving target (eq. 15)


@settings(max_examples=300, deadline=None)
@given(
    st.floats(min_value=-math.pi, max_value=math.pi),
    st.floats(min_value=-12.0, max_value=12.0),
    st.floats(min_value=-12.0, max_value=12.0),
    st.floats(min_value=13.0, max_value=25.0),
    st.booleans(),
)
def test_moving_target_velocity_is_within_limits(angle, tx, ty, s, relative):
    dx, dy = math.sin(angle), math.cos(angle)
    gx, gy, lam, held = gm.moving_target_velocity(dx, dy, tx, ty, s, 13.0, 25.0, relative)
    speed = math.hypot(gx, gy)
    assert 13.0 - 1e-9 <= speed <= 25.0 + 1e-9
    assert lam >= 0.0
    if math.hypot(tx, ty) < 13.0:  # always feasible
        # the relative velocity v_g - v_t is along the field
        assert (gx - tx) * dy - (gy - ty) * dx == pytest.approx(0.0, abs=1e-9)
        if not relative:
            assert speed == pytest.approx(s, rel=1e-9)
            assert held
        elif not held:
            assert lam == s  # eq. (15) with lambda = s: the speed relative to the target is s


def test_moving_target_relative_speed_is_eq_15():
    # target 5 m/s east, field due north: v_g = (5, 20) within limits, lambda = 20
    gx, gy, lam, held = gm.moving_target_velocity(0.0, 1.0, 5.0, 0.0, 20.0, 13.0, 25.0)
    assert (gx, gy, lam, held) == pytest.approx((5.0, 20.0, 20.0, False))
    # target 10 m/s along the field: 30 m/s would break the limit, so |v_g| = 25
    gx, gy, lam, held = gm.moving_target_velocity(0.0, 1.0, 0.0, 10.0, 20.0, 13.0, 25.0)
    assert (gx, gy, lam, held) == pytest.approx((0.0, 25.0, 15.0, True))
    # Frew's choice: the ground speed is 20
    gx, gy, _, _ = gm.moving_target_velocity(0.0, 1.0, 5.0, 0.0, 20.0, 13.0, 25.0, False)
    assert (gx, gy) == pytest.approx((5.0, math.sqrt(375.0)))


def test_stationary_target_gives_the_field_itself():
    for relative in (True, False):
        gx, gy, lam, _ = gm.moving_target_velocity(0.6, 0.8, 0.0, 0.0, 20.0, 13.0, 25.0, relative)
        assert (gx, gy, lam) == pytest.approx((12.0, 16.0, 20.0))
