"""The course-loop identifier (``guidance.course_id``) against the eq. (2) fixed-wing of
``plant.step`` flown with a gain and a command delay that guidance does not assume."""

import math
import random
from collections import deque
from dataclasses import replace

import pytest

from app.core.frames import wrap_pi
from app.core.guidance import course_id as cid
from app.core.plant import FixedWingState, VehicleEnvelope, step

W = 0.2  # rad/s
PARAMS = cid.CourseIdParams(W, 1.0)


def _fly(
    k_true: float,
    delay_s: float,
    seconds: float = 120.0,
    seed: int = 1,
    tick_s: float = 0.1,
    jitter: float = 0.0,
    course_noise_rad: float = 0.0,
    lead_rad: float | None = None,
    course0: float = 0.0,
    spin_rad_s: float = 0.0,
    give_rate: bool = False,
) -> list[cid.CourseSample]:
    """Closed loop on ``plant.step`` (0.02 s physics): a controller that assumes k = 1 steers
    a reference course (random sinusoids, plus a steady spin) with the lead of
    ``guidance.course`` (error + reference rate, clamped at W), each command reaching the
    vehicle ``delay_s`` after the tick that sent it and held until the next one. Ticks every
    ``tick_s`` (uniformly jittered by +-``jitter`` of it). ``lead_rad``: command course + this
    instead (a loop driven into saturation). Returns every tick's sample."""
    rng = random.Random(seed)
    env = VehicleEnvelope(15.0, 10.0, 20.0, 2.0, W, k_true)
    amps = [rng.uniform(0.3, 0.8) for _ in range(3)]
    freqs = [rng.uniform(0.05, 0.3) for _ in range(3)]
    phases = [rng.uniform(0.0, math.tau) for _ in range(3)]

    def ref(t: float) -> tuple[float, float]:
        angle = course0 + spin_rad_s * t
        rate = spin_rad_s
        for a, f, p in zip(amps, freqs, phases, strict=True):
            angle += a * math.sin(f * t + p)
            rate += a * f * math.cos(f * t + p)
        return angle, rate

    vehicle = FixedWingState(0.0, 0.0, wrap_pi(course0), 15.0)
    pending: deque[tuple[float, float]] = deque()
    acting = vehicle.course_rad
    samples = []
    dt = 0.02
    t = 0.0
    next_tick = 0.0
    while t < seconds:
        if t >= next_tick - 1e-9:
            measured = wrap_pi(vehicle.course_rad + rng.gauss(0.0, course_noise_rad))
            if lead_rad is not None:
                lead = lead_rad
            else:
                angle, rate = ref(t)
                lead = min(max(wrap_pi(angle - measured) + rate, -W), W)
            command = wrap_pi(measured + lead)
            rate_given = vehicle.course_rate_rad_s if give_rate else None
            samples.append(cid.CourseSample(t, measured, command, rate_given))
            pending.append((t + delay_s, command))
            next_tick = t + tick_s * (1.0 + rng.uniform(-jitter, jitter))
        while pending and pending[0][0] <= t + 1e-9:
            acting = pending.popleft()[1]
        vehicle = step(vehicle, acting, 15.0, env, dt)
        t = round(t + dt, 9)
    return samples


def _identify(
    samples: list[cid.CourseSample], params: cid.CourseIdParams = PARAMS
) -> tuple[cid.CourseIdState, cid.CourseLoopEstimate]:
    state = cid.initial_state()
    for sample in samples:
        state = cid.update(state, sample, params)
    return state, cid.estimate(state, params)


def _effective_gain(k: float, dt_s: float = 0.02) -> float:
    """The gain of the continuous loop that ``plant.step``'s Euler steps of ``dt_s`` amount to:
    each step holds the rate of its start, so an error decays by (1 - k dt) per step."""
    return -math.log(1.0 - k * dt_s) / dt_s


