"""``replace`` for the core's frozen values: ``dataclasses.replace`` without its per-call walk.

A step returns a new value (style rule 2), so the agent's step replaces its 31-field state
about ten times per control tick. ``dataclasses.replace`` walks the class's fields and goes
through ``__init__`` on every call: about 11 us for that state on a 2-core EPYC. For a frozen
value with slots and no ``__post_init__`` (nothing to re-check), ``replace`` here copies
the slots with a function written once per class: about 4.5 us. A field left out of
``__init__`` is not copied but set as ``__init__`` sets it (a cache starts empty again).
Every other class (validated parameters) goes to ``dataclasses.replace`` as before, so the
outcome is the same value either way (``tests/core/test_values.py``).
"""

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

T = TypeVar("T")

_Replacer = Callable[[Any, dict[str, Any]], Any]
_REPLACERS: dict[type, _Replacer] = {}

if TYPE_CHECKING:
    # mypy's dataclass plugin checks each call's field names and types as it does for
    # dataclasses.replace; at run time the function below stands in
    from dataclasses import replace as replace
else:

    def replace(obj: T, /, **changes: Any) -> T:
        """A copy of the dataclass value ``obj`` with ``changes``, as ``dataclasses.replace``:
        the same value, a ``TypeError`` for a name that is not an ``__init__`` field."""
        cls = type(obj)
        replacer = _REPLACERS.get(cls)
        if replacer is None:
            replacer = _REPLACERS[cls] = _replacer_for(cls)
        result: T = replacer(obj, changes)
        return result


def _by_dataclasses(obj: Any, changes: dict[str, Any]) -> Any:
    return dataclasses.replace(obj, **changes)


def _replacer_for(cls: type) -> _Replacer:
    """A function that copies a value of ``cls`` with changes: written for the class where
    copying the slots is all ``__init__`` would do, ``dataclasses.replace`` otherwise."""
    if not dataclasses.is_dataclass(cls) or "__slots__" not in cls.__dict__:
        return _by_dataclasses
    fields = dataclasses.fields(cls)
    if hasattr(cls, "__post_init__") or any(f.name not in cls.__dict__ for f in fields):
        return _by_dataclasses
    names = tuple(f.name for f in fields if f.init)
    # member descriptors set a slot directly, past the frozen class's __setattr__
    scope: dict[str, Any] = {"_new": object.__new__, "_cls": cls, "_names": frozenset(names)}
    lines = [
        "def replace(obj, changes):",
        "    if not _names.issuperset(changes):",
        "        _unknown(changes)",
        "    new = _new(_cls)",
    ]
    for i, f in enumerate(fields):
        scope[f"_set{i}"] = cls.__dict__[f.name].__set__
        if f.init:
            lines.append(
                f"    _set{i}(new, changes[{f.name!r}] if {f.name!r} in changes else obj.{f.name})"
            )
        elif f.default is not dataclasses.MISSING:  # as __init__ leaves it: not copied
            scope[f"_default{i}"] = f.default
            lines.append(f"    _set{i}(new, _default{i})")
        elif f.default_factory is not dataclasses.MISSING:
            scope[f"_factory{i}"] = f.default_factory
            lines.append(f"    _set{i}(new, _factory{i}())")
    lines.append("    return new")

    def unknown(changes: dict[str, Any]) -> None:
        wrong = sorted(set(changes) - set(names))
        raise TypeError(f"{cls.__name__} has no field {wrong[0]!r} to replace")

    scope["_unknown"] = unknown
    exec("\n".join(lines), scope)
    replacer: _Replacer = scope["replace"]
    return replacer
