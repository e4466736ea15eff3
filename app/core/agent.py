"""One vehicle's decision step: guidance (field, optimal c, ILVF switch, lag compensation,
moving-target correction) and phase keeping, as a pure ``agent_step(state, inputs, params)``.

Everything the step needs arrives in ``AgentInputs`` (own telemetry, the target's position and
velocity, the team's positions) and ``AgentParams``; everything it remembers is in the returned
``AgentState``. The same function is driven by the fast numerical simulation, an in-process
async run and the live mission. Later parts add fields (an estimator's state, a mission stage)
with defaults, so callers that do not know them keep working.
"""

import math
from dataclasses import dataclass, field
from functools import lru_cache, partial
from typing import Literal

import numpy as np

from app.core import phase, plant
from app.core.frames import wrap_pi
from app.core.guidance import horizon as hz
from app.core.guidance.course import (
    CourseLoop,
    course_command,
    inverse_field_wanted,
    predict_min_distance_error,
)
from app.core.guidance.field import FieldParams, course_and_rate, optimal_c, peak_curvature
from app.core.guidance.moving_target import moving_target_velocity_unchecked
from app.core.guidance.orbit_plan import (
    PlannedOrbit,
    ellipse_course_and_rate,
    orbit_speed_cap,
    orbit_speed_profile,
    planned_orbit_axes,
)
from app.core.plant import VehicleEnvelope, require_positive
from app.core.values import replace

GuidanceLaw = Literal["proposed", "frew", "fixed"]
PhaseLaw = Literal["paper", "frew", "none"]
Orbit = Literal["ccw", "cw"]
FieldMode = Literal["field", "inverse"]
OrbitPlan = Literal["circle", "ellipse"]
Planner = Literal["field", "horizon"]
PhaseActuator = Literal["speed", "radius"]
#: what the radius actuator keeps spaced around a moving target (``PhaseParams.radius_phase``)
RadiusPhase = Literal["orbit_time", "polar"]
ActuatorChoice = Literal["auto", "speed", "radius"]

FREW_C = 2.0


@dataclass(frozen=True, slots=True)
class GuidanceParams:
    """Which field and how it is flown.

    ``law``: ``proposed`` (optimal c, section 4.1, recomputed as speed changes, with the ILVF
    switch), ``frew`` (c = 2) or ``fixed`` (c = ``c``). ``feed_forward``: lag compensation of the
    course command (``guidance.course.course_command``); False is the paper's literal eq. (2) loop.
    ``curvature_margin``: fraction of the course-rate limit the optimal c may use.
    ``inverse_field``: the ILVF switch (default: on for ``proposed`` only).
    ``relative_speed``: with a moving target, the speed command is the speed relative to the
    target (eq. 15 with lambda = speed); False makes it the ground speed (Frew's choice).
    ``orbit_plan``: ``circle`` (the paper's: the field converges to the circle r_d around the
    target whatever its speed) or ``ellipse`` (improvement: around a target too fast for the
    circle, the field converges to the flyable ellipse closest to it, aligned with the target's
    velocity; ``orbit_plan.planned_orbit_axes`` with ``plan_margin`` of the course-rate limit and
    semi-axes within ``plan_max_stretch`` r_d of r_d; the circle while it is flyable).
    ``speed_cap`` (improvement): around a moving target, the ground speed is capped where the
    orbit (the circle, or the planned one) would need more than ``speed_cap_margin`` of the
    course-rate limit at the speed the phase law wants (``orbit_plan.orbit_speed_cap``: flying
    against the target's motion, e.g. at most 11.2 m/s on the 90 m circle around a 3 m/s
    target), braking ahead of such a place at ``speed_cap_brake`` of the envelope's acceleration.
    ``turn_slow_rad`` (improvement): a (start, full) pair of course errors: where the field's
    ground course is more than ``start`` from the vehicle's, the ground speed is capped on a
    ramp down to the envelope's minimum at ``full`` and beyond, so that a turn the course-rate
    limit stretches out (a target that turned or stopped under a vehicle on its far side) is
    flown on the tightest circle the vehicle has (v / rate) and not at the phase law's speed;
    None: off.
    ``planner`` (improvement, issue #15 item 4): ``field`` flies the field as above;
    ``horizon`` plans the ground course rate and speed over the next ``horizon.horizon_s`` on
    the target estimate and the team's seats (``guidance.horizon``), every
    ``horizon.replan_s``, and flies the plan's start (the field's command stays the fallback).
    """

    radius_m: float
    orbit: Orbit = "ccw"
    law: GuidanceLaw = "proposed"
    c: float | None = None
    feed_forward: bool = True
    curvature_margin: float = 1.0
    inverse_field: bool | None = None
    c_update_speed_step_m_s: float = 0.1
    switch_check_period_s: float = 0.2
    switch_enter_below_m: float = 0.0
    switch_leave_above_m: float = 0.5
    relative_speed: bool = True
    orbit_plan: OrbitPlan = "circle"
    plan_margin: float = 1.0
    plan_max_stretch: float = 0.5
    speed_cap: bool = False
    speed_cap_margin: float = 0.95
    speed_cap_brake: float = 0.7
    turn_slow_rad: tuple[float, float] | None = None
    planner: Planner = "field"
    horizon: hz.HorizonParams = field(default_factory=hz.HorizonParams)
    #: +1 counter-clockwise, -1 clockwise (derived from ``orbit``)
    orbit_sign: int = field(init=False, repr=False)
    #: whether the ILVF switch is used (derived from ``law`` and ``inverse_field``)
    uses_inverse_field: bool = field(init=False, repr=False)

    def __post_init__(self) -> None:
        require_positive(
            "GuidanceParams",
            radius_m=self.radius_m,
            c_update_speed_step_m_s=self.c_update_speed_step_m_s,
            switch_check_period_s=self.switch_check_period_s,
        )
        if self.orbit not in ("ccw", "cw"):
            raise ValueError(f"GuidanceParams.orbit must be 'ccw' or 'cw', got {self.orbit!r}")
        if self.law not in ("proposed", "frew", "fixed"):
            raise ValueError(f"GuidanceParams.law must be proposed|frew|fixed, got {self.law!r}")
        if self.law == "fixed" and self.c is None:
            raise ValueError("GuidanceParams: law 'fixed' needs c")
        if self.c is not None:
            require_positive("GuidanceParams", c=self.c)
        if not (math.isfinite(self.curvature_margin) and 0.0 < self.curvature_margin <= 1.0):
            raise ValueError(
                f"GuidanceParams.curvature_margin must be in (0, 1], got {self.curvature_margin!r}"
            )
        if self.planner not in ("field", "horizon"):
            raise ValueError(
                f"GuidanceParams.planner must be 'field' or 'horizon', got {self.planner!r}"
            )
        if self.orbit_plan not in ("circle", "ellipse"):
            raise ValueError(
                f"GuidanceParams.orbit_plan must be 'circle' or 'ellipse', got {self.orbit_plan!r}"
            )
        if not (math.isfinite(self.plan_margin) and 0.0 < self.plan_margin <= 1.0):
            raise ValueError(
                f"GuidanceParams.plan_margin must be in (0, 1], got {self.plan_margin!r}"
            )
        if not (math.isfinite(self.plan_max_stretch) and 0.0 < self.plan_max_stretch < 1.0):
            raise ValueError(
                f"GuidanceParams.plan_max_stretch must be in (0, 1), got {self.plan_max_stretch!r}"
            )
        for name in ("speed_cap_margin", "speed_cap_brake"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 < value <= 1.0):
                raise ValueError(f"GuidanceParams.{name} must be in (0, 1], got {value!r}")
        if self.turn_slow_rad is not None:
            start, full = self.turn_slow_rad
            if not (
                math.isfinite(start) and math.isfinite(full) and 0.0 <= start < full <= math.pi
            ):
                raise ValueError(
                    "GuidanceParams.turn_slow_rad must be (start, full) with"
                    f" 0 <= start < full <= pi, got {self.turn_slow_rad!r}"
                )
        uses_inverse = self.law == "proposed" if self.inverse_field is None else self.inverse_field
        object.__setattr__(self, "orbit_sign", 1 if self.orbit == "ccw" else -1)
        object.__setattr__(self, "uses_inverse_field", uses_inverse)