@pytest.mark.parametrize(
    ("k_true", "delay_s"), [(0.55, 0.4), (0.55, 0.0), (1.0, 0.0), (1.6, 0.2), (0.55, 1.0)]
)
def test_gain_and_delay_are_recovered_from_the_closed_loop(k_true: float, delay_s: float) -> None:
    _, est = _identify(_fly(k_true, delay_s, seconds=180.0))
    assert est.ready
    assert est.gain_per_s == pytest.approx(_effective_gain(k_true), rel=0.02)
    assert est.gain_per_s == pytest.approx(k_true, rel=0.1)
    assert est.delay_s == pytest.approx(delay_s, abs=0.1 * max(delay_s, 0.1) + 1e-9)
    assert est.rel_se < PARAMS.max_rel_se


def test_course_noise_and_irregular_ticks_still_give_k_and_delay_within_10_percent() -> None:
    """0.3 deg of course noise (the ~0.07 rad/s of rate noise over one tick the rate window is
    there for), ticks every 0.1 s +-40 %, a delay between two candidates' grid points."""
    samples = _fly(0.55, 0.3, seconds=180.0, jitter=0.4, course_noise_rad=0.005)
    _, est = _identify(samples)
    assert est.ready
    assert est.gain_per_s == pytest.approx(0.55, rel=0.1)
    assert est.delay_s == pytest.approx(0.3, abs=0.03 + 1e-9)


def test_a_rate_measured_by_the_autopilot_can_replace_the_course_difference() -> None:
    _, est = _identify(_fly(0.55, 0.2, seconds=180.0, give_rate=True))
    assert est.ready
    assert est.gain_per_s == pytest.approx(0.55, rel=0.05)
    assert est.delay_s == pytest.approx(0.2, abs=0.05)


def test_a_loop_always_saturated_is_never_ready() -> None:
    """Commanding half a radian ahead all the time: the vehicle turns at W whatever its k, so
    no sample tells k, and none is fitted."""
    state, est = _identify(_fly(0.55, 0.0, lead_rad=0.5))
    assert not est.ready
    assert est.informative_count == 0
    assert state.saturated > 1000
    assert est.gain_per_s == PARAMS.prior_gain_per_s


def _fly_bank_limited(k_true: float, seconds: float = 180.0) -> list[cid.CourseSample]:
    """An autopilot whose turn command saturates at a course error of W / 1 (the ArduPlane
    adapter's bank limit, sized for the k = 1 it assumes) and whose real gain is ``k_true``:
    rate = k_true * clamp(e, -W, W). Commanded errors sweep +-0.5 rad, mostly beyond it."""
    samples, course, t, dt = [], 0.0, 0.0, 0.02
    command = 0.0
    while t < seconds:
        if round(t / 0.1, 6).is_integer():
            command = wrap_pi(course + 0.5 * math.sin(0.4 * t) + 0.1 * math.sin(1.3 * t))
            samples.append(cid.CourseSample(t, course, command))
        error = max(-W, min(W, wrap_pi(command - course)))
        course = wrap_pi(course + k_true * error * dt)
        t = round(t + dt, 9)
    return samples


def test_where_the_autopilots_command_saturates_nothing_beyond_it_is_fitted() -> None:
    """A loop 0.7 times as strong as assumed turns at 0.7 W when its command saturates, under
    the rate test's 0.8 W: fitted, those samples take k for W / e and put it far too low.
    Told where the command saturates, the identifier fits only below it and finds 0.7."""
    samples = _fly_bank_limited(0.7)
    _, blind = _identify(samples)
    state, told = _identify(samples, replace(PARAMS, command_limit_rad=W))
    assert told.ready
    assert told.gain_per_s == pytest.approx(_effective_gain(0.7), rel=0.05)
    assert blind.gain_per_s < 0.8 * told.gain_per_s
    assert state.saturated > 100


def test_a_command_limit_must_be_an_angle() -> None:
    for bad in (0.0, -0.1, 4.0, math.nan):
        with pytest.raises(ValueError, match="command_limit_rad"):
            replace(PARAMS, command_limit_rad=bad)


def test_straight_flight_is_quiet_and_never_ready() -> None:
    state, est = _identify(_fly(0.55, 0.0, lead_rad=0.0, seconds=30.0))
    assert not est.ready
    assert state.quiet > 250
    assert state.informative_count == 0


