"""Target motion models on the paper's state X = [x, vx, y, vy, ax, ay] (eqs 16-21).

x is metres east, y metres north; velocities in m/s, accelerations in m/s^2. Every model is linear
for a fixed time step (the turn models for a fixed turn rate), so it is a transition matrix F(dt)
and a process-noise covariance Q(dt), both shape (6, 6). ``propagate`` applies the model to a
stack of states (the unscented filter's sigma points).

All matrices are computed in closed form, with series expansions where the closed form cancels
(omega * dt -> 0), so the turn models are exact and smooth through a zero turn rate.
"""

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Literal

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

STATE_DIM = 6
"""Length of the state vector X = [x, vx, y, vy, ax, ay]."""
POS = (0, 2)
"""Indices of the position components (east, north) in X."""
VEL = (1, 3)
"""Indices of the velocity components (east, north) in X."""
ACC = (4, 5)
"""Indices of the acceleration components (east, north) in X."""

ModelKind = Literal["cv", "ca", "turn", "ct"]

# below this |omega * dt| the turn models use Taylor series (relative error ~ (omega dt)^4 / 100)
_SERIES_LIMIT = 2e-2


@dataclass(frozen=True, slots=True)
class MotionModel:
    """One motion model of the IMM.

    Parameters
    ----------
    kind
        ``"cv"``: constant velocity, eqs (16)-(17), white-noise acceleration on the position and
        velocity pairs, acceleration states held (no noise).
        ``"ca"``: constant acceleration, eqs (18)-(19), white-noise jerk.
        ``"turn"``: the paper's turning model, eqs (20)-(21): on each axis the acceleration
        rotates with the velocity (a' = -omega^2 v), which is exact for a constant-rate turn in
        either direction; white-noise jerk. Tends to ``"ca"`` as omega -> 0.
        ``"ct"``: the classical coordinated turn (the velocity vector rotates at omega, clockwise
        positive as courses are), white-noise acceleration, acceleration states held. Tends to
        ``"cv"`` as omega -> 0.
    noise_intensity
        Power spectral density q of the driving white noise: m^2/s^3 (acceleration noise, "cv"
        and "ct") or m^2/s^5 (jerk noise, "ca" and "turn"), per axis.
    turn_rate_rad_s
        omega for "turn" (its sign does not matter) and "ct" (clockwise positive).
    name
        A label for reports; defaults to the kind.
    """

    kind: ModelKind
    noise_intensity: float
    turn_rate_rad_s: float = 0.0
    name: str = field(default="")

    def __post_init__(self) -> None:
        if self.kind not in ("cv", "ca", "turn", "ct"):
            raise ValueError(f"unknown motion model kind {self.kind!r}")
        if not (math.isfinite(self.noise_intensity) and self.noise_intensity >= 0.0):
            raise ValueError(f"noise_intensity must be finite and >= 0, got {self.noise_intensity}")
        if not math.isfinite(self.turn_rate_rad_s):
            raise ValueError(f"turn_rate_rad_s must be finite, got {self.turn_rate_rad_s}")
        if not self.name:
            object.__setattr__(self, "name", self.kind)

    def transition(self, dt_s: float) -> FloatArray:
        """State transition matrix F(dt), shape (6, 6), read-only (eq 17, 19 or 21)."""
        return _transition(self.kind, self.turn_rate_rad_s, float(dt_s))

    def process_noise(self, dt_s: float) -> FloatArray:
        """Discrete process-noise covariance Q(dt), shape (6, 6), read-only, PSD."""
        return _process_noise(self.kind, self.turn_rate_rad_s, self.noise_intensity, float(dt_s))

    def propagate(self, states: FloatArray, dt_s: float) -> FloatArray:
        """Apply the model to states of shape (..., 6) over ``dt_s`` (no noise); a new array."""
        return states @ self.transition(dt_s).T

    def scaled(self, factor: float) -> "MotionModel":
        """The same model with its noise intensity multiplied by ``factor`` (Appendix A's Q_i)."""
        return MotionModel(
            self.kind, self.noise_intensity * factor, self.turn_rate_rad_s, self.name
        )


def _sinc(x: float) -> float:
    """sin(x)/x, exact at 0."""
    return math.sin(x) / x if abs(x) > 1e-8 else 1.0 - x * x / 6.0


#: each axis's (p, v, a) rows and columns in the state order [x, vx, y, vy, ax, ay]
_AXIS_INDEX = tuple(np.ix_(idx, idx) for idx in ((POS[a], VEL[a], ACC[a]) for a in (0, 1)))


