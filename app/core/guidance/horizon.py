"""Receding-horizon track guidance (issue #15 item 4): plan the next ``horizon_s`` seconds on
the target estimate, fly the plan's start, plan again.

The field (``field.py``, ``orbit_plan.py``) answers where the vehicle is now; it does not look
at where the target will be, and at a place the orbit cannot be flown it saturates the turn
and lets the vehicle drift out. Here each vehicle instead chooses its own ground course rate
and speed command over the horizon, piecewise constant over blocks of ``block_s``, within the
airframe's limits (course rate within ``rate_margin`` of W, the speed command within the
envelope, the speed answering it through the speed loop saturated at the acceleration limit),
to minimise over the horizon

    mean_k (d_k / distance_ref)^2 + spacing_weight * mean_k (e_k / spacing_ref)^2
    + terminal: (d_N / distance_ref)^2 + (radial speed_N / radial_ref)^2, weighted
    + smoothing of the block-to-block changes

where d_k is the distance error to the circle r_d around the *predicted* target and e_k the
phase error against the vehicle's seat (the paper's seat law, eq. 22-28: the seat is where the
teammates' phases put it now, and it moves on at the rate the teammates' phases were seen to
move). The target is predicted from its estimate: position, velocity and, where the estimate
carries one, the acceleration, split into a turn rate (the coordinated-turn mode's) and an
along-track acceleration, both fading with ``manoeuvre_fade_s`` (a manoeuvre in progress is
anticipated, not extrapolated for ever). Through the target's manoeuvres, which that
prediction misses, the agent flies the field instead (``manoeuvre_dv_m_s``).

The optimiser is L-BFGS-B on the block controls with the exact gradient (reverse
accumulation over the Euler steps, below), warm-started from the previous plan moved on to the
present (``moved_on``: each new block the old plan's average over the block's span, so that a
replan between block edges starts from what the vehicle was flying). The team plan also starts
from the field's own controls (the agent's guess), at most every ``guess_every_s``: replanned
every 0.5 s with 1 s blocks, the plan moved on was the cheaper start 94 % of the time. Every
function here is pure.
"""

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize  # type: ignore[import-untyped]

