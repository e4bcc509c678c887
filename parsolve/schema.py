"""The scene's reading primitives, shared by the scene reader and every registry entry's
schema (effects, loads, relations): a TOML table with its dotted path and typed reads, the number check
every float passes, and the plain names that become HDF5 groups. Nothing here imports an
effect or the scene, so that entries read their own keys without an import circle."""

from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass
from typing import Any

from parsolve.errors import InputError

# Numbers beyond these magnitudes are not physical in any system of units, and their products
# (stiffness = E × lengths^d, forces × lengths) overflow or underflow double precision.
MAX_MAGNITUDE = 1e50
MIN_MAGNITUDE = 1e-50
# Relation and load-pattern names become HDF5 group names: plain identifiers only.
NAME_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_\-]{0,63}")


def check_number(value: float, source: str, key: str) -> float:
    """A finite number of sane magnitude (0 allowed), or an InputError naming the key."""
    v = float(value)
    if math.isnan(v):
        raise InputError("not a number (nan)", source, key)
    if math.isinf(v):
        raise InputError(f"must be finite, got {v}", source, key)
    if abs(v) > MAX_MAGNITUDE:
        raise InputError(f"{v:g} is absurdly large (|value| must not exceed {MAX_MAGNITUDE:g}; "
                         "products of such numbers overflow)", source, key)
    if v != 0.0 and abs(v) < MIN_MAGNITUDE:
        raise InputError(f"{v:g} is absurdly small (|value| must be 0 or at least "
                         f"{MIN_MAGNITUDE:g})", source, key)
    return v


class Table:
    """A TOML table with its dotted path: typed reads, and unknown keys reported at the end."""

    def __init__(self, data: dict, path: str, source: str):
        if not isinstance(data, dict):
            raise InputError(f"expected a table, got {type(data).__name__}", source, path)
        self.data, self.path, self.source, self.used = data, path, source, set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def error(self, name: str, message: str) -> InputError:
        return InputError(message, self.source, self.key(name))

    def has(self, name: str) -> bool:
        return name in self.data

    def get(self, name: str, kind: type | tuple, default: Any = ..., choices=None) -> Any:
        self.used.add(name)
        if name not in self.data:
            if default is ...:
                close = difflib.get_close_matches(name, set(self.data) - self.used, n=1)
                if close:  # a misspelt key: point at it rather than at the missing one
                    raise self.error(close[0], f"unknown key (did you mean {name!r}?)")
                raise self.error(name, "missing required key")
            return default
        value = self.data[name]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if float in kinds and int not in kinds and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if isinstance(value, bool) and bool not in kinds or not isinstance(value, kinds):
            names = " or ".join(k.__name__ for k in kinds)
            raise self.error(name, f"expected {names}, got {type(value).__name__} {value!r}")
        if isinstance(value, float):  # every float the scene reads passes here
            check_number(value, self.source, self.key(name))
        if choices is not None and value not in choices:
            raise self.error(name, f"must be one of {', '.join(map(str, choices))}; got {value!r}")
        return value

    def floats(self, name: str, length: int | None = None, default: Any = ...) -> list[float] | None:
        value = self.get(name, list, default)
        if value is None or value is default and default is not ...:
            return value
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            raise self.error(name, f"expected a list of numbers, got {value!r}")
        if length is not None and len(value) != length:
            raise self.error(name, f"expected {length} numbers, got {len(value)}")
        return [check_number(v, self.source, f"{self.key(name)}[{i}]") for i, v in enumerate(value)]

    def table(self, name: str, default: Any = ...) -> "Table | None":
        value = self.get(name, dict, default)
        return value if value is None else Table(value, self.key(name), self.source)

    def tables(self, name: str) -> list["Table"]:
        value = self.get(name, list, [])
        return [Table(v, f"{self.key(name)}[{i}]", self.source) for i, v in enumerate(value)]

    def done(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            close = difflib.get_close_matches(unknown[0], self.used, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else \
                f" (known: {', '.join(sorted(self.used))})"
            raise self.error(unknown[0], "unknown key" + hint)


# ------------------------------------------------ what loads and relations address

COMPONENTS = {"x": 0, "y": 1, "z": 2, "ux": 0, "uy": 1, "uz": 2}


@dataclass(frozen=True)
class Declared:
    """What a load or relation entry reads against: the model's dimension, the fields the
    scene's effects declare {name: components} and the primary one (the displacement: the
    field named by default), None when no effect has one."""

    dim: int
    fields: dict
    primary: str | None


def field_name(t: Table, declared: Declared) -> str:
    """The field a relation, term or load addresses: 'field', else the primary one, else the
    only one."""
    fields, primary = declared.fields, declared.primary
    if t.has("field") or primary is None and len(fields) != 1:
        name = t.get("field", str)
        if name not in fields:
            raise t.error("field", f"unknown field {name!r} (fields: {', '.join(fields)})")
        return name
    return primary if primary is not None else next(iter(fields))


def field_component(t: Table, name: str, declared: Declared, field: str) -> int:
    """Component index within a field; a scalar field has one, unnamed (or "value")."""
    if declared.fields[field] == 1:
        if t.has(name) and t.get(name, str) not in ("", "value", field):
            raise t.error(name, f"field {field!r} is scalar: it has no component {t.data[name]!r}")
        t.used.add(name)
        return 0
    return component(t, name, declared.dim)


def component(t: Table, name: str, dim: int) -> int:
    """A vector component by name (x, y, z or ux, uy, uz) within ``dim``."""
    comp = t.get(name, str)
    if comp not in COMPONENTS or COMPONENTS[comp] >= dim:
        allowed = [c for c, i in COMPONENTS.items() if i < dim and len(c) == 1]
        raise t.error(name, f"unknown component {comp!r} for a {dim}D model (use {', '.join(allowed)})")
    return COMPONENTS[comp]


def plain_name(t: Table, default: Any = ...) -> str:
    """A relation or load-pattern name: it becomes an HDF5 group name."""
    name = t.get("name", str, default)
    if not NAME_PATTERN.fullmatch(name):
        raise t.error("name", f"{name!r} is not a plain name (a letter or '_', then letters, "
                              "digits, '_' or '-'; at most 64 characters)")
    return name