@dataclass(frozen=True, slots=True)
class PhaseParams:
    """Phase keeping: ``paper`` (seat law, eq. 24-28), ``frew`` (neighbour law) or ``none``
    (cruise). ``gain_per_s`` is k of eq. (24). With ``predictive`` the law steers on the phase
    each vehicle will have when it reaches the circle (``phase.arrival_phase_lead``) and drops
    the (r_d / r)^2 weight.

    ``actuator``: how the law's wanted speed v_w (eq. 27) acts. ``speed`` (the paper's) commands
    it. ``radius`` (for autopilots that hold their own airspeed, e.g. PX4 fixed-wing offboard)
    keeps cruise speed and flies the field around an effective radius
    r_eff = r_d v_cruise / v_w instead: at a fixed speed v the phase rate on a circle is v / r,
    so r_eff gives the phase rate the speed law asked for. r_eff stays within
    ``radius_band_m`` of r_d (and no tighter than the course-rate limit allows), changes at most
    ``radius_rate_m_s`` per second, and the field is built for r_eff rounded to
    ``radius_step_m`` about r_d (so c and the field are re-solved only when it moves a step;
    a spaced team has v_w = v_cruise, hence r_eff = r_d exactly). Around a moving target the
    phase rate at a held ground speed s is uneven round the orbit, so the radius actuator steers
    on the orbit-time phase theta + v_t . r_hat / s (first order in v_t / s): a team spaced in
    it stays on r_d, and its polar angles swing by up to sqrt(3) v_t / s rad about 2 pi / 3 (for
    three), which no vehicle at a fixed speed on one circle can avoid.

    ``lead_speed_m_s`` (speed actuator only): the vehicle furthest behind its seat (the largest
    error) flies this speed and every other one the law's speed for its error minus that
    largest one, so that the team closes its gaps at the lead speed instead of about cruise
    (None: about cruise, the paper's law). Up to 10 m outside the circle, at distance r, the lead
    is held to W r_d^2 / r (W the course-rate limit), fading back to the lead by 20 m out: at
    W r_d itself the circle takes the whole turn, and a leader blown out would stay out. With
    ``lead_held_outside`` (the mission's adjust stage, the team already gathered) it is held at
    any distance outside: the fade is for a leader still flying in from afar in gather; and it
    is at most ``held_lead_turn_share`` of W r_d anywhere (a team on the circle at W r_d has no
    turn to spare, and twenty vehicles there were pushed out again and again).

    ``radius_phase = "polar"`` keeps the polar angles themselves spaced instead, by the radius
    too: at ground speed s on a circle around a target moving at v_t the relative speed along
    the orbit is u = -v_t . t_hat + sqrt(s^2 - (v_t . r_hat)^2), so the polar rate u / r is the
    wanted one omega_w = v_w / r_d on r_eff = u / omega_w, which swings by about v_t / omega_w
    round the orbit (18 m at 3 m/s and 15 m/s on 90 m) where the band allows it; the slew limit
    grows by |v_t| to follow it.
    """

    law: PhaseLaw = "paper"
    gain_per_s: float = 0.05
    predictive: bool = False
    actuator: PhaseActuator = "speed"
    radius_band_m: float = 15.0
    radius_rate_m_s: float = 1.0
    radius_step_m: float = 0.5
    radius_phase: RadiusPhase = "orbit_time"
    lead_speed_m_s: float | None = None
    lead_held_outside: bool = False
    held_lead_turn_share: float = 1.0

    def __post_init__(self) -> None:
        if not (
            math.isfinite(self.held_lead_turn_share) and 0.0 < self.held_lead_turn_share <= 1.0
        ):
            raise ValueError(
                f"PhaseParams.held_lead_turn_share must be in (0, 1]: {self.held_lead_turn_share}"
            )
        if self.lead_speed_m_s is not None and not (
            math.isfinite(self.lead_speed_m_s) and self.lead_speed_m_s > 0.0
        ):
            raise ValueError(
                f"PhaseParams.lead_speed_m_s must be finite and > 0: {self.lead_speed_m_s}"
            )
        if self.law not in ("paper", "frew", "none"):
            raise ValueError(f"PhaseParams.law must be paper|frew|none, got {self.law!r}")
        if not (math.isfinite(self.gain_per_s) and self.gain_per_s >= 0.0):
            raise ValueError(f"PhaseParams.gain_per_s must be finite and >= 0: {self.gain_per_s}")
        if self.actuator not in ("speed", "radius"):
            raise ValueError(
                f"PhaseParams.actuator must be 'speed' or 'radius', got {self.actuator!r}"
            )
        if self.radius_phase not in ("orbit_time", "polar"):
            raise ValueError(
                f"PhaseParams.radius_phase must be 'orbit_time' or 'polar', got "
                f"{self.radius_phase!r}"
            )
        require_positive(
            "PhaseParams",
            radius_band_m=self.radius_band_m,
            radius_rate_m_s=self.radius_rate_m_s,
            radius_step_m=self.radius_step_m,
        )


def resolve_actuator(configured: ActuatorChoice, honours_speed: bool) -> PhaseActuator:
    """The phase actuator to fly: ``auto`` is ``speed`` where the vehicle's autopilot honours a
    speed command (the built-in simulator, ArduPlane GUIDED) and ``radius`` where it holds its
    own airspeed (PX4 fixed-wing offboard); ``speed`` and ``radius`` are taken as given."""
    if configured == "auto":
        return "speed" if honours_speed else "radius"
    if configured in ("speed", "radius"):
        return configured
    raise ValueError(f"phase actuator must be auto|speed|radius, got {configured!r}")


def with_phase_actuator(params: "AgentParams", actuator: PhaseActuator) -> "AgentParams":
    """``params`` flying phase keeping with ``actuator`` (itself when it already does)."""
    if params.phase.actuator == actuator:
        return params
    return replace(params, phase=replace(params.phase, actuator=actuator))


