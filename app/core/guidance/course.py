"""The course command that the eq. (2) vehicle can follow, and the inverse-field switch rule
(paper section 4.1) with its prediction of the closed loop.

Courses are radians clockwise from north (MAVLink); positions metres east/north relative to the
target.
"""

import math
from dataclasses import dataclass

from app.core.frames import wrap_pi
from app.core.guidance.field import FieldParams, check_finite, course_and_rate, peak_curvature
from app.core.plant import VehicleEnvelope, advance
from app.core.values import replace


@dataclass(frozen=True, slots=True)
class CourseLoop:
    """The autopilot's course loop as guidance assumes it (eq. 2): gain k ``gain_per_s`` (1/s),
    limit W ``max_rate_rad_s`` (rad/s), and whether the command feeds the field's course rate
    forward (False: the paper's literal loop)."""

    gain_per_s: float
    max_rate_rad_s: float
    feed_forward: bool = True

    def __post_init__(self) -> None:
        if not (self.gain_per_s > 0.0 and self.max_rate_rad_s > 0.0):
            raise ValueError(
                "CourseLoop gain_per_s and max_rate_rad_s must be > 0, got "
                f"{self.gain_per_s!r}, {self.max_rate_rad_s!r}"
            )


def course_command(
    course_rad: float,
    field_course_rad: float,
    field_course_rate_rad_s: float,
    loop: CourseLoop,
) -> float:
    """A course command for the eq. (2) course loop, compensated for its lag.

    Eq. (2) turns at k * (command - course), saturated at W. Commanding the field course itself
    leaves a lag e = (field course rate) / k, so the vehicle settles c s / (2k) off the circle and
    overshoots where the field turns hard. With feed-forward the command is

        course + clamp(wrap(field_course - course) + field_course_rate / k, +-W/k),

    so unsaturated the course error obeys de/dt = -k e exactly. The clamp keeps the implied rate
    within W (the turn direction is the one of the field error, never an ambiguous wrap of a
    command half a turn away). Without feed-forward the command is the field course (the paper's
    literal law), still clamped.

    ``loop`` holds k, W and whether the rate is fed forward. All angles are courses (rad,
    clockwise from north); the result is in [-pi, pi).
    """
    # a sum of finite floats is finite (short of overflow): name the culprit only when it is not
    if not math.isfinite(course_rad + field_course_rad + field_course_rate_rad_s):
        check_finite(
            course_rad=course_rad,
            field_course_rad=field_course_rad,
            field_course_rate_rad_s=field_course_rate_rad_s,
        )
    return _lead_command(course_rad, field_course_rad, field_course_rate_rad_s, loop)


def _lead_command(course: float, field_course: float, field_rate: float, loop: CourseLoop) -> float:
    k = loop.gain_per_s
    lead = wrap_pi(field_course - course)
    if loop.feed_forward:
        lead += field_rate / k
    limit = loop.max_rate_rad_s / k
    lead = min(max(lead, -limit), limit)
    return wrap_pi(course + lead)


def predict_min_distance_error(
    rel_east_m: float,
    rel_north_m: float,
    course_rad: float,
    speed_m_s: float,
    field: FieldParams,
    loop: CourseLoop,
    step_s: float = 0.1,
    horizon_s: float = 60.0,
) -> float:
    """Smallest r - r_d (m) the vehicle would reach flying the *ordinary* field from here.

    The prediction integrates eq. (2) (course loop with gain k saturated at W, constant speed,
    target-relative frame) under ``course_command`` in steps of ``step_s``. It stops early when the
    outcome is decided:

    - the vehicle is inside the circle (r < r_d): the value is returned at once;
    - the course is aligned with the field (within 0.01 rad) while the field's peak curvature is
      within W / s: from there the vehicle follows a field line, and field lines never cross the
      circle ((r^2 - r_d^2)^2 does not increase along them);
    - with feed-forward, the vehicle is more than 2.2 turn radii outside the circle and moving
      away (a lagging literal loop is followed to the horizon instead: it may still come back
      and overshoot);
    - the horizon ends.

    The vehicle is the eq. (2) plant (``plant.advance``: ``plant.step`` on floats) at the
    constant speed, in the target's frame; ``field`` is flown as the ordinary field whatever its
    ``inverse``.
    """
    check_finite(
        rel_east_m=rel_east_m, rel_north_m=rel_north_m, course_rad=course_rad, speed_m_s=speed_m_s
    )
    if not (speed_m_s > 0.0 and step_s > 0.0 and horizon_s > 0.0):
        raise ValueError("speed_m_s, step_s and horizon_s must be > 0")
    ordinary = replace(field, inverse=False) if field.inverse else field
    w = loop.max_rate_rad_s
    # one speed: the speed loop never acts (its acceleration limit is never reached)
    envelope = VehicleEnvelope(speed_m_s, speed_m_s, speed_m_s, 1.0, w, loop.gain_per_s)
    flyable = peak_curvature(field.radius_m, field.c)[0] <= w / speed_m_s * (1.0 + 1e-9)
    far_m = 2.2 * speed_m_s / w
    x, y, chi = rel_east_m, rel_north_m, course_rad
    s = speed_m_s
    min_err = math.hypot(x, y) - field.radius_m
    t = 0.0
    while t < horizon_s:
        f_course, f_rate = course_and_rate(x, y, s * math.sin(chi), s * math.cos(chi), ordinary)
        if flyable and abs(wrap_pi(f_course - chi)) < 0.01:
            return min_err
        cmd = _lead_command(chi, f_course, f_rate, loop)
        x, y, chi, _, _, _ = advance(x, y, chi, s, cmd, s, envelope, step_s, exact_arc=False)
        t += step_s
        err = math.hypot(x, y) - field.radius_m
        if err < min_err:
            min_err = err
            if err < 0.0:
                return min_err
        elif loop.feed_forward and err > far_m and x * math.sin(chi) + y * math.cos(chi) > 0.0:
            return min_err
    return min_err


def inverse_field_wanted(
    using_inverse: bool,
    predicted_min_error_m: float,
    enter_below_m: float = 0.0,
    leave_above_m: float = 0.5,
) -> bool:
    """The ILVF switch rule with hysteresis (section 4.1).

    Switch to the inverse field when flying the ordinary field from here would take the vehicle
    inside the circle (predicted min r - r_d < ``enter_below_m``); switch back once it would stay
    at least ``leave_above_m`` outside. The gap keeps the switch from chattering.
    """
    check_finite(predicted_min_error_m=predicted_min_error_m)
    if using_inverse:
        return predicted_min_error_m < leave_above_m
    return predicted_min_error_m < enter_below_m