def test_non_finite_samples_are_dropped_and_counted() -> None:
    samples = _fly(0.55, 0.4, seconds=180.0)
    clean_state, clean = _identify(samples)
    bad = [
        cid.CourseSample(math.nan, 0.0, 0.0),
        cid.CourseSample(1.0, math.inf, 0.0),
        cid.CourseSample(1.0, 0.0, math.nan),
        cid.CourseSample(1.0, 0.0, 0.0, -math.inf),
    ]
    mixed: list[cid.CourseSample] = []
    for i, sample in enumerate(samples):
        mixed.append(sample)
        if i % 50 == 25:
            mixed.append(bad[(i // 50) % len(bad)])
    state, est = _identify(mixed)
    assert state.dropped == len(mixed) - len(samples)
    assert state.dropped > 20
    # a dropped sample leaves no trace: the fit is the clean one
    assert est == clean
    assert replace(state, dropped=0) == clean_state


def test_wrap_around_at_pi_changes_nothing() -> None:
    """The same loop flown with every course shifted by pi (crossing +-pi all the time) and
    spinning through whole turns: the same estimate."""
    base = _identify(_fly(0.55, 0.4, seconds=180.0))[1]
    shifted = _identify(_fly(0.55, 0.4, seconds=180.0, course0=math.pi - 0.01))[1]
    spun = _identify(_fly(0.55, 0.4, seconds=240.0, spin_rad_s=0.08))[1]
    assert shifted.ready
    assert spun.ready
    assert shifted.gain_per_s == pytest.approx(base.gain_per_s, rel=0.02)
    assert shifted.delay_s == base.delay_s
    assert spun.gain_per_s == pytest.approx(_effective_gain(0.55), rel=0.02)
    assert spun.delay_s == pytest.approx(0.4)


def test_no_command_sent_restarts_the_window() -> None:
    """While nothing is sent (the agent holding), what the vehicle does is not ours to fit."""
    samples = _fly(0.55, 0.0, seconds=60.0)
    state = cid.initial_state()
    for sample in samples[:300]:
        state = cid.update(state, sample, PARAMS)
    held = state
    for sample in samples[300:400]:
        state = cid.update(state, replace(sample, command_rad=None), PARAMS)
    assert state.informative_count == held.informative_count
    assert state.commands == ()
    assert state.gaps == held.gaps + 1
    for sample in samples[400:]:
        state = cid.update(state, sample, PARAMS)
    assert state.informative_count > held.informative_count


def test_stale_and_late_ticks_restart_the_rate_baseline() -> None:
    samples = _fly(0.55, 0.0, seconds=20.0)
    state = cid.initial_state()
    for sample in samples[:100]:
        state = cid.update(state, sample, PARAMS)
    before = state.gaps
    state = cid.update(state, samples[50], PARAMS)  # out of order
    assert state.gaps == before + 1
    assert state.window == ()
    late = replace(samples[100], t_s=samples[99].t_s + 5.0)  # a 5 s gap
    state = cid.update(state, late, PARAMS)
    assert state.gaps == before + 2


def test_k_stays_within_its_bounds() -> None:
    """A loop far weaker than the lower bound: k is clamped, and never reported ready."""
    params = replace(PARAMS, min_gain_per_s=0.5)
    _, est = _identify(_fly(0.25, 0.0, seconds=180.0), params)
    assert est.gain_per_s == 0.5
    assert not est.ready


def test_params_are_validated() -> None:
    with pytest.raises(ValueError, match="max_rate_rad_s"):
        cid.CourseIdParams(0.0)
    with pytest.raises(ValueError, match="ascending"):
        cid.CourseIdParams(W, delays_s=(0.0, 0.2, 0.1))
    with pytest.raises(ValueError, match="prior_gain_per_s"):
        cid.CourseIdParams(W, prior_gain_per_s=5.0)
    with pytest.raises(ValueError, match="saturation_fraction"):
        cid.CourseIdParams(W, saturation_fraction=1.5)
    env = VehicleEnvelope(14.0, 10.0, 18.0, 2.0, 0.25, 0.7)
    assert cid.params_for(env) == cid.CourseIdParams(0.25, 0.7)