@dataclass(frozen=True, slots=True)
class AgentParams:
    """Fixed configuration of one vehicle's agent. ``index`` is the vehicle's place in
    ``AgentInputs.team_positions`` (0-based; MAVLink system id index + 1)."""

    index: int
    envelope: VehicleEnvelope
    guidance: GuidanceParams
    phase: PhaseParams = PhaseParams()
    #: the course loop the guidance assumes (derived from ``envelope`` and ``guidance``)
    course_loop: CourseLoop = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.index < 0:
            raise ValueError(f"AgentParams.index must be >= 0, got {self.index}")
        ph = self.phase
        if ph.actuator == "radius" and ph.radius_band_m >= self.guidance.radius_m:
            raise ValueError(
                f"PhaseParams.radius_band_m ({ph.radius_band_m} m) must be smaller than the "
                f"standoff radius ({self.guidance.radius_m} m)"
            )
        env = self.envelope
        loop = CourseLoop(
            env.course_gain_per_s, env.max_course_rate_rad_s, self.guidance.feed_forward
        )
        object.__setattr__(self, "course_loop", loop)


@dataclass(frozen=True, slots=True)
class OwnTelemetry:
    """The vehicle's own state: metres east/north of the origin, course (rad, clockwise from
    north), ground speed m/s; the autopilot's airspeed m/s where it reports one (the wind
    estimate's input, ``guidance.wind``) and its own wind estimate (east, north m/s, where the
    air moves to) where it sends one (PX4 WIND_COV, ArduPilot WIND), which the mission agent
    then flies instead of its own fit. ``up_m``: its height about the origin where known, with
    ``climb_m_s`` its climb rate and ``level_up_m`` the height about the origin it is sent to
    (the separation guard's inputs, ``mission.separation``)."""

    east_m: float
    north_m: float
    course_rad: float
    speed_m_s: float
    airspeed_m_s: float | None = None
    wind_m_s: tuple[float, float] | None = None
    up_m: float | None = None
    climb_m_s: float | None = None
    level_up_m: float | None = None


@dataclass(frozen=True, slots=True)
class TargetInfo:
    """The target as the agent knows it (truth or an estimate): position m, velocity m/s,
    acceleration m/s^2, east/north."""

    east_m: float
    north_m: float
    v_east_m_s: float = 0.0
    v_north_m_s: float = 0.0
    a_east_m_s2: float = 0.0
    a_north_m_s2: float = 0.0


@dataclass(frozen=True, slots=True)
class AgentInputs:
    """One tick's inputs. ``team_positions[j]`` is vehicle j's (east_m, north_m); the agent's own
    entry is replaced by its telemetry. An empty tuple (or a team of one) means no phase keeping.
    """

    t_s: float
    own: OwnTelemetry
    target: TargetInfo
    team_positions: tuple[tuple[float, float], ...] = ()
    #: ``team_motion[j]``: vehicle j's (course rad, ground speed m/s) where known (the joint
    #: receding-horizon plan's input, ``GuidanceParams.planner``); empty: not known
    team_motion: tuple[tuple[float, float], ...] = ()


@dataclass(frozen=True, slots=True)
class AgentState:
    """What the agent remembers between ticks.

    ``mode``: flying the ordinary field or the inverse one. ``c`` and ``c_speed_m_s``: the
    guidance parameter and the speed it was computed for (``c_speed_m_s = 0``: not yet), by
    the law ``c_law`` (the mission may switch laws between ticks).
    ``c_radius_m``: the field radius c was computed for (r_d, or the radius actuator's r_eff).
    ``next_switch_check_t_s``: when the ILVF rule is next evaluated.
    ``radius_m`` and ``radius_t_s``: the radius actuator's filtered r_eff (before rounding to
    its step) and the time it was last updated (0 and -inf: not yet; it starts at r_d).
    """

    mode: FieldMode = "field"
    c: float = FREW_C
    c_speed_m_s: float = 0.0
    c_law: str = ""
    next_switch_check_t_s: float = -math.inf
    c_radius_m: float = 0.0
    radius_m: float = 0.0
    radius_t_s: float = -math.inf
    #: the receding-horizon planner's plan (``GuidanceParams.planner``; None: not yet): the
    #: vehicle's own, and the team's it is part of (a joint plan; None: planned alone)
    plan: hz.Plan | None = None
    team_plan: hz.TeamPlan | None = None
    #: the target velocity the planner took to be steady (None: none yet), and until when the
    #: field is flown after the target's last manoeuvre (``HorizonParams.manoeuvre_dv_m_s``)
    manoeuvre_ref: tuple[float, float] | None = None
    field_until_s: float = -math.inf


@dataclass(frozen=True, slots=True)
class Command:
    """What the autopilot adapter turns into setpoints.

    ``course_rad`` (clockwise from north) is lag-compensated for the eq. (2) loop;
    ``field_course_rad`` is the uncompensated desired ground course and
    ``course_rate_ff_rad_s`` its rate along the vehicle's motion (for adapters that take a rate).
    ``speed_m_s`` is the ground-speed command within the envelope; ``airspeed_m_s``, when the
    wind is known (``guidance.wind``), the airspeed that flies it there, within the airframe's
    limits: what an autopilot whose speed setpoint is an airspeed is to be given.
    ``actuator`` is the phase actuator that acted and ``radius_m`` the radius the field was
    flown around (r_d, or the radius actuator's r_eff; 0: not stated). ``min_up_m`` /
    ``max_up_m``: the band of heights about the origin the vehicle must keep to for
    separation (``mission.separation``; None: no bound), which the altitude it is sent is
    held to.
    """

    course_rad: float
    speed_m_s: float
    field_course_rad: float
    course_rate_ff_rad_s: float
    c: float
    inverse: bool
    actuator: PhaseActuator = "speed"
    radius_m: float = 0.0
    airspeed_m_s: float | None = None
    min_up_m: float | None = None
    max_up_m: float | None = None


@dataclass(frozen=True, slots=True)
class AgentEvent:
    """Something worth logging: ``kind`` is a short fixed word, ``detail`` free text."""

    t_s: float
    kind: str
    detail: str = ""


_NO_EVENTS: tuple[AgentEvent, ...] = ()


def predict_own(
    own: OwnTelemetry,
    course_cmd_rad: float,
    speed_cmd_m_s: float,
    envelope: VehicleEnvelope,
    dt_s: float,
) -> OwnTelemetry:
    """Where the eq. (2) vehicle will be after ``dt_s`` s under the held (course, speed)
    command: course rate k * wrap(command - course) saturated at the envelope's limit and held,
    acceleration ``speed_gain_per_s`` * (command - speed) saturated and held (the command
    clamped to the envelope, the speed never past it), position along the exact arc. The
    latency compensation of ``mission.agent`` steers on this: ``plant.step`` without holding a
    measured speed within the envelope. ``dt_s = 0`` returns ``own`` itself."""
    if dt_s == 0.0:
        return own
    start = plant.FixedWingState(own.east_m, own.north_m, own.course_rad, own.speed_m_s)
    ahead = plant.step(start, course_cmd_rad, speed_cmd_m_s, envelope, dt_s, hold_envelope=False)
    return OwnTelemetry(ahead.east_m, ahead.north_m, ahead.course_rad, ahead.speed_m_s)


