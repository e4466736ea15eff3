"""The autopilot's course loop identified in flight: gain k (1/s) and pure delay (s) of eq. (2).

Guidance assumes the autopilot turns at k * wrap(command - course), saturated at W
(``guidance.course.course_command``). Real autopilots differ (ArduPlane GUIDED with stock
``GUIDED_P``: k about 0.5-0.6 /s and some lag), and with k wrong the lead compensation
(field rate / k) and the clamp (W / k) are wrong. This module fits, from each control tick's
(time, measured course, course command sent), the model

    rate(t) = k * wrap(command(t - d) - course(t))                          (eq. 2, delayed)

where ``command`` is what was sent, held until the next one (zero-order hold), and d one of a
small set of candidate delays. For every candidate the fit is a scalar recursive least squares
with exponential forgetting (the weighted sums S_xx, S_xy, S_yy of regressor and rate, decayed
by exp(-dt / memory_s) per informative sample of dt seconds: the estimate remembers the last
``memory_s`` seconds of informative flight); the delay is the candidate with the smallest
residual (a neighbour must fit clearly better to be taken), k its slope.

Samples and which are used:

- The measured rate is the course's turn over the last ``rate_window_s`` (at least one tick
  interval) divided by its duration, and the regressor the mean over the same span of
  wrap(command(s - d) - course(s)), with the course interpolated linearly between ticks and
  the command history held piecewise constant: exact for irregular tick times and for a delay
  that is not a multiple of the tick. The window keeps the course's noise from dominating the
  rate at 10 Hz (0.3 deg of course noise is 0.07 rad/s of rate over one 0.1 s tick); with
  ticks longer than the window the rate is one interval's. A rate measured by the autopilot
  may be given instead (``CourseSample``); then the regressor is taken at the tick itself.
- A sample is informative when the loop cannot have been saturated and the error is large
  enough for noise not to dominate: |rate| < ``saturation_fraction`` W,
  |k_check * e| < ``saturation_fraction`` W for every candidate delay and every interval of
  the window (k_check: the estimate once ready, else the lower bound of k: a saturated loop
  turns at W whatever its k, so the rate test is what rejects saturation; the prior would
  also reject a weaker loop flown at the prior's clamp W / k_prior, where such a loop is not
  saturated and most informative) and |e| >= ``min_error_rad``; and, where the autopilot's
  own turn command saturates at a course error whatever the loop's gain
  (``command_limit_rad``: the ArduPlane adapter's bank limit is reached at e = W / k_assumed),
  |e| < that for every candidate delay and interval (no margin: below it the command is not
  saturated, and a margin would leave out the steady orbit, where the lead sits just under
  it; in the simulator's ArduPlane 0.8 of it found k only late, at 1.7-2.1 /s). Without that
  test a loop weaker than the adapter assumes (0.7 rad/s where 1 was assumed) turns at less
  than W in that saturation, passes the rate test, and is identified at W / e, lower than it
  is: flown with that k the course command asks for still larger errors, more of them
  saturated, and the estimate runs down (real ArduPlane 4.6.2 SITL: 0.87 -> 0.36 /s over a
  mission, with the demanded bank at its limit half the time).
  The others are counted (``saturated``, ``quiet``).
- A non-finite sample is dropped and counted; a tick not later than the last one, a gap longer
  than ``max_gap_s`` or a tick with no command sent (``command_rad`` None: the vehicle flies
  something else) restarts the window (counted in ``gaps``).

Linear interpolation of the course makes k a little low when k times the tick interval is not
small: by (k dt)^2 / 12, 0.03 % at 10 Hz and k = 0.55 /s, 2.5 % at 1 Hz.

The estimate is ready once ``min_informative_s`` seconds of informative samples have been fitted
and k's relative standard error is below ``max_rel_se``; k is kept within [``min_gain_per_s``,
``max_gain_per_s``]. Pure: ``update`` returns a new state.
"""

import bisect
import itertools
import math
from dataclasses import dataclass
from typing import Any

from app.core.frames import wrap_pi
from app.core.plant import VehicleEnvelope
from app.core.values import replace

_MIN_GAIN, _MAX_GAIN = 0.2, 3.0  # 1/s: the default bounds of k
_DEFAULT_DELAYS_S = tuple(round(0.1 * i, 1) for i in range(11))
_SSE_FLOOR = 1e-9  # of S_yy: residual differences below this are rounding, not fit


