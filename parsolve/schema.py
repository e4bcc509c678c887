"""The scene's reading primitives, shared by the scene reader and every registry entry's
schema (effects, loads): a TOML table with its dotted path and typed reads, the number check
every float passes, and the plain names that become HDF5 groups. Nothing here imports an
effect or the scene, so that entries read their own keys without an import circle."""

from __future__ import annotations

import difflib
import math
import re
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
