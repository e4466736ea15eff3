"""Loading validated configuration files (TOML) into pydantic models, with one-line errors."""

import tomllib
from pathlib import Path
from typing import TypeVar

from pydantic import BaseModel, ValidationError

from app.errors import ConfigError

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs"

ModelT = TypeVar("ModelT", bound=BaseModel)


def resolve_config(name_or_path: str | Path) -> Path:
    """Find a config: an existing path, or a name (with or without ``.toml``) in ``configs/``."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    for candidate in (CONFIG_DIR / f"{name_or_path}.toml", CONFIG_DIR / str(name_or_path)):
        if candidate.is_file():
            return candidate
    known = ", ".join(sorted(p.stem for p in CONFIG_DIR.glob("*.toml"))) or "none"
    raise ConfigError(f"no config file {str(name_or_path)!r} (known names: {known})")


def load_config(name_or_path: str | Path, model: type[ModelT]) -> ModelT:
    """Read a TOML config and validate it against ``model``; raise ConfigError naming the field."""
    path = resolve_config(name_or_path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from exc
    return validate_config(raw, model, source=str(path))


def validate_config(raw: object, model: type[ModelT], source: str = "config") -> ModelT:
    """Validate already-parsed data against ``model``; raise ConfigError with the first problem."""
    try:
        return model.model_validate(raw)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(part) for part in first["loc"]) or "(top level)"
        more = f" (and {exc.error_count() - 1} more)" if exc.error_count() > 1 else ""
        raise ConfigError(f"{source}: {where}: {first['msg']}{more}") from exc
