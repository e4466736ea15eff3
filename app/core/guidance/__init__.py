"""Lyapunov vector field guidance (paper sections 3-4), by role: ``field`` (the field, curvature,
optimal c), ``course`` (the lag-compensated course command and the inverse-field switch),
``moving_target`` (eq. 15) and ``orbit_plan`` (the planned orbit and speed cap around a fast
target)."""
