"""The loads parsolve knows: each names its scene key, the values it takes, the domain of its
vector term (facets, cells or nodes of its region) and its forces there (its module's
``forces``). A ``[[loads]]`` entry gives exactly one of these keys; adding a load kind is a
module and one line here.

Every entry reads the same common keys (``name``, ``field``, ``region``, ``evolution``) and its
own value: ``field`` values (one per component of the loaded field), ``one`` value (a pressure)
or ``dim`` values (an acceleration); ``expressions``: whether a value may be an expression of
(x, y, z, t) (a string) besides a number. ``parse`` reads a ``[[loads]]`` entry so (the
scene's reader hands it each entry, as it hands a relation to its kind's entry)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from parsolve.loads import body, gravity, nodal, pressure, total_force, traction
from parsolve.loads.base import LoadSpec, uses_time
from parsolve.schema import Declared, Table, field_name, plain_name


@dataclass(frozen=True)
class LoadEntry:
    forces: Callable            # (LoadSpec, Where, Instant) -> NodeForces block after block
    domain: str                 # its vector term's: "facets", "cells" or "nodes"
    values: str                 # "field", "one" or "dim"
    on: str                     # "vector" (a vector field), "scalar" (a scalar one) or "any"
    expressions: bool           # values may be expressions of (x, y, z, t)
    region: str | None          # default region (None: required)
    kind: str = ""              # the entry it is an alias of on a scalar field ("flux": traction)
    description: str = ""


LOADS: dict[str, LoadEntry] = {
    "traction": LoadEntry(traction.forces, "facets", "field", "vector", True, None,
                          description="force per unit area on a boundary region"),
    "total_force": LoadEntry(total_force.forces, "facets", "field", "vector", False, None,
                             description="resultant spread uniformly over a boundary region"),
    "body": LoadEntry(body.forces, "cells", "field", "vector", True, "all",
                      description="force per unit volume on a region's cells"),
    "nodal": LoadEntry(nodal.forces, "nodes", "field", "any", True, None,
                       description="force on each node of a region"),
    "pressure": LoadEntry(pressure.forces, "facets", "one", "vector", True, None,
                          description="pressure against the outward normal of a boundary region"),
    "gravity": LoadEntry(gravity.forces, "cells", "dim", "vector", False, "all",
                         description="acceleration: the body force ρ g, ρ the materials' density"),
    # a scalar field's loads under their own names
    "flux": LoadEntry(traction.forces, "facets", "field", "scalar", True, None, "traction",
                      "flux into the domain per unit area of a boundary region"),
    "source": LoadEntry(body.forces, "cells", "field", "scalar", True, "all", "body",
                        "source per unit volume on a region's cells"),
    "total_flux": LoadEntry(total_force.forces, "facets", "field", "scalar", False, None,
                            "total_force",
                            "total flux spread uniformly over a boundary region"),
}

# the keys every entry reads besides its own (type, description), for the scene reference
COMMON_KEYS = {
    "name": ("string", "the pattern the load belongs to (default \"loads\")"),
    "field": ("string", "the field it loads (default: the displacement, else the only field)"),
    "region": ("string", "where it acts"),
    "evolution": ("string", "its factor in time (default \"ramp\"; \"constant\" for a value "
                            "that names t)"),
}


def names_for(ncomp: int) -> tuple[str, ...]:
    """The keys a load on a field of ``ncomp`` components may give: the field kind's own in
    the registry's order, then those of any field (a scalar field's: flux, source,
    total_flux, nodal)."""
    want = "scalar" if ncomp == 1 else "vector"
    own = [k for k, e in LOADS.items() if e.on == want]
    return tuple(own + [k for k, e in LOADS.items() if e.on == "any"]) if want == "scalar" \
        else tuple(k for k, e in LOADS.items() if e.on in (want, "any"))


def parse(t: Table, declared: Declared) -> LoadSpec:
    """A ``[[loads]]`` entry (a scene Table) → spec: the common keys, then the value of the one
    load key it gives, read as its entry says."""
    pattern = plain_name(t, "loads")
    field = field_name(t, declared)
    ncomp, dim = declared.fields[field], declared.dim
    names = names_for(ncomp)
    given = [k for k in names if t.has(k)]
    if len(given) != 1:
        raise t.error(names[0], f"give exactly one of {', '.join(names)}")
    key = given[0]
    entry = LOADS[key]
    vector = _values(t, key, entry, {"field": ncomp, "one": 1, "dim": dim}[entry.values])
    region = t.get("region", str, ... if entry.region is None else entry.region)
    timed = any(isinstance(v, str) and uses_time(v) for v in vector)
    evolution = t.get("evolution", str, "constant" if timed else "ramp")
    t.done()
    return LoadSpec(pattern, region, entry.kind or key, vector, evolution, t.path, field, key)


def _values(t: Table, key: str, entry, count: int) -> list:
    """``count`` values: numbers (one may be given bare when one is wanted) or, where the
    entry takes them, expressions of (x, y, z, t)."""
    raw = t.data[key]
    number = isinstance(raw, (int, float)) and not isinstance(raw, bool)
    if count == 1 and (number or entry.expressions and isinstance(raw, str)):
        return [t.get(key, (float, str) if entry.expressions else float)]
    if not entry.expressions or not isinstance(raw, list) or \
            not any(isinstance(v, str) for v in raw):
        return t.floats(key, count)
    t.used.add(key)
    if len(raw) != count:
        raise t.error(key, f"expected {count} values, got {len(raw)}")
    sub = Table({f"{key}[{i}]": v for i, v in enumerate(raw)}, t.path, t.source)
    return [sub.get(k, (float, str)) for k in sub.data]