def _check_inputs(inputs: AgentInputs) -> None:
    own, tgt = inputs.own, inputs.target
    total = (
        inputs.t_s
        + own.east_m
        + own.north_m
        + own.course_rad
        + own.speed_m_s
        + tgt.east_m
        + tgt.north_m
        + tgt.v_east_m_s
        + tgt.v_north_m_s
        + tgt.a_east_m_s2
        + tgt.a_north_m_s2
    )
    for e, n in inputs.team_positions:
        total += e + n
    # a sum of finite floats is finite (short of overflow); a NaN or inf anywhere is not
    if math.isfinite(total):
        if own.speed_m_s < 0.0:
            raise ValueError(f"agent input own.speed_m_s must be >= 0, got {own.speed_m_s!r}")
        return
    named = {
        "t_s": inputs.t_s,
        "own.east_m": own.east_m,
        "own.north_m": own.north_m,
        "own.course_rad": own.course_rad,
        "own.speed_m_s": own.speed_m_s,
        "target.east_m": tgt.east_m,
        "target.north_m": tgt.north_m,
        "target.v_east_m_s": tgt.v_east_m_s,
        "target.v_north_m_s": tgt.v_north_m_s,
        "target.a_east_m_s2": tgt.a_east_m_s2,
        "target.a_north_m_s2": tgt.a_north_m_s2,
    }
    for j, (e, n) in enumerate(inputs.team_positions):
        named[f"team_positions[{j}]"] = e + n
    for name, value in named.items():
        if not math.isfinite(value):
            raise ValueError(f"agent input {name} must be finite, got {value!r}")
    raise ValueError("agent inputs overflow to a non-finite sum")


def _design_speed(speed_m_s: float, step_m_s: float) -> float:
    """``speed_m_s`` rounded up to the c update step (at least one step)."""
    return max(math.ceil(speed_m_s / step_m_s - 1e-9), 1) * step_m_s


def _guidance_c(
    state: AgentState, params: AgentParams, speed_m_s: float, radius_m: float
) -> AgentState:
    g = params.guidance
    if g.law == "frew":
        c = FREW_C
    elif g.law == "fixed":
        assert g.c is not None  # checked in GuidanceParams
        c = g.c
    else:
        # design for the speed rounded up to the update step, so that the field stays flyable
        # at every speed up to the one it was computed for
        design_speed = _design_speed(speed_m_s, g.c_update_speed_step_m_s)
        if (
            design_speed == state.c_speed_m_s
            and state.c_law == g.law
            and radius_m == state.c_radius_m
        ):
            return state
        env = params.envelope
        c = optimal_c(radius_m, design_speed, env.max_course_rate_rad_s, g.curvature_margin)
        return replace(state, c=c, c_speed_m_s=design_speed, c_law=g.law, c_radius_m=radius_m)
    if c == state.c and state.c_speed_m_s > 0.0 and state.c_law == g.law:
        return state
    return replace(state, c=c, c_speed_m_s=max(speed_m_s, 1e-9), c_law=g.law, c_radius_m=radius_m)


#: how far outside the circle a leader is held to W r_d^2 / r (``PhaseParams.lead_speed_m_s``);
#: the hold fades out over as far again
_LEAD_BAND_M = 10.0


def _speed_command(
    inputs: AgentInputs, params: AgentParams, state: AgentState, radius_m: float
) -> float:
    """v_w of eq. (27) for the team's phases; with ``predictive`` each phase is led by its
    arrival lead onto the field's circle ``radius_m`` (r_d, or the radius actuator's r_eff)."""
    env, ph, g = params.envelope, params.phase, params.guidance
    team = inputs.team_positions
    if ph.law == "none" or len(team) < 2 or ph.gain_per_s == 0.0:
        return env.cruise_speed_m_s
    if not 0 <= params.index < len(team):
        raise ValueError(f"vehicle index {params.index} outside a team of {len(team)}")
    tx, ty, sign = inputs.target.east_m, inputs.target.north_m, g.orbit_sign
    # at a held ground speed s, a target moving at v_t makes the phase rate uneven round the
    # orbit; steer on the orbit-time phase theta + v_t . r_hat / s instead (first order in
    # v_t / s), which a team at s on one circle advances evenly
    tv_e, tv_n = inputs.target.v_east_m_s, inputs.target.v_north_m_s
    time_phase = (
        ph.actuator == "radius" and ph.radius_phase == "orbit_time" and (tv_e != 0.0 or tv_n != 0.0)
    )
    inv_s = 1.0 / env.cruise_speed_m_s
    phases: list[float] = []
    own_r = 0.0
    for j, (e, n) in enumerate(team):
        if j == params.index:
            e, n = inputs.own.east_m, inputs.own.north_m
        x, y = e - tx, n - ty
        theta = sign * math.atan2(y, x)
        r = math.hypot(x, y)
        if ph.predictive:
            theta += phase.arrival_phase_lead(r, radius_m, state.c)
        if time_phase and r > 0.0:
            theta += (tv_e * x + tv_n * y) / r * inv_s
        if j == params.index:
            own_r = r
        phases.append(theta)
    errors = phase.seat_errors(phases) if ph.law == "paper" else phase.neighbour_errors(phases)
    error, base = errors[params.index], env.cruise_speed_m_s
    if ph.lead_speed_m_s is not None and ph.actuator == "speed":
        # the vehicle furthest behind its seat flies the lead speed and the others slower by
        # the law: the team closes its gaps at the lead speed (not about cruise); the radius
        # actuator's wanted speed stays about cruise (it holds its speed)
        error, base = error - max(errors), ph.lead_speed_m_s
        if ph.lead_held_outside:
            # the team has gathered: on the circle, keep a share of the turn rate to spare
            base = min(base, ph.held_lead_turn_share * env.max_course_rate_rad_s * radius_m)
        held = ph.lead_held_outside and own_r > radius_m
        if held or radius_m < own_r < radius_m + 2.0 * _LEAD_BAND_M:
            # just outside the circle, no faster than the speed whose full turn rate tightens
            # the orbit (v / W <= r_d^2 / r < r_d): at W r_d itself there is no turn to spare,
            # and a leader blown out stays out until its speed drops; faded out over a second
            # band (a leader still flying in from afar keeps the lead), unless held outside
            cap = env.max_course_rate_rad_s * radius_m * radius_m / own_r
            fade = 1.0 if held else min(1.0, (radius_m + 2.0 * _LEAD_BAND_M - own_r) / _LEAD_BAND_M)
            base = min(base, base - fade * (base - cap))
    return phase.phase_speed(
        error,
        own_r,
        g.radius_m,
        base,
        ph.gain_per_s,
        env.min_speed_m_s,
        env.max_speed_m_s,
        distance_weight=not ph.predictive,
    )


def radius_bounds(params: AgentParams, speed_m_s: float) -> tuple[float, float]:
    """The radius actuator's band (m) at ``speed_m_s``: r_d -/+ ``radius_band_m``, the lower
    edge raised to 1.05 turn radii at the speed's c design step and ``curvature_margin`` of the
    course-rate limit (v / r_eff within the limit, with room for the field to converge), but
    never above r_d (where r_d itself is that tight, the band only widens)."""
    g, env, ph = params.guidance, params.envelope, params.phase
    rd = g.radius_m
    design = _design_speed(max(speed_m_s, env.cruise_speed_m_s), g.c_update_speed_step_m_s)
    turn_m = design / (g.curvature_margin * env.max_course_rate_rad_s)
    lower = min(max(rd - ph.radius_band_m, 1.05 * turn_m), rd)
    return lower, rd + ph.radius_band_m


