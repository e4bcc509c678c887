"""The SPEC language shared by ``parsolve post`` curves and ``parsolve study`` quantities.

    time                                   load parameter of each saved step
    step                                   step number (1, 2, ...)
    relation:<name>:multiplier[:<sel>]     λ of a relation; <sel> = row number, "sum" or "mean";
    relation:<name>:primal[:<sel>]         A q; one-row relations need no <sel>, others must say
    relation:<name>:resultant:<comp>       /relations/<name>/resultant (x, y, z, then mx, my, mz)
    field:<name>:<comp>@x,y[,z]            nodal field interpolated at a point (shape functions)
    cell_field:<name>:<comp>@x,y[,z]       value of the cell containing the point
    max:field:<name>:<comp>[@<region>]     largest nodal value (signed) over a region or all
    maxabs:field:<name>:<comp>[@<region>]  largest |value|
    norm:field:<name>                      L2 norm over the mesh, sqrt(∫ |f|² dΩ)
    energy                                 strain energy ½ ∫ ε : C ε dΩ (linear elastic scenes)

Components: x, y, z for vectors; xx, yy, (zz,) (yz, xz,) xy for Voigt tensors; or a number.
Every spec evaluates to one value per saved step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.errors import InputError
from parsolve.post.locate import interpolate, locate
from parsolve.post.result import Result

RESULTANT = ("x", "y", "z", "mx", "my", "mz")
MAX_LENGTH = 300    # characters of a spec (a name, a point, a region name: never an expression)


@dataclass
class Spec:
    text: str
    kind: str                       # time, step, relation, field, cell_field, max, maxabs, norm, energy
    name: str = ""
    what: str = ""                  # relation: multiplier / primal / resultant
    sel: str = ""                   # component or row selector
    at: tuple[float, ...] | None = None
    region: str | None = None


def parse(text: str, source: str | None = None) -> Spec:
    """Parse a spec; a malformed one is an InputError naming ``source`` and the spec."""
    def bad(why: str) -> InputError:
        return InputError(f"invalid spec: {why}", source, text)

    if len(text) > MAX_LENGTH:
        raise InputError(f"invalid spec: longer than {MAX_LENGTH} characters", source, text[:40] + "...")
    body, _, where = text.partition("@")
    parts = body.split(":")
    head = parts[0]
    if head in ("time", "step", "energy") and len(parts) == 1 and not where:
        return Spec(text, head)
    if head == "relation":
        if len(parts) not in (3, 4) or parts[2] not in ("multiplier", "primal", "resultant"):
            raise bad("expected relation:<name>:multiplier|primal[:row|sum|mean] or "
                      "relation:<name>:resultant:<comp>")
        if parts[2] == "resultant" and len(parts) != 4:
            raise bad("a resultant needs a component (x, y, z, mx, my, mz)")
        return Spec(text, head, parts[1], parts[2], parts[3] if len(parts) == 4 else "")
    if head in ("field", "cell_field"):
        if len(parts) not in (2, 3) or not where:
            raise bad(f"expected {head}:<name>[:<comp>]@x,y[,z]")
        try:
            at = tuple(float(v) for v in where.split(","))
        except ValueError:
            raise bad(f"point {where!r} is not numbers (x,y[,z]; no expressions)") from None
        if not all(np.isfinite(at)) or not 2 <= len(at) <= 3:
            raise bad(f"point {where!r} is not 2 or 3 finite numbers")
        return Spec(text, head, parts[1], sel=parts[2] if len(parts) == 3 else "0", at=at)
    if head in ("max", "maxabs") and len(parts) in (3, 4) and parts[1] == "field":
        return Spec(text, head, parts[2], sel=parts[3] if len(parts) == 4 else "0",
                    region=where or None)
    if head == "norm" and len(parts) == 3 and parts[1] == "field" and not where:
        return Spec(text, head, parts[2])
    raise bad("unknown form (time, step, energy, relation:..., field:...@x,y, cell_field:...@x,y, "
              "max:field:..., maxabs:field:..., norm:field:<name>)")


def _rows(res: Result, spec: Spec, values: np.ndarray) -> np.ndarray:
    sel = spec.sel
    if not sel and values.shape[1] == 1:
        return values[:, 0]
    if sel == "sum":
        return values.sum(axis=1)
    if sel == "mean":
        return values.mean(axis=1)
    if sel.isdigit() and int(sel) < values.shape[1]:
        return values[:, int(sel)]
    raise InputError(f"relation {spec.name!r} has {values.shape[1]} rows: add :sum, :mean or a row "
                     f"number 0..{values.shape[1] - 1}", res.path, spec.text)


def _relation(res: Result, spec: Spec) -> np.ndarray:
    if f"relations/{spec.name}" not in res.file:
        known = ", ".join(res.names("relations")) or "none"
        raise InputError(f"no relation {spec.name!r} (known: {known})", res.path, spec.text)
    values = res.dataset(f"relations/{spec.name}/{spec.what}", spec.text)
    if spec.what != "resultant":
        return _rows(res, spec, values)
    labels = res.file.attrs.get("resultant_components")
    if labels is not None:  # written by the run: x, y[, z], scalar fields by name, moments
        comps = tuple(str(labels).split())
    else:
        comps = RESULTANT[:values.shape[1]] if values.shape[1] != 3 or res.dim == 3 else ("x", "y", "mz")
    if spec.sel not in comps:
        raise InputError(f"no resultant component {spec.sel!r} (known: {', '.join(comps)})",
                         res.path, spec.text)
    return values[:, comps.index(spec.sel)]


def _field(res: Result, spec: Spec, group: str) -> tuple[np.ndarray, int]:
    if spec.name not in res.names(group):
        known = ", ".join(res.names(group)) or "none"
        raise InputError(f"no {group[:-1].replace('_', ' ')} {spec.name!r} (known: {known})",
                         res.path, spec.text)
    values = res.file[f"{group}/{spec.name}"][()]
    return values, res.component(values.shape[2], spec.sel, spec.text)


def _outside(res: Result, spec: Spec) -> InputError:
    return InputError(f"point {spec.at} is outside the mesh", res.path, spec.text)


def _check_point(res: Result, spec: Spec) -> None:
    if len(spec.at) != res.dim:
        raise InputError(f"the point needs {res.dim} coordinates", res.path, spec.text)


def evaluate(res: Result, spec: Spec) -> np.ndarray:
    """The spec's value at every saved step, (nsteps,)."""
    if spec.kind == "time":
        return res.times.astype(float)
    if spec.kind == "step":
        return np.arange(1, len(res.times) + 1, dtype=float)
    if spec.kind == "relation":
        return _relation(res, spec)
    if spec.kind == "field":
        values, c = _field(res, spec, "fields")
        _check_point(res, spec)
        out = interpolate(values[..., c:c + 1], res.points, res.cells, res.cell_type, spec.at)
        if out is None:
            raise _outside(res, spec)
        return out[:, 0]
    if spec.kind == "cell_field":
        values, c = _field(res, spec, "cell_fields")
        _check_point(res, spec)
        found = locate(res.points, res.cells, res.cell_type, spec.at)
        if found is None:
            raise _outside(res, spec)
        return values[:, found[0], c]
    if spec.kind in ("max", "maxabs"):
        values, c = _field(res, spec, "fields")
        v = values[:, _region_nodes(res, spec), c]
        return (np.abs(v) if spec.kind == "maxabs" else v).max(axis=1)
    if spec.kind == "norm":
        from parsolve.post.integrals import l2_norm

        values = _field(res, Spec(spec.text, spec.kind, spec.name, sel="0"), "fields")[0]
        return l2_norm(res.points, res.cells, res.cell_type, values)
    if spec.kind == "energy":
        from parsolve.post.integrals import strain_energy

        return strain_energy(res, spec.text)
    raise AssertionError(spec.kind)


def _region_nodes(res: Result, spec: Spec) -> np.ndarray:
    if spec.region is None:
        return np.arange(len(res.points))
    from parsolve.post.scene_model import regions

    return regions(res, spec.text)(spec.region, spec.text).nodes


def series(res: Result, text: str) -> np.ndarray:
    return evaluate(res, parse(text, res.path))