@dataclass(frozen=True, slots=True)
class CourseIdParams:
    """How the course loop is identified.

    ``max_rate_rad_s``: W, the course-rate limit (rad/s); ``prior_gain_per_s``: the k assumed
    until the estimate is ready (1/s); ``delays_s``: the candidate delays (s, ascending, >= 0);
    ``memory_s``: the forgetting time constant in informative seconds; ``rate_window_s``: the
    span the rate is measured over; ``min_error_rad``, ``saturation_fraction``: which samples
    are informative (module docstring); ``min_informative_s`` and ``max_rel_se``: when the
    estimate is ready; ``max_gap_s``: the longest tick interval a rate is measured across;
    ``delay_switch_ratio``: a new delay is taken only when its residual is below this fraction
    of the current delay's (no chatter between neighbours that fit alike);
    ``command_limit_rad``: the course error at which the autopilot's own turn command
    saturates whatever the loop's gain (None: none known; module docstring).
    """

    max_rate_rad_s: float
    prior_gain_per_s: float = 1.0
    delays_s: tuple[float, ...] = _DEFAULT_DELAYS_S
    memory_s: float = 60.0
    rate_window_s: float = 0.5
    min_error_rad: float = 0.02
    saturation_fraction: float = 0.8
    min_gain_per_s: float = _MIN_GAIN
    max_gain_per_s: float = _MAX_GAIN
    min_informative_s: float = 10.0
    max_rel_se: float = 0.05
    max_gap_s: float = 2.0
    delay_switch_ratio: float = 0.9
    command_limit_rad: float | None = None

    def __post_init__(self) -> None:
        for name in ("max_rate_rad_s", "memory_s", "min_informative_s", "max_gap_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"CourseIdParams.{name} must be finite and > 0, got {value!r}")
        if not (math.isfinite(self.rate_window_s) and self.rate_window_s >= 0.0):
            raise ValueError(
                f"CourseIdParams.rate_window_s must be finite and >= 0, got {self.rate_window_s!r}"
            )
        if not (0.0 < self.min_gain_per_s < self.max_gain_per_s < math.inf):
            raise ValueError(
                "CourseIdParams needs 0 < min_gain_per_s < max_gain_per_s (finite), got "
                f"{self.min_gain_per_s!r}, {self.max_gain_per_s!r}"
            )
        if not (self.min_gain_per_s <= self.prior_gain_per_s <= self.max_gain_per_s):
            raise ValueError(
                f"CourseIdParams.prior_gain_per_s {self.prior_gain_per_s!r} is outside "
                f"[{self.min_gain_per_s}, {self.max_gain_per_s}]"
            )
        d = self.delays_s
        if not d or any(not (math.isfinite(x) and x >= 0.0) for x in d):
            raise ValueError(f"CourseIdParams.delays_s must be finite and >= 0, got {d!r}")
        if any(b <= a for a, b in itertools.pairwise(d)):
            raise ValueError(f"CourseIdParams.delays_s must be strictly ascending, got {d!r}")
        if not (math.isfinite(self.min_error_rad) and 0.0 <= self.min_error_rad < math.pi):
            raise ValueError(
                f"CourseIdParams.min_error_rad must be in [0, pi), got {self.min_error_rad!r}"
            )
        limit = self.command_limit_rad
        if limit is not None and not (math.isfinite(limit) and 0.0 < limit <= math.pi):
            raise ValueError(
                f"CourseIdParams.command_limit_rad must be in (0, pi] or None, got {limit!r}"
            )
        for name in ("saturation_fraction", "max_rel_se", "delay_switch_ratio"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 < value <= 1.0):
                raise ValueError(f"CourseIdParams.{name} must be in (0, 1], got {value!r}")


def params_for(envelope: VehicleEnvelope) -> CourseIdParams:
    """Identification for a vehicle of this envelope: W its course-rate limit, the prior its
    assumed k (clamped into the default gain bounds); change the rest with ``replace``."""
    prior = min(max(envelope.course_gain_per_s, _MIN_GAIN), _MAX_GAIN)
    return CourseIdParams(envelope.max_course_rate_rad_s, prior)


@dataclass(frozen=True, slots=True)
class CourseSample:
    """One control tick: telemetry time ``t_s``, measured ``course_rad`` (clockwise from north)
    and the ``command_rad`` sent on it (None: nothing was sent, e.g. while holding). A measured
    ``course_rate_rad_s`` (rad/s, positive clockwise) replaces the one from the courses."""

    t_s: float
    course_rad: float
    command_rad: float | None
    course_rate_rad_s: float | None = None


@dataclass(frozen=True, slots=True)
class _Fit:
    """The forgetting least-squares sums of one candidate delay (rate = k * regressor)."""

    sxx: float = 0.0
    sxy: float = 0.0
    syy: float = 0.0

    def sse(self) -> float:
        return max(self.syy - self.sxy * self.sxy / self.sxx, 0.0) if self.sxx > 0.0 else math.inf


@dataclass(frozen=True, slots=True)
class _Interval:
    """One tick interval: its duration (s), the course's turn (rad), the mean error of every
    candidate delay times the duration (rad s) and the largest error in magnitude (rad)."""

    dt_s: float
    turn_rad: float
    weighted: tuple[float, ...]
    peak_rad: float


@dataclass(frozen=True, slots=True)
class CourseIdState:
    """What the identifier remembers.

    ``commands``: the recent (t_s, command) history, newest last; ``last``: the previous tick's
    (t_s, course); ``window``: the tick intervals the rate is measured over; ``fits``: one per
    candidate delay; ``informative_s`` the forgotten weight (s) of the informative samples,
    ``effective_n`` their forgotten number and ``informative_count`` their total number;
    ``delay_index`` the chosen candidate; counters of what was left out: ``dropped``
    (non-finite), ``saturated``, ``quiet`` (error too small), ``gaps`` (window restarted).
    """

    commands: tuple[tuple[float, float], ...] = ()
    last: tuple[float, float] | None = None
    window: tuple[_Interval, ...] = ()
    fits: tuple[_Fit, ...] = ()
    informative_s: float = 0.0
    effective_n: float = 0.0
    informative_count: int = 0
    delay_index: int = 0
    dropped: int = 0
    saturated: int = 0
    quiet: int = 0
    gaps: int = 0


@dataclass(frozen=True, slots=True)
class CourseLoopEstimate:
    """The identified loop: gain k (1/s, within the bounds), delay (s), k's relative standard
    error, the informative seconds and samples it rests on, and whether it is ready."""

    gain_per_s: float
    delay_s: float
    rel_se: float
    informative_s: float
    informative_count: int
    ready: bool


def initial_state() -> CourseIdState:
    return CourseIdState()


def estimate(state: CourseIdState, params: CourseIdParams) -> CourseLoopEstimate:
    """The current estimate (the prior k and delay 0, not ready, before two informative
    samples)."""
    if not state.fits or state.informative_count < 2:
        k0, s_inf, n = params.prior_gain_per_s, state.informative_s, state.informative_count
        return CourseLoopEstimate(k0, 0.0, math.inf, s_inf, n, False)
    i = state.delay_index
    fit = state.fits[i]
    k_raw = fit.sxy / fit.sxx
    k = min(max(k_raw, params.min_gain_per_s), params.max_gain_per_s)
    # the slope's standard error, SSE / ((n - 1) S_xx), over the forgotten number of samples
    n_eff = state.effective_n
    rel_se = math.sqrt(fit.sse() / ((n_eff - 1.0) * fit.sxx)) / k if n_eff > 1.0 else math.inf
    ready = (
        state.informative_s >= params.min_informative_s
        and rel_se <= params.max_rel_se
        and params.min_gain_per_s <= k_raw <= params.max_gain_per_s
    )
    return CourseLoopEstimate(
        k, params.delays_s[i], rel_se, state.informative_s, state.informative_count, ready
    )


def update(state: CourseIdState, sample: CourseSample, params: CourseIdParams) -> CourseIdState:
    """Fold one control tick in (see the module docstring); never raises on bad numbers."""
    t, chi, cmd = sample.t_s, sample.course_rad, sample.command_rad
    given_rate = sample.course_rate_rad_s
    total = t + chi + (0.0 if cmd is None else cmd) + (0.0 if given_rate is None else given_rate)
    if not math.isfinite(total):  # a sum of finite floats is finite (short of overflow)
        return replace(state, dropped=state.dropped + 1)
    chi = wrap_pi(chi)
    if cmd is None:  # nothing sent: what acts now is not ours, forget the history
        restarted = state.gaps + (1 if state.commands else 0)
        return replace(state, commands=(), last=(t, chi), window=(), gaps=restarted)
    changes = _fold(state, t, chi, given_rate, params)
    horizon = t - params.delays_s[-1] - params.max_gap_s  # the next interval's reach
    commands = state.commands
    if commands and commands[0][0] < horizon:
        # keep the newest command older than the horizon: it still holds at the horizon
        j = bisect.bisect_left(commands, horizon, key=_sent_at) - 1
        commands = commands[j:]
    changes["commands"] = (*commands, (t, wrap_pi(cmd)))
    changes["last"] = (t, chi)
    return replace(state, **changes)


def _fold(
    state: CourseIdState, t: float, chi: float, given_rate: float | None, params: CourseIdParams
) -> dict[str, Any]:
    """The state's changes: the window extended by the interval ending at this tick, and the
    window's sample fitted when it is informative."""
    if state.last is None or not state.commands:
        return {}
    t0, chi0 = state.last
    dt = t - t0
    if not (0.0 < dt <= params.max_gap_s):
        return {"window": (), "gaps": state.gaps + 1}
    turn = wrap_pi(chi - chi0)
    commands = state.commands
    times = [c[0] + 1e-9 for c in commands]  # sent at or before a time: acting then
    errors = []
    for d in params.delays_s:
        if given_rate is None:
            x = _mean_error(commands, times, t0 - d, dt, chi0, turn)
        else:
            j = bisect.bisect_right(times, t - d) - 1
            x = None if j < 0 else wrap_pi(commands[j][1] - chi)
        if x is None:  # the history does not reach back this far yet
            return {"window": (), "gaps": state.gaps + 1}
        errors.append(x)
    peak = max(map(abs, errors))
    if given_rate is None:
        window = (*state.window, _Interval(dt, turn, tuple(dt * x for x in errors), peak))
        # the shortest run of the newest intervals that spans the rate window
        span = sum(w.dt_s for w in window)
        while len(window) > 1 and span - window[0].dt_s >= params.rate_window_s - 1e-9:
            span -= window[0].dt_s
            window = window[1:]
        if span < params.rate_window_s - 1e-9:
            return {"window": window}
        rate = sum(w.turn_rad for w in window) / span
        regressors = [sum(col) / span for col in zip(*(w.weighted for w in window), strict=True)]
        peak = max(w.peak_rad for w in window)
    else:
        window = ()
        rate, regressors = given_rate, errors

    # before the estimate is ready the rate test guards against saturation (docstring)
    now = estimate(state, params)
    k_check = now.gain_per_s if now.ready else params.min_gain_per_s
    limit = params.saturation_fraction * params.max_rate_rad_s
    command_limit = params.command_limit_rad
    if (
        abs(rate) >= limit
        or k_check * peak >= limit
        or (command_limit is not None and peak >= command_limit)
    ):
        return {"window": window, "saturated": state.saturated + 1}
    if abs(regressors[state.delay_index]) < params.min_error_rad:
        return {"window": window, "quiet": state.quiet + 1}
    # forgetting in informative time; each sample weighs its newest interval (s)
    weight = dt
    decay = math.exp(-dt / params.memory_s)
    fits = state.fits or tuple(_Fit() for _ in params.delays_s)
    wr = weight * rate
    fits = tuple(
        _Fit(decay * f.sxx + weight * x * x, decay * f.sxy + wr * x, decay * f.syy + wr * rate)
        for f, x in zip(fits, regressors, strict=True)
    )
    index = state.delay_index
    residuals = [f.sse() for f in fits]
    best = min(range(len(fits)), key=residuals.__getitem__)  # the first of equals
    floor = _SSE_FLOOR * fits[index].syy
    if residuals[best] + floor < params.delay_switch_ratio * residuals[index]:
        index = best
    return {
        "window": window,
        "fits": fits,
        "informative_s": decay * state.informative_s + weight,
        "effective_n": decay * state.effective_n + 1.0,
        "informative_count": state.informative_count + 1,
        "delay_index": index,
    }


def _sent_at(command: tuple[float, float]) -> float:
    return command[0]


def _mean_error(
    commands: tuple[tuple[float, float], ...],
    times: list[float],
    start_s: float,
    dt: float,
    chi0: float,
    turn: float,
) -> float | None:
    """Mean over s in [start_s, start_s + dt] of wrap(command(s) - course), the course moving
    linearly from ``chi0`` by ``turn`` over the interval and the commands (sent at ``times``,
    ascending) held piecewise constant; None when no command covers the interval's start."""
    j = bisect.bisect_right(times, start_s) - 1
    if j < 0:
        return None
    end = start_s + dt
    n = len(commands)
    if j + 1 >= n or commands[j + 1][0] >= end:  # one command over the whole interval
        return wrap_pi(commands[j][1] - (chi0 + 0.5 * turn))
    total = 0.0
    a = start_s
    while a < end - 1e-12 and j < n:
        b = min(commands[j + 1][0], end) if j + 1 < n else end
        if b > a:
            mid = 0.5 * (a + b) - start_s
            total += (b - a) * wrap_pi(commands[j][1] - (chi0 + turn * mid / dt))
        a = b
        j += 1
    return total / dt
