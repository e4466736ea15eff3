"""Drivers of the core: the fast numerical simulation and the asyncio loops over injected ports."""
