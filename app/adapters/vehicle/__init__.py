"""Vehicle link: the port the mission flies vehicles through, its MAVSDK 4.x implementation and
the per-autopilot command adapters."""