def effective_radius(v_wanted_m_s: float, params: AgentParams, speed_m_s: float) -> float:
    """r_eff = r_d v_cruise / v_w (the radius on which cruise speed gives the phase rate
    v_w / r_d the speed law asks for), clamped to ``radius_bounds`` at ``speed_m_s``. Raises
    ValueError for a wanted speed that is not finite and > 0."""
    lower, upper = radius_bounds(params, speed_m_s)
    return _effective_radius(v_wanted_m_s, params, lower, upper)


def _effective_radius(
    v_wanted_m_s: float, params: AgentParams, lower: float, upper: float
) -> float:
    if not (math.isfinite(v_wanted_m_s) and v_wanted_m_s > 0.0):
        raise ValueError(f"wanted speed must be finite and > 0, got {v_wanted_m_s!r}")
    r = params.guidance.radius_m * params.envelope.cruise_speed_m_s / v_wanted_m_s
    return min(max(r, lower), upper)


def _polar_radius(
    inputs: AgentInputs, params: AgentParams, v_wanted_m_s: float, lower: float, upper: float
) -> float:
    """r_eff = u / omega_w (``PhaseParams.radius_phase = "polar"``): the radius on which the
    relative speed along the orbit at cruise ground speed, u, gives the polar rate the speed
    law wants, v_w / r_d; clamped to [lower, upper]."""
    if not (math.isfinite(v_wanted_m_s) and v_wanted_m_s > 0.0):
        raise ValueError(f"wanted speed must be finite and > 0, got {v_wanted_m_s!r}")
    own, tgt, g = inputs.own, inputs.target, params.guidance
    x, y = own.east_m - tgt.east_m, own.north_m - tgt.north_m
    r = math.hypot(x, y)
    if r == 0.0:
        return _effective_radius(v_wanted_m_s, params, lower, upper)
    radial = (tgt.v_east_m_s * x + tgt.v_north_m_s * y) / r
    along = g.orbit_sign * (tgt.v_north_m_s * x - tgt.v_east_m_s * y) / r  # v_t . t_hat
    s = params.envelope.cruise_speed_m_s
    u = -along + math.sqrt(max(s * s - radial * radial, 0.0))
    if u <= 0.0:  # the target outruns the orbit here: the widest orbit slows the phase least
        return upper
    return min(max(u * g.radius_m / v_wanted_m_s, lower), upper)


def _field_radius(radius_m: float, rd: float, step_m: float, lower: float, upper: float) -> float:
    """``radius_m`` rounded to the grid r_d + j step, kept within [lower, upper]."""
    r = rd + round((radius_m - rd) / step_m) * step_m
    if r < lower:
        r = rd + math.ceil((lower - rd) / step_m - 1e-9) * step_m
    elif r > upper:
        r = rd + math.floor((upper - rd) / step_m + 1e-9) * step_m
    return min(max(r, lower), upper)


def _radius_actuator(
    state: AgentState, inputs: AgentInputs, params: AgentParams, speed_now: float
) -> tuple[AgentState, float]:
    """The radius actuator's tick: the speed law's v_w (on the field flown last tick), its
    r_eff, slewed at ``radius_rate_m_s`` from the last one, rounded to the field's step; c for
    that field. Returns the new state and the field's radius."""
    g, ph = params.guidance, params.phase
    rd, step = g.radius_m, ph.radius_step_m
    lower, upper = radius_bounds(params, speed_now)
    prev = state.radius_m if state.radius_m > 0.0 else rd
    prev_field = _field_radius(prev, rd, step, lower, upper)
    s = _guidance_c(state, params, speed_now, prev_field)
    v_wanted = _speed_command(inputs, params, s, prev_field)
    tgt = inputs.target
    rate = ph.radius_rate_m_s
    if ph.radius_phase == "polar" and (tgt.v_east_m_s != 0.0 or tgt.v_north_m_s != 0.0):
        wanted = _polar_radius(inputs, params, v_wanted, lower, upper)
        rate += math.hypot(tgt.v_east_m_s, tgt.v_north_m_s)
    else:
        wanted = _effective_radius(v_wanted, params, lower, upper)
    # the first tick (radius_t_s = -inf) starts from r_d; time going back holds the radius
    dt = inputs.t_s - state.radius_t_s
    max_change = rate * dt if 0.0 < dt < math.inf else 0.0
    filtered = prev + min(max(wanted - prev, -max_change), max_change)
    # the band moves with speed: a radius the vehicle can no longer turn is left at once
    filtered = min(max(filtered, lower), upper)
    radius = _field_radius(filtered, rd, step, lower, upper)
    s = _guidance_c(s, params, speed_now, radius)
    # (built directly: this runs every tick, and dataclasses.replace costs ten times more)
    new_state = AgentState(
        mode=s.mode,
        c=s.c,
        c_speed_m_s=s.c_speed_m_s,
        c_law=s.c_law,
        next_switch_check_t_s=s.next_switch_check_t_s,
        c_radius_m=s.c_radius_m,
        radius_m=filtered,
        radius_t_s=inputs.t_s,
    )
    return new_state, radius


