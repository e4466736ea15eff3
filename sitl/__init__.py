"""The built-in simulator: pure vehicle and target dynamics, and a MAVLink front over UDP."""
