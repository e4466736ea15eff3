"""standoff: cooperative standoff tracking of a moving ground target by fixed-wing UAVs."""

__version__ = "0.1.0"