def agent_step(
    state: AgentState, inputs: AgentInputs, params: AgentParams
) -> tuple[AgentState, Command, tuple[AgentEvent, ...]]:
    """One control tick for one vehicle: (state, inputs, params) -> (state, command, events).

    1. c: the optimal c of section 4.1 for the vehicle's current speed (recomputed when the
       speed has moved by ``c_update_speed_step_m_s``), 2 for Frew's field, or the fixed c.
    2. ILVF switch (law ``proposed``): every ``switch_check_period_s``, outside the circle,
       predict the smallest r - r_d of flying the ordinary field from here
       (``guidance.course.predict_min_distance_error``) and apply
       ``guidance.course.inverse_field_wanted``.
       Inside the circle the ordinary field (which leads out to it) is always flown. The check
       is skipped when it cannot matter: far outside (> 2.2 turn radii) or already aligned with a
       flyable field.
    3. Speed: cruise, or the phase law's speed (eq. 27) from the team's phases. With the
       ``radius`` actuator the speed stays at cruise and the law's speed is flown as the
       field's radius instead (``effective_radius``); c, the ILVF switch and the field then use
       that radius (all of this before step 2).
    4. Course: the field direction in the target's frame (eq. 8/14), corrected for the target's
       motion (eq. 15) to a ground velocity at the commanded speed (the ground speed held at
       cruise with the ``radius`` actuator), and lag-compensated with the ground course's own
       rate (``guidance.course.course_command``).

    Parameters
    ----------
    state : AgentState
        What the agent remembered from its last tick (``AgentState()`` at the start).
    inputs : AgentInputs
        This tick: time (s), own telemetry (m east/north, course rad clockwise from north, m/s),
        the target (truth or estimate: m, m/s, m/s^2) and the team's positions (m).
    params : AgentParams
        The vehicle's index in the team, its envelope, the guidance and phase laws.

    Returns
    -------
    (AgentState, Command, tuple of AgentEvent)
        The new state (``state`` itself when nothing changed), the (course, speed) command, and
        the events of this tick (ILVF switches), usually empty.

    Raises
    ------
    ValueError
        On a non-finite input (naming it), a negative speed, or an index outside the team.

    Pure: never mutates its arguments. The command is always finite, its speed within the
    envelope, its implied course rate k * (command - course) within the course-rate limit.
    """
    _check_inputs(inputs)
    env, g = params.envelope, params.guidance
    own, tgt = inputs.own, inputs.target
    speed_now = own.speed_m_s if own.speed_m_s > 0.0 else env.cruise_speed_m_s
    by_radius = params.phase.actuator == "radius"
    if by_radius:
        new_state, radius = _radius_actuator(state, inputs, params, speed_now)
    else:
        radius = g.radius_m
        new_state = _guidance_c(state, params, speed_now, radius)
    c = new_state.c

    x, y = own.east_m - tgt.east_m, own.north_m - tgt.north_m
    vx = own.speed_m_s * math.sin(own.course_rad) - tgt.v_east_m_s
    vy = own.speed_m_s * math.cos(own.course_rad) - tgt.v_north_m_s
    events = _NO_EVENTS

    if g.uses_inverse_field:
        if inputs.t_s >= new_state.next_switch_check_t_s:
            new_state, events = _switch_rule(new_state, inputs, params, x, y, vx, vy, c, radius)
    elif new_state.mode == "inverse":
        # the switch is off (e.g. the mission's track stage after an approach that used it):
        # never stay on the inverse field, which leads away from the circle
        new_state = replace(new_state, mode="field")
        events = (AgentEvent(inputs.t_s, "inverse-field-off", "switch disabled"),)

    inverse = new_state.mode == "inverse"
    if by_radius:
        speed_cmd = env.cruise_speed_m_s
    else:
        speed_cmd = _speed_command(inputs, params, new_state, radius)
    rel_course, rel_rate = _relative_course(x, y, vx, vy, c, inverse, tgt, params, radius)

    if (
        tgt.v_east_m_s == 0.0
        and tgt.v_north_m_s == 0.0
        and tgt.a_east_m_s2 == 0.0
        and (tgt.a_north_m_s2 == 0.0)
    ):
        ground_course, ground_rate = rel_course, rel_rate
        if g.turn_slow_rad is not None and not by_radius:
            speed_cmd = min(speed_cmd, _turn_slow_cap(own.course_rad, ground_course, g, env))
    else:
        max_speed = env.max_speed_m_s
        if by_radius:
            # the autopilot holds its own speed: the ground velocity keeps cruise speed (no
            # relative-speed law, no speed cap: there is no speed to command)
            relative_speed = False
        else:
            relative_speed = g.relative_speed
            if g.speed_cap:
                max_speed = _speed_cap(x, y, math.hypot(vx, vy), tgt, params, radius)
        ground_course, ground_rate, speed_cmd = _ground_course(
            rel_course, rel_rate, tgt, speed_cmd, env, relative_speed, max_speed
        )
        if g.turn_slow_rad is not None and not by_radius:
            cap = _turn_slow_cap(own.course_rad, ground_course, g, env)
            if cap < speed_cmd:
                # the same field direction flown at the capped ground speed (eq. 15 again)
                ground_course, ground_rate, speed_cmd = _ground_course(
                    rel_course, rel_rate, tgt, cap, env, False, cap
                )

    cmd_course = course_command(own.course_rad, ground_course, ground_rate, params.course_loop)
    command = Command(
        course_rad=cmd_course,
        speed_m_s=speed_cmd,
        field_course_rad=ground_course,
        course_rate_ff_rad_s=ground_rate,
        c=c,
        inverse=inverse,
        actuator=params.phase.actuator,
        radius_m=radius,
    )
    if g.planner == "horizon":
        new_state, command, planned = _horizon_command(new_state, inputs, params, command)
        events = (*events, *planned)
    return new_state, command, events


def _seat_path(inputs: AgentInputs, params: AgentParams, velocity: hz.Array) -> hz.Array | None:
    """The vehicle's seat over the plan (``horizon.seat_path``: the teammates predicted round
    the circle at cruise speed); None without phase keeping."""
    env, ph, g = params.envelope, params.phase, params.guidance
    team = inputs.team_positions
    if ph.law == "none" or len(team) < 2:
        return None
    if not 0 <= params.index < len(team):
        raise ValueError(f"vehicle index {params.index} outside a team of {len(team)}")
    tx, ty, sign = inputs.target.east_m, inputs.target.north_m, g.orbit_sign
    own = sign * math.atan2(inputs.own.north_m - ty, inputs.own.east_m - tx)
    others = [
        sign * math.atan2(n - ty, e - tx) for j, (e, n) in enumerate(team) if j != params.index
    ]
    return hz.seat_path(
        own,
        np.array(others),
        velocity,
        g.radius_m,
        sign,
        env.cruise_speed_m_s,
        g.horizon.step_s,
    )


def _field_guess(problem: hz.TeamProblem, params: AgentParams, velocity: hz.Array) -> hz.Array:
    """The field's own controls over the horizon, per block (2, blocks, n): every vehicle of
    ``problem`` flown on the track stage's field (without phase keeping, at cruise speed)
    around the predicted target, its course rate that of eq. (2) under the lag-compensated
    command. The joint plan's starting point."""
    g, env = params.guidance, params.envelope
    hp = g.horizon
    nb, per, dt = hp.blocks, hp.steps_per_block, hp.step_s
    n = problem.count
    out = np.empty((2, nb, n))
    w, k_gain = env.max_course_rate_rad_s, env.course_gain_per_s
    cruise = env.cruise_speed_m_s
    c = FREW_C if g.law == "frew" else (g.c if g.law == "fixed" and g.c is not None else FREW_C)
    target = problem.target
    for i in range(n):
        x = float(problem.east_m[i])
        y = float(problem.north_m[i])
        chi = float(problem.course_rad[i])
        speed = float(problem.speed_m_s[i])
        for b in range(nb):
            rate_sum = 0.0
            speed_sum = 0.0
            for j in range(per):
                step_k = b * per + j
                tve, tvn = float(velocity[step_k, 0]), float(velocity[step_k, 1])
                rx = x - float(target[step_k, 0])
                ry = y - float(target[step_k, 1])
                vx = speed * math.sin(chi) - tve
                vy = speed * math.cos(chi) - tvn
                tgt = TargetInfo(0.0, 0.0, tve, tvn)
                rel_course, rel_rate = _relative_course(
                    rx, ry, vx, vy, c, False, tgt, params, g.radius_m
                )
                if tve == 0.0 and tvn == 0.0:
                    course, rate, speed_cmd = rel_course, rel_rate, cruise
                else:
                    course, rate, speed_cmd = _ground_course(
                        rel_course, rel_rate, tgt, cruise, env, g.relative_speed, env.max_speed_m_s
                    )
                u = min(max(k_gain * wrap_pi(course - chi) + rate, -w), w)
                x += speed * math.sin(chi) * dt
                y += speed * math.cos(chi) * dt
                chi += u * dt
                accel = min(
                    max(env.speed_gain_per_s * (speed_cmd - speed), -env.max_accel_m_s2),
                    env.max_accel_m_s2,
                )
                speed += accel * dt
                rate_sum += u
                speed_sum += speed_cmd
            out[0, b, i] = rate_sum / per
            out[1, b, i] = speed_sum / per
    return out


