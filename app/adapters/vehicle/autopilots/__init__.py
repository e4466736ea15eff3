"""Autopilot adapters: turn a (course, speed[, altitude]) command into what an autopilot accepts.

Three forms (design.md section 5):

- ``velocity``: velocity + yaw offboard setpoints (the built-in simulator, PX4 multicopters);
- ``px4-fixed-wing``: a point ahead on the course with the course as velocity
  (``set_position_velocity_ned``; PX4 fixed-wing ignores velocity-only setpoints) and the airspeed
  by MAV_CMD_DO_CHANGE_SPEED whenever it changes; COM_OBL_RC_ACT checked (and set if asked);
- ``arduplane``: GUIDED mode with MAV_CMD_GUIDED_CHANGE_HEADING / _SPEED / _ALTITUDE
  (ardupilotmega dialect) sent as COMMAND_INT through MavlinkDirect; SYSID_MYGCS, FS_GCS_ENABL
  and FS_LONG_ACTN checked and set so that ArduPlane's GCS failsafe returns it if we go silent.

Every setpoint passes ``limit_setpoint`` first (speed within limits, course changing no faster
than the course-rate limit) and every number that leaves is checked finite.
"""
