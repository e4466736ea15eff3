"""Motion models (eqs 16-21): closed forms, omega -> 0 limits, process noise against expm."""

import math

import numpy as np
import pytest
import scipy.linalg  # type: ignore[import-untyped]
from hypothesis import given, settings
from hypothesis import strategies as st

from app.core.estimation.linalg import is_spd
from app.core.estimation.models import MotionModel

AXIS = (0, 1, 4)  # x, vx, ax of the state [x, vx, y, vy, ax, ay]


def _van_loan(omega: float, q: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact F and Q of the per-axis model d(p, v, a) = (v, a, -omega^2 v) + jerk noise."""
    a = np.zeros((3, 3))
    a[0, 1] = a[1, 2] = 1.0
    a[2, 1] = -(omega**2)
    g = np.zeros((3, 3))
    g[2, 2] = q
    m = np.zeros((6, 6))
    m[:3, :3] = -a
    m[:3, 3:] = g
    m[3:, 3:] = a.T
    e = scipy.linalg.expm(m * dt)
    f = e[3:, 3:].T
    return scipy.linalg.expm(a * dt), f @ e[:3, 3:]


def test_cv_and_ca_matrices_are_eqs_17_and_19():
    dt = 0.7
    f_cv = MotionModel("cv", 1.0).transition(dt)
    f_ca = MotionModel("ca", 1.0).transition(dt)
    expected_cv = np.eye(6)
    expected_cv[0, 1] = expected_cv[2, 3] = dt
    expected_ca = expected_cv.copy()
    expected_ca[0, 4] = expected_ca[2, 5] = dt * dt / 2
    expected_ca[1, 4] = expected_ca[3, 5] = dt
    np.testing.assert_array_equal(f_cv, expected_cv)
    np.testing.assert_allclose(f_ca, expected_ca, rtol=0, atol=1e-15)


def test_turn_matrix_is_eq_21():
    w, dt = 0.3, 2.0
    f = MotionModel("turn", 1.0, w).transition(dt)
    s, c = math.sin(w * dt), math.cos(w * dt)
    expected = np.array(
        [
            [1, s / w, 0, 0, (1 - c) / w**2, 0],
            [0, c, 0, 0, s / w, 0],
            [0, 0, 1, s / w, 0, (1 - c) / w**2],
            [0, 0, 0, c, 0, s / w],
            [0, -w * s, 0, 0, c, 0],
            [0, 0, 0, -w * s, 0, c],
        ]
    )
    np.testing.assert_allclose(f, expected, atol=1e-14)


@pytest.mark.parametrize("omega", [0.0, 1e-9, 1e-5, 0.01, 0.05, 0.5, 2.0])
@pytest.mark.parametrize("dt", [1e-6, 0.1, 1.0, 10.0])
def test_turn_model_f_and_q_match_the_matrix_exponential(omega, dt):
    model = MotionModel("turn", 0.7, omega)
    f_exact, q_exact = _van_loan(omega, 0.7, dt)
    f = model.transition(dt)[np.ix_(AXIS, AXIS)]
    q = model.process_noise(dt)[np.ix_(AXIS, AXIS)]
    np.testing.assert_allclose(f, f_exact, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(q, q_exact, rtol=1e-6, atol=1e-12 * max(1.0, np.abs(q_exact).max()))


@given(dt=st.floats(1e-3, 20.0), omega=st.floats(1e-12, 1e-4))
def test_turn_model_tends_to_ca_and_acts_as_cv_without_acceleration(dt, omega):
    turn = MotionModel("turn", 1.0, omega)
    ca = MotionModel("ca", 1.0)
    cv = MotionModel("cv", 1.0)
    scale = max(1.0, dt * dt)
    np.testing.assert_allclose(turn.transition(dt), ca.transition(dt), atol=1e-6 * scale)
    np.testing.assert_allclose(
        turn.process_noise(dt), ca.process_noise(dt), rtol=1e-5, atol=1e-9 * dt**5
    )
    x = np.array([3.0, 1.5, -2.0, 0.5, 0.0, 0.0])
    np.testing.assert_allclose(turn.propagate(x, dt), cv.propagate(x, dt), atol=1e-6 * scale)


@given(dt=st.floats(1e-3, 20.0), omega=st.floats(-1e-4, 1e-4))
def test_coordinated_turn_tends_to_cv(dt, omega):
    ct = MotionModel("ct", 1.0, omega).transition(dt)
    cv = MotionModel("cv", 1.0).transition(dt)
    np.testing.assert_allclose(ct, cv, atol=2e-4 * max(1.0, dt * dt))


def test_coordinated_turn_rotates_the_velocity_clockwise():
    quarter = MotionModel("ct", 0.0, math.pi / 2).transition(1.0)
    x = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0])  # heading north at 1 m/s
    after = quarter @ x
    np.testing.assert_allclose(after[[1, 3]], [1.0, 0.0], atol=1e-12)  # now heading east
    np.testing.assert_allclose(after[[0, 2]], [2 / math.pi, 2 / math.pi], atol=1e-12)


@settings(max_examples=60)
@given(
    kind=st.sampled_from(["cv", "ca", "turn", "ct"]),
    q=st.floats(1e-6, 10.0),
    omega=st.floats(-1.0, 1.0),
    dt=st.floats(1e-3, 100.0),
)
def test_process_noise_is_symmetric_psd(kind, q, omega, dt):
    qm = MotionModel(kind, q, omega).process_noise(dt)
    np.testing.assert_array_equal(qm, qm.T)
    assert np.linalg.eigvalsh(qm).min() >= -1e-9 * np.abs(qm).max()


def test_matrices_are_read_only_and_models_validate():
    f = MotionModel("cv", 1.0).transition(0.1)
    with pytest.raises(ValueError):
        f[0, 0] = 2.0
    with pytest.raises(ValueError, match="kind"):
        MotionModel("xx", 1.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="noise_intensity"):
        MotionModel("cv", -1.0)
    with pytest.raises(ValueError, match="turn_rate"):
        MotionModel("turn", 1.0, math.nan)
    assert is_spd(MotionModel("ca", 1.0).process_noise(0.1) + np.eye(6) * 1e-12)