def _horizon_command(
    state: AgentState, inputs: AgentInputs, params: AgentParams, fallback: Command
) -> tuple[AgentState, Command, tuple[AgentEvent, ...]]:
    """``planner = "horizon"``: plan again every ``replan_s`` (from the vehicle's state, on the
    target's predicted path and the seat), and fly the plan at this tick: its course with its
    rate fed forward (``course_command``), its speed command. The field's ``fallback`` is
    flown if the plan cannot be made (reported once per episode as ``horizon-fallback``),
    around a target slower than ``min_target_speed_m_s``, and for ``manoeuvre_settle_s`` after
    the target's estimated velocity moved ``manoeuvre_dv_m_s`` from the one the planner took
    to be steady (reported as ``horizon-hold`` where a plan was being flown)."""
    g, env, ph = params.guidance, params.envelope, params.phase
    if ph.actuator == "radius":
        # the autopilot holds its own airspeed: the plan's speeds would not be flown
        return state, fallback, _NO_EVENTS
    hp = g.horizon
    own, tgt = inputs.own, inputs.target
    if math.hypot(tgt.v_east_m_s, tgt.v_north_m_s) < hp.min_target_speed_m_s:
        # a still target: the field holds its circle exactly (a new plan starts when it moves)
        if state.plan is None:
            return state, fallback, _NO_EVENTS
        return replace(state, plan=None, team_plan=None), fallback, _NO_EVENTS
    velocity_now = (tgt.v_east_m_s, tgt.v_north_m_s)
    ref = state.manoeuvre_ref
    if ref is None:
        state = replace(state, manoeuvre_ref=velocity_now)
    else:
        change = math.hypot(velocity_now[0] - ref[0], velocity_now[1] - ref[1])
        if change > hp.manoeuvre_dv_m_s:
            until = inputs.t_s + hp.manoeuvre_settle_s
            state = replace(state, manoeuvre_ref=velocity_now, field_until_s=until)
            if state.plan is not None:
                detail = (
                    f"the target's velocity changed by {change:.1f} m/s: the field flies"
                    f" until {hp.manoeuvre_settle_s:g} s after its manoeuvre"
                )
                hold = (AgentEvent(inputs.t_s, "horizon-hold", detail),)
                return replace(state, plan=None, team_plan=None), fallback, hold
    if inputs.t_s < state.field_until_s:
        return replace(state, plan=None, team_plan=None), fallback, _NO_EVENTS
    current = state.plan
    events = _NO_EVENTS
    team_size = max(len(inputs.team_positions), 1)
    if (
        current is None
        or inputs.t_s < current.t_s
        or hz.replan_due(inputs.t_s, current.t_s, hp.replan_s, params.index, team_size)
    ):
        air = hz.Airframe(
            env.min_speed_m_s,
            env.max_speed_m_s,
            env.max_accel_m_s2,
            env.max_course_rate_rad_s,
            env.speed_gain_per_s,
        )
        steps = hp.blocks * hp.steps_per_block
        path, velocity = hz.predict_target(
            (tgt.v_east_m_s, tgt.v_north_m_s),
            (tgt.a_east_m_s2, tgt.a_north_m_s2),
            steps,
            hp.step_s,
            hp.manoeuvre_fade_s,
        )
        v_end = (float(velocity[-1, 0]), float(velocity[-1, 1]))
        warm = current if current is not None and inputs.t_s >= current.t_s else None
        team = inputs.team_positions
        joint = (
            hp.joint
            and ph.law != "none"
            and 2 <= len(team) <= hp.joint_max_vehicles
            and len(inputs.team_motion) == len(team)
        )
        try:
            if joint:
                if not 0 <= params.index < len(team):
                    raise ValueError(f"vehicle index {params.index} outside a team of {len(team)}")
                positions = [
                    (own.east_m, own.north_m) if j == params.index else team[j]
                    for j in range(len(team))
                ]
                motion = [
                    (own.course_rad, own.speed_m_s) if j == params.index else inputs.team_motion[j]
                    for j in range(len(team))
                ]
                team_problem = hz.TeamProblem(
                    east_m=np.array([e - tgt.east_m for e, _ in positions]),
                    north_m=np.array([n - tgt.north_m for _, n in positions]),
                    course_rad=np.array([c for c, _ in motion]),
                    speed_m_s=np.array([v for _, v in motion]),
                    target=path,
                    target_velocity=v_end,
                    radius_m=g.radius_m,
                    airframe=air,
                    target_velocities=velocity,
                    orbit_sign=g.orbit_sign,
                )
                team_warm = state.team_plan if warm is not None else None
                team_plan = hz.plan_team(
                    inputs.t_s,
                    team_problem,
                    hp,
                    team_warm,
                    partial(_field_guess, team_problem, params, velocity),
                )
                current = team_plan.member(params.index, hp.block_s)
                state = replace(state, team_plan=team_plan)
            else:
                problem = hz.Problem(
                    east_m=own.east_m - tgt.east_m,
                    north_m=own.north_m - tgt.north_m,
                    course_rad=own.course_rad,
                    speed_m_s=own.speed_m_s if own.speed_m_s > 0.0 else env.cruise_speed_m_s,
                    target=path,
                    target_velocity=v_end,
                    radius_m=g.radius_m,
                    orbit_sign=g.orbit_sign,
                    airframe=air,
                    seat=_seat_path(inputs, params, velocity),
                )
                current = hz.plan(inputs.t_s, problem, hp, warm)
                state = replace(state, team_plan=None)
        except ValueError as exc:
            if state.plan is not None:
                events = (AgentEvent(inputs.t_s, "horizon-fallback", str(exc)),)
            return replace(state, plan=None, team_plan=None), fallback, events
        if state.plan is None:
            detail = f"planning {hp.horizon_s:g} s ahead every {hp.replan_s:g} s"
            events = (AgentEvent(inputs.t_s, "horizon-on", detail),)
        state = replace(state, plan=current)
    course, rate, speed = current.at(inputs.t_s)
    speed = env.clamp_speed(speed)
    cmd_course = course_command(own.course_rad, course, rate, params.course_loop)
    command = replace(
        fallback,
        course_rad=cmd_course,
        speed_m_s=speed,
        field_course_rad=wrap_pi(course),
        course_rate_ff_rad_s=rate,
        inverse=False,
        radius_m=g.radius_m,
    )
    return state, command, events