Array = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class HorizonParams:
    """How the receding-horizon planner plans (see the module docstring)."""

    horizon_s: float = 40.0
    block_s: float = 1.0
    step_s: float = 0.5
    replan_s: float = 0.5
    distance_ref_m: float = 3.0
    spacing_ref_rad: float = math.radians(4.0)
    spacing_weight: float = 1.0
    terminal_weight: float = 4.0
    radial_ref_m_s: float = 1.5
    smooth_weight: float = 0.05
    rate_margin: float = 1.0
    manoeuvre_fade_s: float = 5.0
    max_iterations: int = 10
    #: the team plan tries the field's own controls as a start again after this long (s;
    #: every replan when the replans are further apart): a plan moved on from 0.5 s before
    #: rarely loses to it, and the guess costs a third of a plan
    guess_every_s: float = 2.0
    #: below this target speed the field is flown (it holds a still target's circle exactly;
    #: the plan's blocks do not: 2 s blocks held 2.2 m RMS)
    min_target_speed_m_s: float = 1.5
    #: the team plan's penalty on a phase running against the orbit's direction: the
    #: relative velocity's component along the orbit below ``direction_min_m_s``, per m/s
    direction_weight: float = 1.0
    direction_min_m_s: float = 1.0
    #: a manoeuvre of the target: its estimated velocity this far (m/s) from the velocity it
    #: was taken to hold; the field is then flown until ``manoeuvre_settle_s`` after the last
    #: one. The plan predicts the target at constant velocity, and through a turn the field
    #: recovers closer to the optimum (on the true target over B-C, the field 1.02x the
    #: oracle, the plan 1.28x); 10 s measured best of 10, 20 and 30 (docs/mission.md)
    manoeuvre_dv_m_s: float = 1.5
    manoeuvre_settle_s: float = 10.0
    #: plan the whole team at once where every teammate's course and speed are known (each
    #: agent flies its own part of the same plan); else each vehicle alone against its seat
    joint: bool = True
    #: the largest team planned jointly: each agent plans every vehicle, so the team's work
    #: grows with the square of its size (a replan per agent: joint 12 ms for 3 vehicles, 72 ms
    #: for 20; alone about 5 ms at any size); a larger team plans each vehicle alone
    joint_max_vehicles: int = 5

    def __post_init__(self) -> None:
        for name in (
            "horizon_s",
            "block_s",
            "step_s",
            "replan_s",
            "distance_ref_m",
            "spacing_ref_rad",
            "radial_ref_m_s",
            "manoeuvre_fade_s",
            "guess_every_s",
            "manoeuvre_dv_m_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"HorizonParams.{name} must be finite and > 0, got {value!r}")
        for name in ("spacing_weight", "terminal_weight", "smooth_weight", "manoeuvre_settle_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"HorizonParams.{name} must be finite and >= 0, got {value!r}")
        if not (math.isfinite(self.rate_margin) and 0.0 < self.rate_margin <= 1.0):
            raise ValueError(f"HorizonParams.rate_margin must be in (0, 1], got {self.rate_margin}")
        per_block = self.block_s / self.step_s
        if abs(per_block - round(per_block)) > 1e-9 or round(per_block) < 1:
            raise ValueError("HorizonParams.block_s must be a whole number of step_s")
        blocks = self.horizon_s / self.block_s
        if abs(blocks - round(blocks)) > 1e-9 or round(blocks) < 1:
            raise ValueError("HorizonParams.horizon_s must be a whole number of block_s")
        if self.max_iterations < 1:
            raise ValueError("HorizonParams.max_iterations must be >= 1")
        if self.joint_max_vehicles < 2:
            raise ValueError("HorizonParams.joint_max_vehicles must be >= 2")

    @property
    def blocks(self) -> int:
        return round(self.horizon_s / self.block_s)

    @property
    def steps_per_block(self) -> int:
        return round(self.block_s / self.step_s)


@dataclass(frozen=True, slots=True)
class Airframe:
    """The limits the plan keeps to: ground speed m/s, acceleration m/s^2, course rate rad/s,
    and the speed loop's gain 1/s (acceleration = gain (command - speed), saturated)."""

    min_speed_m_s: float
    max_speed_m_s: float
    max_accel_m_s2: float
    max_course_rate_rad_s: float
    speed_gain_per_s: float


@dataclass(frozen=True, slots=True)
class Problem:
    """One plan's inputs. Positions are metres east/north relative to the target's estimated
    position now; ``target`` (N + 1, 2) is its predicted path at the plan's steps (row 0 is
    (0, 0)) and ``target_velocity`` its predicted velocity at the last step; courses are
    clockwise from north. ``seat`` (N,): the vehicle's seat at the plan's steps 1..N (a phase:
    the polar angle counter-clockwise from east times ``orbit_sign``, ``seat_path``); None:
    no spacing term (a team of one)."""

    east_m: float
    north_m: float
    course_rad: float
    speed_m_s: float
    target: Array
    target_velocity: tuple[float, float]
    radius_m: float
    orbit_sign: int
    airframe: Airframe
    seat: Array | None = None


@dataclass(frozen=True, slots=True)
class Plan:
    """A plan made at ``t_s`` from course ``course_rad``: per block the ground course rate
    (rad/s, clockwise positive) and the speed command (m/s); its cost and how many cost
    evaluations it took."""

    t_s: float
    course_rad: float
    block_s: float
    rates: tuple[float, ...]
    speeds: tuple[float, ...]
    cost: float
    evaluations: int

    def at(self, t_s: float) -> tuple[float, float, float]:
        """(course rad, course rate rad/s, speed command m/s) the plan has for ``t_s`` (held at
        its last block past the horizon, at its start before it)."""
        tau = max(t_s - self.t_s, 0.0)
        course = self.course_rad
        last = len(self.rates) - 1
        for b, rate in enumerate(self.rates):
            span = self.block_s if b < last else math.inf
            if tau <= span:
                return course + rate * tau, rate, self.speeds[b]
            course += rate * span
            tau -= span
        return course, self.rates[-1], self.speeds[-1]  # pragma: no cover - last span is inf


def replan_due(t_s: float, planned_t_s: float, replan_s: float, index: int, team: int) -> bool:
    """Whether a plan made at ``planned_t_s`` is to be made again at ``t_s``: every
    ``replan_s`` on a grid of slots staggered by the vehicle's place in the team, the slots of
    ``index`` at (index + 1/2) / ``team`` of the period, so that the team's agents do not all
    plan on one telemetry frame, and no slot falls on a frame of a 10 Hz telemetry (a frame a
    hair early would put the plan off by a whole frame: the slots are 17 ms or more from the
    frames for a team of 2, 3 or 5). Where they all planned on one frame, the agents sharing a
    process steered one after another, each after the others' plans: over MAVLink at 3x
    (seeds 1-3) each vehicle skipped 4-24 frames and waited up to 0.17-0.34 s for one;
    staggered, 0-5 frames and up to 0.13-0.22 s. The fast simulation flies the same (eight
    seeds, RMS distance within 0.12 m per segment; docs/mission.md, "The planner's time over
    MAVLink")."""
    offset = replan_s * ((index % team) + 0.5) / team if team > 0 else 0.0

    def slot(x: float) -> int:
        return math.floor((x - offset) / replan_s)

    return slot(t_s) > slot(planned_t_s)


def predict_target(
    velocity: tuple[float, float],
    accel: tuple[float, float],
    steps: int,
    step_s: float,
    fade_s: float,
) -> tuple[Array, Array]:
    """The target's path (steps + 1, 2) relative to where it is now and its velocity there
    (steps + 1, 2): its velocity turned at the turn rate its acceleration implies (normal
    component / speed) and sped up by the along-track component, both fading as
    exp(-t / fade_s); the speed never goes below 0."""
    ve, vn = velocity
    ae, an = accel
    speed = math.hypot(ve, vn)
    turn = along = 0.0
    if speed > 0.5:
        turn = (ve * an - vn * ae) / (speed * speed)  # counter-clockwise positive
        along = (ve * ae + vn * an) / speed
        turn = min(max(turn, -0.5), 0.5)
        along = min(max(along, -5.0), 5.0)
    heading = math.atan2(vn, ve)
    path = np.zeros((steps + 1, 2))
    vel = np.empty((steps + 1, 2))
    vel[0] = velocity
    e = n = 0.0
    decay = math.exp(-step_s / fade_s)
    for k in range(steps):
        e += speed * math.cos(heading) * step_s
        n += speed * math.sin(heading) * step_s
        heading += turn * step_s
        speed = max(speed + along * step_s, 0.0)
        turn *= decay
        along *= decay
        path[k + 1, 0], path[k + 1, 1] = e, n
        vel[k + 1, 0], vel[k + 1, 1] = speed * math.cos(heading), speed * math.sin(heading)
    return path, vel


def seat_path(
    own_phase_rad: float,
    phases_rad: Array,
    target_velocity: Array,
    radius_m: float,
    orbit_sign: int,
    speed_m_s: float,
    step_s: float,
) -> Array:
    """The vehicle's seat at steps 1..N (N = len(target_velocity) - 1) as its teammates will
    place it: each teammate (``phases_rad``, their phases now; the vehicle's own phase is
    ``own_phase_rad``) is predicted to fly the circle ``radius_m`` about the target at ground
    speed ``speed_m_s`` (ground velocity v_t + lambda d along the circle's tangent d, |.| =
    speed, so its phase moves at lambda / r_d, unevenly round the orbit of a moving target),
    and the seat is the paper's seat law's (eq. 22-28) from theirs alone: the mean, over the
    teammates, of each one's phase plus the vehicle's place in the orbit order behind it times
    2 pi / n."""
    n = len(phases_rad) + 1
    rel = np.mod(phases_rad - own_phase_rad, 2.0 * math.pi)  # ahead of the vehicle, (0, 2 pi)
    order = np.argsort(rel)
    # the teammate ranked j (1-based) ahead sits j 2 pi / n ahead of the seat
    offsets = 2.0 * math.pi * np.arange(1, n) / n
    unwrapped = own_phase_rad + rel[order]
    steps = len(target_velocity) - 1
    out = np.empty(steps)
    s2 = speed_m_s * speed_m_s
    for k in range(steps):
        vt = target_velocity[k]
        polar = orbit_sign * unwrapped
        tx, ty = -np.sin(polar) * orbit_sign, np.cos(polar) * orbit_sign
        along = vt[0] * tx + vt[1] * ty
        disc = np.maximum(s2 - (vt[0] * vt[0] + vt[1] * vt[1]) + along * along, 0.0)
        lam = np.maximum(np.sqrt(disc) - along, 0.1 * speed_m_s)
        rate = lam / radius_m
        unwrapped = unwrapped + rate * step_s
        out[k] = float(np.mean(unwrapped - offsets))
    return out


def cost_and_gradient(x: Array, problem: Problem, params: HorizonParams) -> tuple[float, Array]:
    """The plan's cost for the block controls ``x`` = (rates..., speeds...) and its gradient."""
    p, hp, air = problem, params, problem.airframe
    nb, per = hp.blocks, hp.steps_per_block
    steps = nb * per
    dt = hp.step_s
    rates = np.repeat(x[:nb], per)
    # course chi_k = chi_0 + dt sum_{j<k} u_j
    chi = np.empty(steps + 1)
    chi[0] = p.course_rad
    chi[1:] = p.course_rad + np.cumsum(rates) * dt
    a_max, gain = air.max_accel_m_s2, air.speed_gain_per_s
    speeds, free = _speed_response(
        x[nb:].reshape(nb, 1), np.array([p.speed_m_s]), per, dt, a_max, gain
    )
    s = speeds[:, 0]
    sin_c, cos_c = np.sin(chi), np.cos(chi)
    pos = np.empty((steps + 1, 2))
    pos[0] = (p.east_m, p.north_m)
    pos[1:, 0] = p.east_m + np.cumsum(s[:-1] * sin_c[:-1]) * dt
    pos[1:, 1] = p.north_m + np.cumsum(s[:-1] * cos_c[:-1]) * dt
    rel = pos[1:] - p.target[1:]
    r2 = np.maximum(rel[:, 0] ** 2 + rel[:, 1] ** 2, 1e-6)
    r = np.sqrt(r2)
    d = r - p.radius_m
    inv_n = 1.0 / steps
    dref2 = hp.distance_ref_m**2
    cost = float(np.sum(d * d)) * inv_n / dref2
    g_pos = np.empty((steps, 2))
    coef = 2.0 * d * inv_n / dref2 / r
    g_pos[:, 0] = coef * rel[:, 0]
    g_pos[:, 1] = coef * rel[:, 1]
    if p.seat is not None and hp.spacing_weight > 0.0:
        theta = p.orbit_sign * np.arctan2(rel[:, 1], rel[:, 0])
        e = np.mod(theta - p.seat + math.pi, 2.0 * math.pi) - math.pi
        w = hp.spacing_weight * inv_n / hp.spacing_ref_rad**2
        cost += w * float(np.sum(e * e))
        # d theta / d (x, y) = sign (-y, x) / r^2
        ce = 2.0 * w * e * p.orbit_sign / r2
        g_pos[:, 0] += -ce * rel[:, 1]
        g_pos[:, 1] += ce * rel[:, 0]
    g_chi = np.zeros(steps + 1)
    g_s = np.zeros(steps + 1)
    if hp.terminal_weight > 0.0:
        wt = hp.terminal_weight * inv_n
        xe, yn = float(rel[-1, 0]), float(rel[-1, 1])
        rn = float(r[-1])
        ux, uy = xe / rn, yn / rn
        sN, cN = float(s[-1]), float(chi[-1])
        vx = sN * math.sin(cN) - p.target_velocity[0]
        vy = sN * math.cos(cN) - p.target_velocity[1]
        vr = ux * vx + uy * vy
        dN = float(d[-1])
        rref2 = hp.radial_ref_m_s**2
        cost += wt * (dN * dN / dref2 + vr * vr / rref2)
        # d vr / d pos = (v - vr u) / r
        gv = 2.0 * wt * vr / rref2
        g_pos[-1, 0] += 2.0 * wt * dN / dref2 * ux + gv * (vx - vr * ux) / rn
        g_pos[-1, 1] += 2.0 * wt * dN / dref2 * uy + gv * (vy - vr * uy) / rn
        g_chi[-1] += gv * sN * (ux * math.cos(cN) - uy * math.sin(cN))
        g_s[-1] += gv * (ux * math.sin(cN) + uy * math.cos(cN))
    # suffix sums: G_{k+1} = sum_{m >= k+1} dJ/dpos_m, for the step k -> k+1
    suffix = np.cumsum(g_pos[::-1], axis=0)[::-1]
    g_chi[:-1] += dt * s[:-1] * (cos_c[:-1] * suffix[:, 0] - sin_c[:-1] * suffix[:, 1])
    g_s[:-1] += dt * (sin_c[:-1] * suffix[:, 0] + cos_c[:-1] * suffix[:, 1])
    # rates: chi_k depends on u_j (j < k) with dt
    chi_suffix = np.cumsum(g_chi[::-1])[::-1]  # sum_{k >= m} g_chi_k
    g_rates = dt * chi_suffix[1:]
    grad = np.empty(2 * nb)
    grad[:nb] = g_rates.reshape(nb, per).sum(axis=1)
    grad[nb:] = _speed_adjoint(g_s[:, None], free, per, dt * gain)[:, 0]
    if hp.smooth_weight > 0.0 and nb > 1:
        wr = hp.smooth_weight / air.max_course_rate_rad_s**2
        span = air.max_speed_m_s - air.min_speed_m_s
        ws = hp.smooth_weight / (span * span if span > 0.0 else 1.0)
        for lo, weight in ((0, wr), (nb, ws)):
            diff = np.diff(x[lo : lo + nb])
            cost += weight * float(np.sum(diff * diff))
            grad[lo : lo + nb - 1] -= 2.0 * weight * diff
            grad[lo + 1 : lo + nb] += 2.0 * weight * diff
    return cost, grad


def plan(t_s: float, problem: Problem, params: HorizonParams, warm: Plan | None = None) -> Plan:
    """The best plan from ``problem``'s state, starting from ``warm`` (the previous plan moved
    on to ``t_s``) or, without one, from holding the course at the present speed. Raises
    ``ValueError`` on a non-finite input; never returns a control outside the limits."""
    p, hp, air = problem, params, problem.airframe
    for name in ("east_m", "north_m", "course_rad", "speed_m_s", "radius_m"):
        if not math.isfinite(getattr(p, name)):
            raise ValueError(f"horizon Problem.{name} must be finite")
    if p.seat is not None and not np.isfinite(p.seat).all():
        raise ValueError("horizon Problem.seat must be finite")
    if not np.isfinite(p.target).all():
        raise ValueError("horizon Problem.target must be finite")
    nb = hp.blocks
    w = hp.rate_margin * air.max_course_rate_rad_s
    speed_now = min(max(p.speed_m_s, air.min_speed_m_s), air.max_speed_m_s)
    x0 = np.empty(2 * nb)
    if warm is None:
        x0[:nb] = 0.0
        x0[nb:] = speed_now
    else:
        old = np.array([warm.rates, warm.speeds])
        moved = moved_on(old, (t_s - warm.t_s) / hp.block_s, nb)
        x0[:nb] = moved[0]
        x0[nb:] = moved[1]
    x0[:nb] = np.clip(x0[:nb], -w, w)
    x0[nb:] = np.clip(x0[nb:], air.min_speed_m_s, air.max_speed_m_s)
    lower = np.concatenate([np.full(nb, -w), np.full(nb, air.min_speed_m_s)])
    upper = np.concatenate([np.full(nb, w), np.full(nb, air.max_speed_m_s)])
    scale = np.concatenate([np.full(nb, w), np.full(nb, _speed_scale(air))])
    x, cost, evaluations = _minimise(
        lambda v: cost_and_gradient(v, p, hp), x0, lower, upper, scale, hp.max_iterations
    )
    if not (np.isfinite(x).all() and math.isfinite(cost)):
        x, cost = x0, cost_and_gradient(x0, p, hp)[0]
    x[:nb] = np.clip(x[:nb], -w, w)
    x[nb:] = np.clip(x[nb:], air.min_speed_m_s, air.max_speed_m_s)
    return Plan(
        t_s=t_s,
        course_rad=p.course_rad,
        block_s=hp.block_s,
        rates=tuple(float(v) for v in x[:nb]),
        speeds=tuple(float(v) for v in x[nb:]),
        cost=cost,
        evaluations=evaluations,
    )


@dataclass(frozen=True, slots=True)
class TeamProblem:
    """A plan for the whole team at once (each agent plans everyone and flies its own part):
    ``east_m`` ... ``speed_m_s`` (n,) the team's states now (relative to the target's estimated
    position), the spacing term the adjacent phase gaps' errors against 2 pi / n, in the orbit
    order of the start."""

    east_m: Array
    north_m: Array
    course_rad: Array
    speed_m_s: Array
    target: Array
    target_velocity: tuple[float, float]
    radius_m: float
    airframe: Airframe
    #: the target's predicted velocity at every step (N + 1, 2) and the orbit's direction
    #: (+1 counter-clockwise): a vehicle whose phase would run backwards is penalised
    target_velocities: Array | None = None
    orbit_sign: int = 1

    @property
    def count(self) -> int:
        return int(self.east_m.shape[0])

    def successor(self) -> NDArray[np.intp]:
        """Each vehicle's counter-clockwise neighbour about the target at the start."""
        order = np.argsort(np.arctan2(self.north_m, self.east_m))
        nxt = np.empty(self.count, dtype=np.intp)
        nxt[order] = np.roll(order, -1)
        return nxt


def team_cost_and_gradient(
    x: Array, problem: TeamProblem, params: HorizonParams, successor: NDArray[np.intp]
) -> tuple[float, Array]:
    """The team plan's cost for the block controls ``x`` = (rates (blocks, n), speeds
    (blocks, n)) flattened, and its gradient."""
    p, hp, air = problem, params, problem.airframe
    nb, per, n = hp.blocks, hp.steps_per_block, problem.count
    steps = nb * per
    dt = hp.step_s
    ctrl = x.reshape(2, nb, n)
    rates = np.repeat(ctrl[0], per, axis=0)  # (steps, n)
    chi = np.empty((steps + 1, n))
    chi[0] = p.course_rad
    chi[1:] = p.course_rad + np.cumsum(rates, axis=0) * dt
    a_max, gain = air.max_accel_m_s2, air.speed_gain_per_s
    s, free = _speed_response(ctrl[1], p.speed_m_s, per, dt, a_max, gain)
    sin_c, cos_c = np.sin(chi), np.cos(chi)
    ex = np.empty((steps + 1, n))
    ny = np.empty((steps + 1, n))
    ex[0], ny[0] = p.east_m, p.north_m
    ex[1:] = p.east_m + np.cumsum(s[:-1] * sin_c[:-1], axis=0) * dt
    ny[1:] = p.north_m + np.cumsum(s[:-1] * cos_c[:-1], axis=0) * dt
    rx = ex[1:] - p.target[1:, 0:1]
    ry = ny[1:] - p.target[1:, 1:2]
    r2 = np.maximum(rx * rx + ry * ry, 1e-6)
    r = np.sqrt(r2)
    d = r - p.radius_m
    inv = 1.0 / (steps * n)
    dref2 = hp.distance_ref_m**2
    cost = float(np.sum(inv * d * d)) / dref2
    coef = 2.0 * d * inv / dref2 / r
    gx = coef * rx
    gy = coef * ry
    if n >= 2 and hp.spacing_weight > 0.0:
        theta = np.arctan2(ry, rx)
        gap = np.mod(theta[:, successor] - theta, 2.0 * math.pi) - 2.0 * math.pi / n
        w = hp.spacing_weight * inv / hp.spacing_ref_rad**2
        cost += float(np.sum(w * gap * gap))
        g_theta = -2.0 * w * gap
        g_theta[:, successor] += 2.0 * w * gap  # a permutation: no index repeats
        # d theta / d (x, y) = (-y, x) / r^2
        gx += -g_theta * ry / r2
        gy += g_theta * rx / r2
    g_chi = np.zeros((steps + 1, n))
    g_s = np.zeros((steps + 1, n))
    if p.target_velocities is not None and hp.direction_weight > 0.0:
        sg = float(p.orbit_sign)
        sk_, ck_ = s[1:], chi[1:]
        vx = sk_ * sin_c[1:] - p.target_velocities[1:, 0:1]
        vy = sk_ * cos_c[1:] - p.target_velocities[1:, 1:2]
        h = sg * (rx * vy - ry * vx) / r
        short = np.minimum(h - hp.direction_min_m_s, 0.0)
        wd = hp.direction_weight * inv
        cost += float(np.sum(wd * short * short))
        gh = 2.0 * wd * short
        gx += gh * (sg * vy / r - h * rx / r2)
        gy += gh * (-sg * vx / r - h * ry / r2)
        ghx = gh * (-sg * ry / r)
        ghy = gh * (sg * rx / r)
        g_chi[1:] += ghx * sk_ * np.cos(ck_) - ghy * sk_ * np.sin(ck_)
        g_s[1:] += ghx * np.sin(ck_) + ghy * np.cos(ck_)
    if hp.terminal_weight > 0.0:
        wt = hp.terminal_weight / (steps * n)
        ux, uy = rx[-1] / r[-1], ry[-1] / r[-1]
        sN, cN = s[-1], chi[-1]
        vx = sN * np.sin(cN) - p.target_velocity[0]
        vy = sN * np.cos(cN) - p.target_velocity[1]
        vr = ux * vx + uy * vy
        dN = d[-1]
        rref2 = hp.radial_ref_m_s**2
        cost += wt * float(np.sum(dN * dN / dref2 + vr * vr / rref2))
        gv = 2.0 * wt * vr / rref2
        gx[-1] += 2.0 * wt * dN / dref2 * ux + gv * (vx - vr * ux) / r[-1]
        gy[-1] += 2.0 * wt * dN / dref2 * uy + gv * (vy - vr * uy) / r[-1]
        g_chi[-1] += gv * sN * (ux * np.cos(cN) - uy * np.sin(cN))
        g_s[-1] += gv * (ux * np.sin(cN) + uy * np.cos(cN))
    sx = np.cumsum(gx[::-1], axis=0)[::-1]
    sy = np.cumsum(gy[::-1], axis=0)[::-1]
    g_chi[:-1] += dt * s[:-1] * (cos_c[:-1] * sx - sin_c[:-1] * sy)
    g_s[:-1] += dt * (sin_c[:-1] * sx + cos_c[:-1] * sy)
    chi_suffix = np.cumsum(g_chi[::-1], axis=0)[::-1]
    g_rates = dt * chi_suffix[1:]
    grad = np.empty((2, nb, n))
    grad[0] = g_rates.reshape(nb, per, n).sum(axis=1)
    grad[1] = _speed_adjoint(g_s, free, per, dt * gain)
    if hp.smooth_weight > 0.0 and nb > 1:
        span = air.max_speed_m_s - air.min_speed_m_s
        weights = (
            hp.smooth_weight / air.max_course_rate_rad_s**2,
            hp.smooth_weight / (span * span if span > 0.0 else 1.0),
        )
        for i, weight in enumerate(weights):
            diff = np.diff(ctrl[i], axis=0)
            cost += weight * float(np.sum(diff * diff)) / n
            grad[i, :-1] -= 2.0 * weight * diff / n
            grad[i, 1:] += 2.0 * weight * diff / n
    return cost, grad.reshape(-1)


def moved_on(controls: Array, blocks_later: float, blocks: int) -> Array:
    """A plan's block controls (2, its blocks, ...) as ``blocks`` blocks starting
    ``blocks_later`` blocks after it started: each block the plan's time average over the
    block's span (its last block held on past its end). Plain block indices would start a
    plan replanned between block edges up to a block late."""
    have = controls.shape[1]
    later = max(blocks_later, 0.0)
    whole = int(later + 1e-6)
    frac = later - whole
    if frac < 1e-6:
        frac = 0.0
    first = np.minimum(np.arange(blocks) + whole, have - 1)
    second = np.minimum(first + 1, have - 1)
    if frac == 0.0:
        return controls[:, first].copy()
    out: Array = (1.0 - frac) * controls[:, first] + frac * controls[:, second]
    return out


def _speed_scale(air: Airframe) -> float:
    """The speed commands' unit in the optimiser (half the speed range; 1 m/s if none)."""
    half = 0.5 * (air.max_speed_m_s - air.min_speed_m_s)
    return half if half > 0.0 else 1.0


def _minimise(
    fun: Callable[[Array], tuple[float, Array]],
    x0: Array,
    lower: Array,
    upper: Array,
    scale: Array,
    iterations: int,
) -> tuple[Array, float, int]:
    """L-BFGS-B on ``fun`` (cost, gradient) from ``x0`` within [``lower``, ``upper``], in
    units of ``scale`` (course rates in units of the limit, speeds of half their range:
    unscaled, a step in rate and one in speed differ forty times in size, and the search
    spends its iterations on that). Returns (x, cost, evaluations)."""

    def scaled(u: Array) -> tuple[float, Array]:
        cost, grad = fun(u * scale)
        return cost, grad * scale

    result = minimize(
        scaled,
        x0 / scale,
        jac=True,
        method="L-BFGS-B",
        bounds=list(zip(lower / scale, upper / scale, strict=True)),
        options={"maxiter": iterations},
    )
    return np.asarray(result.x, dtype=float) * scale, float(result.fun), int(result.nfev)


def _speed_response(
    commands: Array, speed0: Array, per: int, dt: float, a_max: float, gain: float
) -> tuple[Array, Array]:
    """Speeds (steps + 1, n) under the block speed commands (blocks, n) through the speed
    loop of ``app.core.plant``, s_{k+1} = s_k + dt clip(g (S - s_k), +-A), and per step
    whether the loop was unsaturated (steps, n: 1 or 0, the slope's factor). The recursion
    runs in plain floats: numpy's per-call cost on a handful of vehicles is ten times the
    arithmetic."""
    nb, n = commands.shape
    steps = nb * per
    out = [[0.0] * n for _ in range(steps + 1)]
    free = [[0.0] * n for _ in range(steps)]
    cmd = commands.tolist()
    for i in range(n):
        sk = float(speed0[i])
        out[0][i] = sk
        k = 0
        for b in range(nb):
            target = cmd[b][i]
            for _ in range(per):
                accel = gain * (target - sk)
                if -a_max < accel < a_max:
                    free[k][i] = 1.0
                else:
                    accel = a_max if accel > 0.0 else -a_max
                sk += dt * accel
                k += 1
                out[k][i] = sk
    return np.array(out), np.array(free)


def _speed_adjoint(g_s: Array, free: Array, per: int, dt_gain: float) -> Array:
    """The gradient (blocks, n) of the cost with respect to the block speed commands, from
    its gradient ``g_s`` (steps + 1, n) with respect to each step's speed (reverse
    accumulation through ``_speed_response``)."""
    steps, n = free.shape
    nb = steps // per
    gs = g_s.tolist()
    sh = free.tolist()
    out = [[0.0] * n for _ in range(nb)]
    for i in range(n):
        lam = gs[steps][i]
        for k in range(steps - 1, -1, -1):
            ds = dt_gain * sh[k][i]
            out[k // per][i] += lam * ds
            lam = gs[k][i] + lam * (1.0 - ds)
    return np.array(out)


@dataclass(frozen=True, slots=True)
class TeamPlan:
    """A team plan made at ``t_s``: controls (2, blocks, n) (course rates, speed commands) and
    the courses it started from; ``guess_t_s``: when a start from the field's guess was last
    tried for it (this plan or those it was moved on from)."""

    t_s: float
    controls: Array
    course_rad: Array
    cost: float
    evaluations: int
    guess_t_s: float

    def member(self, index: int, block_s: float) -> Plan:
        return Plan(
            t_s=self.t_s,
            course_rad=float(self.course_rad[index]),
            block_s=block_s,
            rates=tuple(float(v) for v in self.controls[0, :, index]),
            speeds=tuple(float(v) for v in self.controls[1, :, index]),
            cost=self.cost,
            evaluations=self.evaluations,
        )


def plan_team(
    t_s: float,
    problem: TeamProblem,
    params: HorizonParams,
    warm: TeamPlan | None = None,
    guess: Callable[[], Array] | None = None,
) -> TeamPlan:
    """The best team plan from ``problem``'s state, within the limits. The optimiser starts
    from the cheaper of ``warm`` (the previous plan, ``moved_on`` to ``t_s``; used when it is
    for a team of the same size) and what ``guess`` returns (controls (2, blocks, n), e.g. the
    field's own course rates and speeds over the horizon; asked for only without a usable
    ``warm`` or ``guess_every_s`` after it was last tried): from straight flight it finds only
    poor local optima."""
    p, hp, air = problem, params, problem.airframe
    for name in ("east_m", "north_m", "course_rad", "speed_m_s", "target"):
        if not np.isfinite(getattr(p, name)).all():
            raise ValueError(f"horizon TeamProblem.{name} must be finite")
    nb, n = hp.blocks, p.count
    w = hp.rate_margin * air.max_course_rate_rad_s
    starts = []
    guess_t_s, due = t_s, True
    if warm is not None and warm.controls.shape == (2, nb, n) and t_s >= warm.t_s:
        starts.append(moved_on(warm.controls, (t_s - warm.t_s) / hp.block_s, nb))
        if warm.guess_t_s <= t_s < warm.guess_t_s + hp.guess_every_s - 1e-9:
            guess_t_s, due = warm.guess_t_s, False
    if guess is not None and due:
        controls = guess()
        if controls.shape == (2, nb, n) and np.isfinite(controls).all():
            starts.append(controls.copy())
    if not starts:
        straight = np.empty((2, nb, n))
        straight[0] = 0.0
        straight[1] = p.speed_m_s
        starts.append(straight)
    successor = p.successor()
    for start in starts:
        start[0] = np.clip(start[0], -w, w)
        start[1] = np.clip(start[1], air.min_speed_m_s, air.max_speed_m_s)
    costs = [team_cost_and_gradient(x.reshape(-1), p, hp, successor)[0] for x in starts]
    x0 = starts[int(np.argmin(costs))]
    m = nb * n
    lower = np.concatenate([np.full(m, -w), np.full(m, air.min_speed_m_s)])
    upper = np.concatenate([np.full(m, w), np.full(m, air.max_speed_m_s)])
    scale = np.concatenate([np.full(m, w), np.full(m, _speed_scale(air))])
    flat, cost, evaluations = _minimise(
        lambda v: team_cost_and_gradient(v, p, hp, successor),
        x0.reshape(-1),
        lower,
        upper,
        scale,
        hp.max_iterations,
    )
    x = flat.reshape(2, nb, n)
    if not (np.isfinite(x).all() and math.isfinite(cost)):
        x, cost = x0, team_cost_and_gradient(x0.reshape(-1), p, hp, successor)[0]
    x[0] = np.clip(x[0], -w, w)
    x[1] = np.clip(x[1], air.min_speed_m_s, air.max_speed_m_s)
    return TeamPlan(t_s, x, p.course_rad.copy(), cost, evaluations, guess_t_s)
