"""Configuration: validated TOML files built into the values every part of the mission needs.

- ``loading``: finding a file by path or by the name of a shipped one (``app.configs``),
  parsing and validating it (one-line errors);
- ``schema``: the pieces several files share (strict models, vehicle limits, starts, targets,
  the guidance and phase laws);
- ``mission``: a mission file (``standoff fly``, ``ground``, ``agent``);
- ``plan``: a mission file built into the core parameters of every part, before any I/O;
- ``simulator``: a built-in simulator scenario (``standoff sitl``);
- ``estimator``: the target estimator's parameters (``configs/estimator.toml``);
- ``scenario``: a numerical experiment (``standoff simulate``) and an estimation scenario
  (``standoff estimate --generate``).
"""

from app.config.loading import (
    load_config,
    resolve_config,
    shipped_configs,
    shipped_text,
    validate_config,
)

__all__ = ["load_config", "resolve_config", "shipped_configs", "shipped_text", "validate_config"]