def _switch_rule(
    state: AgentState,
    inputs: AgentInputs,
    params: AgentParams,
    x: float,
    y: float,
    vx: float,
    vy: float,
    c: float,
    rd: float,
) -> tuple[AgentState, tuple[AgentEvent, ...]]:
    g, env = params.guidance, params.envelope
    sign = g.orbit_sign
    w = env.max_course_rate_rad_s
    next_check = inputs.t_s + g.switch_check_period_s
    r = math.hypot(x, y)
    rel_speed = math.hypot(vx, vy)
    using_inverse = state.mode == "inverse"
    if r <= rd or rel_speed <= 0.0:
        wanted = False
    else:
        rel_course = math.atan2(vx, vy)
        turn_radius = rel_speed / w
        skip = False
        if not using_inverse:
            if r - rd > 2.2 * turn_radius:
                skip = True
            else:
                f_course, _ = course_and_rate(x, y, vx, vy, _field(rd, c, sign, False))
                flyable = peak_curvature(rd, c)[0] <= w / rel_speed * (1.0 + 1e-9)
                skip = flyable and abs(wrap_pi(f_course - rel_course)) < 0.01
        if skip:
            wanted = False
        else:
            predicted = predict_min_distance_error(
                x, y, rel_course, rel_speed, _field(rd, c, sign, False), params.course_loop
            )
            wanted = inverse_field_wanted(
                using_inverse, predicted, g.switch_enter_below_m, g.switch_leave_above_m
            )
    mode: FieldMode = "inverse" if wanted else "field"
    events = _NO_EVENTS
    if wanted != using_inverse:
        kind = "inverse-field-on" if wanted else "inverse-field-off"
        events = (AgentEvent(inputs.t_s, kind, f"r - r_d = {r - rd:.1f} m"),)
    return replace(state, mode=mode, next_switch_check_t_s=next_check), events


def _ground_course(
    rel_course: float,
    rel_rate: float,
    tgt: TargetInfo,
    speed_cmd: float,
    env: VehicleEnvelope,
    relative_speed: bool,
    max_speed_m_s: float,
) -> tuple[float, float, float]:
    """Eq. (15): ground velocity v_g = v_t + lambda d for the commanded speed
    (``moving_target.moving_target_velocity``), its course and the course's rate (d turning
    at ``rel_rate``, the target accelerating; lambda or |v_g| held constant)."""
    dx, dy = math.sin(rel_course), math.cos(rel_course)
    gx, gy, lam, held = moving_target_velocity_unchecked(
        dx,
        dy,
        tgt.v_east_m_s,
        tgt.v_north_m_s,
        speed_cmd,
        env.min_speed_m_s,
        max_speed_m_s,
        relative_speed,
    )
    # d/dt d = rel_rate * (cos chi, -sin chi)
    px, py = rel_rate * dy, -rel_rate * dx
    ax = tgt.a_east_m_s2 + lam * px
    ay = tgt.a_north_m_s2 + lam * py
    along = gx * dx + gy * dy
    if held and abs(along) > 1e-6:
        # |v_g| held constant: lambda_dot from v_g . d(v_g)/dt = 0
        lam_dot = -(gx * ax + gy * ay) / along
        ax += lam_dot * dx
        ay += lam_dot * dy
    g2 = gx * gx + gy * gy
    if g2 <= 1e-12:
        return rel_course, 0.0, env.min_speed_m_s
    course = math.atan2(gx, gy)
    rate = (gy * ax - gx * ay) / g2
    # (clamped again only against rounding: the velocity was already scaled it in)
    return course, rate, min(max(math.sqrt(g2), env.min_speed_m_s), max_speed_m_s)


def _turn_slow_cap(
    course_rad: float, wanted_rad: float, g: GuidanceParams, env: VehicleEnvelope
) -> float:
    """The ground-speed cap of ``GuidanceParams.turn_slow_rad`` for a course error."""
    assert g.turn_slow_rad is not None
    start, full = g.turn_slow_rad
    error = abs(wrap_pi(wanted_rad - course_rad))
    share = min(max((error - start) / (full - start), 0.0), 1.0)
    return env.max_speed_m_s - share * (env.max_speed_m_s - env.min_speed_m_s)


def orbit_axes(speed_m_s: float, params: AgentParams, rd: float) -> tuple[float, float]:
    """Semi-axes (along, across the target's motion) of the orbit flown around a target moving
    at ``speed_m_s``: the planned one about the circle ``rd`` with ``orbit_plan = "ellipse"``,
    else the circle."""
    g, env = params.guidance, params.envelope
    if g.orbit_plan == "ellipse" and speed_m_s >= 0.5:
        return planned_orbit_axes(
            rd,
            speed_m_s,
            env.min_speed_m_s,
            env.max_course_rate_rad_s,
            g.plan_margin,
            g.plan_max_stretch,
        )
    return rd, rd


def _speed_cap(
    x: float, y: float, rel_speed: float, tgt: TargetInfo, params: AgentParams, rd: float
) -> float:
    """The ground-speed limit of ``GuidanceParams.speed_cap``, within the envelope."""
    g, env = params.guidance, params.envelope
    speed = math.hypot(tgt.v_east_m_s, tgt.v_north_m_s)
    if speed < 0.1:
        return env.max_speed_m_s
    a, b = orbit_axes(speed, params, rd)
    profile = orbit_speed_profile(
        a,
        b,
        speed,
        env.min_speed_m_s,
        env.max_speed_m_s,
        g.speed_cap_margin * env.max_course_rate_rad_s,
    )
    orbit = PlannedOrbit(a, b, tgt.v_east_m_s / speed, tgt.v_north_m_s / speed)
    brake = g.speed_cap_brake * env.max_accel_m_s2
    cap = orbit_speed_cap(x, y, rel_speed, g.orbit_sign, orbit, profile, brake)
    return min(max(cap, env.min_speed_m_s), env.max_speed_m_s)


def _relative_course(
    x: float,
    y: float,
    vx: float,
    vy: float,
    c: float,
    inverse: bool,
    tgt: TargetInfo,
    params: AgentParams,
    rd: float,
) -> tuple[float, float]:
    """Course and rate of the field in the target's frame: the circle ``rd`` (the paper's r_d,
    or the radius actuator's r_eff), or (``orbit_plan = "ellipse"``) the planned orbit around
    the target (``orbit_plan.planned_orbit_axes``: the circle while it is flyable, else the
    flyable ellipse closest to it, aligned with the target's velocity)."""
    g = params.guidance
    sign = g.orbit_sign
    speed = math.hypot(tgt.v_east_m_s, tgt.v_north_m_s)
    if g.orbit_plan == "ellipse" and not inverse and speed >= 0.5:
        a, b = orbit_axes(speed, params, rd)
        if a != b:
            ux, uy = tgt.v_east_m_s / speed, tgt.v_north_m_s / speed
            orbit = PlannedOrbit(a, b, ux, uy)
            return ellipse_course_and_rate(x, y, vx, vy, _field(rd, c, sign, False), orbit)
    return course_and_rate(x, y, vx, vy, _field(rd, c, sign, inverse))


@lru_cache(maxsize=256)
def _field(radius_m: float, c: float, orbit_sign: int, inverse: bool) -> FieldParams:
    """The (validated, immutable) field for these parameters, built once per c rather than on
    every tick: c changes only when the speed moves by ``c_update_speed_step_m_s`` or the
    radius actuator's r_eff by ``PhaseParams.radius_step_m``."""
    return FieldParams(radius_m, c, orbit_sign, inverse)