def _axis_blocks(f3: FloatArray) -> FloatArray:
    """Embed a per-axis (p, v, a) 3x3 matrix into the 6x6 state order [x, vx, y, vy, ax, ay]."""
    out = np.zeros((STATE_DIM, STATE_DIM))
    for index in _AXIS_INDEX:
        out[index] = f3
    return out


@lru_cache(maxsize=512)
def _transition(kind: str, omega: float, dt: float) -> FloatArray:
    if kind == "cv":
        f3 = np.array([[1.0, dt, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        out = _axis_blocks(f3)
    elif kind == "ca":
        f3 = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
        out = _axis_blocks(f3)
    elif kind == "turn":
        wt = omega * dt
        s_over_w = dt * _sinc(wt)  # sin(wT)/w
        half = _sinc(0.5 * wt)
        one_minus_c_over_w2 = 0.5 * dt * dt * half * half  # (1 - cos wT)/w^2 = 2 sin^2(wT/2)/w^2
        c = math.cos(wt)
        w_s = omega * omega * s_over_w  # w sin(wT)
        f3 = np.array([[1.0, s_over_w, one_minus_c_over_w2], [0.0, c, s_over_w], [0.0, -w_s, c]])
        out = _axis_blocks(f3)
    else:  # "ct": velocity rotates clockwise at omega (east = x, north = y)
        wt = omega * dt
        s_over_w = dt * _sinc(wt)
        half = _sinc(0.5 * wt)
        one_minus_c_over_w = omega * 0.5 * dt * dt * half * half  # (1 - cos wT)/w
        c, s = math.cos(wt), math.sin(wt)
        out = np.eye(STATE_DIM)
        # clockwise rotation of (ve, vn) by wT: ve' = c ve + s vn, vn' = -s ve + c vn
        out[0, 1], out[0, 3] = s_over_w, one_minus_c_over_w
        out[2, 1], out[2, 3] = -one_minus_c_over_w, s_over_w
        out[1, 1], out[1, 3] = c, s
        out[3, 1], out[3, 3] = -s, c
    out.setflags(write=False)
    return out


def _wna_block(q: float, dt: float) -> FloatArray:
    """White-noise-acceleration covariance of one (p, v) pair: q [[T^3/3, T^2/2], [T^2/2, T]]."""
    return q * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])


def _jerk_block(q: float, omega: float, dt: float) -> FloatArray:
    """Jerk-noise covariance of one (p, v, a) triple under a' = -omega^2 v (omega = 0: CA).

    Q = q * integral_0^T g(s) g(s)^T ds with g(s) = [(1 - cos ws)/w^2, sin(ws)/w, cos(ws)], the
    last column of exp(A s). Closed form for |omega T| >= 2e-2, else the series to O(omega^2).
    """
    t, w2 = dt, omega * omega
    wt = abs(omega) * dt
    if wt < _SERIES_LIMIT:
        q11 = t**5 / 20.0 - w2 * t**7 / 168.0
        q12 = t**4 / 8.0 - w2 * t**6 / 48.0
        q13 = t**3 / 6.0 - 7.0 * w2 * t**5 / 120.0
        q22 = t**3 / 3.0 - w2 * t**5 / 15.0
        q23 = t**2 / 2.0 - w2 * t**4 / 6.0
        q33 = t - w2 * t**3 / 3.0
    else:
        w = abs(omega)
        s, c = math.sin(w * t), math.cos(w * t)
        s2 = math.sin(2.0 * w * t)
        int_cc = t / 2.0 + s2 / (4.0 * w)  # integral cos^2
        int_ss = t / 2.0 - s2 / (4.0 * w)  # integral sin^2
        q33 = int_cc
        q22 = int_ss / w2
        q23 = s * s / (2.0 * w2)
        q13 = (s / w - int_cc) / w2
        q12 = ((1.0 - c) / w - s * s / (2.0 * w)) / (w2 * w)
        q11 = (t - 2.0 * s / w + int_cc) / (w2 * w2)
    return q * np.array([[q11, q12, q13], [q12, q22, q23], [q13, q23, q33]])


@lru_cache(maxsize=512)
def _process_noise(kind: str, omega: float, q: float, dt: float) -> FloatArray:
    dt = abs(dt)
    out = np.zeros((STATE_DIM, STATE_DIM))
    if kind in ("cv", "ct"):
        # "ct": the common isotropic white-acceleration approximation (exact for omega = 0)
        block = _wna_block(q, dt)
        for axis in (0, 1):
            idx = (POS[axis], VEL[axis])
            out[np.ix_(idx, idx)] = block
    else:
        out = _axis_blocks(_jerk_block(q, omega if kind == "turn" else 0.0, dt))
    out = 0.5 * (out + out.T)
    out.setflags(write=False)
    return out
