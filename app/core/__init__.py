"""Pure numerical core: frames, guidance, estimation, fusion, phase keeping, stage logic.

Nothing in here reads a clock, does I/O or keeps global state: every function takes ``t`` or
``dt`` and returns new values.
"""
