"""Phase keeping: the paper's seat law for n vehicles, Frew's neighbour law, the bound."""

import math

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from app.core import phase
from app.core.frames import TAU
from app.core.guidance import field

angles = st.floats(min_value=-10.0, max_value=10.0, allow_nan=False)


def test_seat_law_for_three_is_the_papers_formula():
    th = [0.1, 0.9, 2.0]  # counter-clockwise order
    errors = phase.seat_errors(th)
    theta_d1 = (th[0] + th[1] + th[2] - TAU) / 3.0  # eq. (28)'s choice
    expected = [theta_d1 - th[0], theta_d1 + TAU / 3 - th[1], theta_d1 + 2 * TAU / 3 - th[2]]
    assert errors == pytest.approx(expected)


def test_phase_scenario_seat_errors():
    th = [math.radians(a) for a in (0.0, 30.0, 50.0)]
    errors = [math.degrees(e) for e in phase.seat_errors(th)]
    # offsets 0, -90, -190 deg: mean -93.3 -> vehicle 0 drops back, vehicle 2 moves up
    assert errors == pytest.approx([-93.333, -3.333, 96.667], abs=1e-3)


@settings(max_examples=200, deadline=None)
@given(st.lists(angles, min_size=1, max_size=7), angles)
def test_seat_errors_sum_to_zero_and_ignore_a_common_rotation(th, shift):
    # two vehicles at the same phase may take their seats either way round: keep them apart
    gaps = [abs(math.remainder(a - b, TAU)) for i, a in enumerate(th) for b in th[:i]]
    assume(all(gap > 1e-6 for gap in gaps))
    errors = phase.seat_errors(th)
    assert sum(errors) == pytest.approx(0.0, abs=1e-9)
    shifted = phase.seat_errors([t + shift for t in th])
    assert shifted == pytest.approx(errors, abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.integers(min_value=1, max_value=8), angles, st.permutations(list(range(8))))
def test_evenly_spaced_vehicles_need_no_correction_in_any_index_order(n, start, perm):
    order = [p for p in perm if p < n]
    th = [0.0] * n
    for rank, i in enumerate(order):
        th[i] = start + TAU * rank / n
    assert phase.seat_errors(th) == pytest.approx([0.0] * n, abs=1e-9)
    assert phase.neighbour_errors(th) == pytest.approx([0.0] * n, abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.lists(angles, min_size=2, max_size=6))
def test_neighbour_errors_sum_to_zero(th):
    assert sum(phase.neighbour_errors(th)) == pytest.approx(0.0, abs=1e-9)


def test_for_three_vehicles_frews_neighbour_law_is_the_seat_law_times_1_5():
    th = [0.3, 1.1, 2.9]
    seat = phase.seat_errors(th)
    frew = phase.neighbour_errors(th)
    assert frew == pytest.approx([1.5 * e for e in seat])


@settings(max_examples=300, deadline=None)
@given(
    st.floats(min_value=-20.0, max_value=20.0),
    st.floats(min_value=0.0, max_value=5000.0),
    st.floats(min_value=0.0, max_value=5.0),
    st.booleans(),
)
def test_phase_speed_is_within_the_limits(error, r, gain, weighted):
    v = phase.phase_speed(error, r, 400.0, 20.0, gain, 13.0, 25.0, weighted)
    assert 13.0 <= v <= 25.0


def test_phase_speed_is_eq_27():
    v = phase.phase_speed(0.01, 800.0, 400.0, 20.0, 0.1, 13.0, 25.0)
    assert v == pytest.approx(20.0 + 0.1 * 0.25 * 0.01 * 400.0)
    assert phase.phase_speed(0.01, 800.0, 400.0, 20.0, 0.1, 13.0, 25.0, False) == pytest.approx(
        20.4
    )


def test_bad_phases_are_rejected():
    with pytest.raises(ValueError, match="finite"):
        phase.seat_errors([0.0, math.nan])
    with pytest.raises(ValueError, match="finite"):
        phase.phase_speed(math.inf, 400.0, 400.0, 20.0, 0.1, 13.0, 25.0)


def test_speed_limited_bound_for_the_phase_scenario():
    offsets = [0.0, math.radians(-90.0), math.radians(-190.0)]
    bound = phase.phase_time_lower_bound(offsets, 400.0, 20.0, 13.0, 25.0, 2.0, math.radians(2.0))
    # closing 188 deg of arc at 400 m needs 12 T - 18.5 >= 1312.4 m
    assert bound == pytest.approx((math.radians(188.0) * 400.0 + 18.5) / 12.0, rel=1e-6)
    assert phase.phase_time_lower_bound([0.0, 0.01], 400.0, 20, 13, 25, 2, 0.02) == 0.0


def test_arc_shift_ramps_then_holds():
    assert phase.arc_shift_m(1.0, 20.0, 25.0, 2.0) == pytest.approx(1.0)  # a t^2 / 2
    assert phase.arc_shift_m(10.0, 20.0, 25.0, 2.0) == pytest.approx(5.0 * 10.0 - 6.25)


def test_arrival_phase_lead_matches_flying_the_field():
    """Fly eq. (4) from r0 and compare theta - s t / r_d at the circle with Phi(r0)."""
    rd, s, c = 400.0, 20.0, field.optimal_c(400.0, 20.0, 0.2)
    r0 = 1500.0
    r, theta, t, dt = r0, 0.0, 0.0, 0.005
    while r - rd > 1e-3:
        r_dot, _ = field.field_polar_rates(r, rd, c, s)
        # midpoint step
        rm = r + 0.5 * dt * r_dot
        r_dot_m, rtd_m = field.field_polar_rates(rm, rd, c, s)
        r += dt * r_dot_m
        theta += dt * rtd_m / rm
        t += dt
    lead = theta - s * t / rd
    assert phase.arrival_phase_lead(r0, rd, c) == pytest.approx(lead, abs=2e-3)
    assert phase.arrival_phase_lead(rd, rd, c) == 0.0
    assert phase.arrival_phase_lead(600.0, rd, c) < 0.0


def test_the_circle_ground_speed_in_wind_is_where_the_downwind_turn_reaches_the_limit():
    circle_ground_speed_in_wind = phase.circle_ground_speed_in_wind
    assert circle_ground_speed_in_wind(0.0, 90.0, 0.2) == pytest.approx(18.0)  # W r
    for w in (0.5, 1.5, 3.0, 4.4):
        g = circle_ground_speed_in_wind(w, 90.0, 0.2)
        # downwind the airspeed is g - w, and the heading rate g^2 / (r a) is at the limit
        assert g**2 / (90.0 * (g - w)) == pytest.approx(0.2)
        # a little slower is flyable all round (the rate is largest downwind)
        h = g - 0.1
        airspeeds = (
            math.sqrt(h * h + w * w - 2.0 * h * w * math.cos(math.radians(a))) for a in range(181)
        )
        assert max(h * h / (90.0 * a) for a in airspeeds) < 0.2
    assert circle_ground_speed_in_wind(3.0, 90.0, 0.2) == pytest.approx(14.2, abs=0.05)
    assert circle_ground_speed_in_wind(4.6, 90.0, 0.2) == 0.0  # beyond W r / 4: none
    with pytest.raises(ValueError):
        circle_ground_speed_in_wind(math.nan, 90.0, 0.2)
    with pytest.raises(ValueError):
        circle_ground_speed_in_wind(-1.0, 90.0, 0.2)
