"""Loading validated configuration files (TOML) into pydantic models, with one-line errors.

A config is a path, or the name of a file shipped with the package: ``configs/`` at the top of
the checkout, installed as the package data ``app.configs`` (``app/configs`` links to it, so a
checkout, an editable install and a wheel all read the same files through
``importlib.resources``).
"""

import re
import tomllib
from dataclasses import dataclass
from importlib.resources import files
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import TypeVar

from pydantic import BaseModel, ValidationError

from app.errors import ConfigError

SHIPPED_PACKAGE = "app.configs"

# the longest description `standoff configs` prints on its one line
_DESCRIPTION_CHARS = 100

# where the opening comment's first sentence ends: '.' or ':' before a space or the end, not
# after an abbreviation ("Fig. 12", "e.g. the SIH model")
_SENTENCE_END = re.compile(r"(?<!Fig)(?<!Figs)(?<!Eq)(?<!e\.g)(?<!i\.e)([.:])(?:\s|$)")

ModelT = TypeVar("ModelT", bound=BaseModel)


@dataclass(frozen=True)
class ShippedConfig:
    """A config file that comes with the package: its name (``standoff fly NAME``) and the
    one-line description from its ``description`` key, else from its opening comment."""

    name: str
    description: str


def shipped_dir() -> Traversable:
    """The folder of the shipped config files (``configs/`` in the checkout)."""
    return files(SHIPPED_PACKAGE)


def _shipped_files() -> dict[str, Traversable]:
    return {
        entry.name.removesuffix(".toml"): entry
        for entry in shipped_dir().iterdir()
        if entry.name.endswith(".toml") and entry.is_file()
    }


def shipped_names() -> tuple[str, ...]:
    """The names of the shipped config files, sorted."""
    return tuple(sorted(_shipped_files()))


def describe(text: str) -> str:
    """A config's one-line description: its top-level ``description`` string, else the first
    sentence of the comment it opens with, else ''; at most about 100 characters."""
    try:
        description = tomllib.loads(text).get("description")
    except tomllib.TOMLDecodeError:
        description = None
    if not isinstance(description, str) or not description.strip():
        comment: list[str] = []
        for line in text.splitlines():
            if not line.startswith("#"):
                break
            comment.append(line.lstrip("#").strip())
        description = " ".join(comment)
        if end := _SENTENCE_END.search(description):
            description = description[: end.start()] + ("." if end.group(1) == "." else "")
    description = " ".join(description.split())
    if len(description) > _DESCRIPTION_CHARS:
        description = description[: _DESCRIPTION_CHARS - 3].rstrip() + "..."
    return description


def shipped_configs() -> tuple[ShippedConfig, ...]:
    """Every shipped config with its description, sorted by name."""
    return tuple(
        ShippedConfig(name, describe(entry.read_text(encoding="utf-8")))
        for name, entry in sorted(_shipped_files().items())
    )


def resolve_config(name_or_path: str | Path) -> Traversable:
    """Find a config: an existing path, or a shipped file's name (with or without ``.toml``)."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    shipped = _shipped_files()
    name = str(name_or_path).removesuffix(".toml")
    if name in shipped:
        return shipped[name]
    known = ", ".join(sorted(shipped)) or "none"
    raise ConfigError(f"no config file {str(name_or_path)!r} (known names: {known})")


def shipped_text(name: str) -> str:
    """The text of a shipped config file (``standoff configs NAME``); ConfigError if unknown."""
    shipped = _shipped_files()
    entry = shipped.get(name.removesuffix(".toml"))
    if entry is None:
        known = ", ".join(sorted(shipped)) or "none"
        raise ConfigError(f"no shipped config {name!r} (known names: {known})")
    return entry.read_text(encoding="utf-8")


def read_config(name_or_path: str | Path) -> tuple[str, dict[str, object]]:
    """Find and parse a TOML config: where it was found (for messages) and its data."""
    found = resolve_config(name_or_path)
    try:
        raw = tomllib.loads(found.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{found}: cannot read: {exc}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{found}: not valid TOML: {exc}") from exc
    return str(found), raw


def load_config(name_or_path: str | Path, model: type[ModelT]) -> ModelT:
    """Read a TOML config and validate it against ``model``; raise ConfigError naming the field."""
    source, raw = read_config(name_or_path)
    return validate_config(raw, model, source=source)


def validate_config(raw: object, model: type[ModelT], source: str = "config") -> ModelT:
    """Validate already-parsed data against ``model``; raise ConfigError with the first problem."""
    try:
        return model.model_validate(raw)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(part) for part in first["loc"]) or "(top level)"
        more = f" (and {exc.error_count() - 1} more)" if exc.error_count() > 1 else ""
        raise ConfigError(f"{source}: {where}: {first['msg']}{more}") from exc
