"""Edges to the outside world: MAVSDK vehicle link, buses, codec, logs."""
