"""Node selectors: safe coordinate expressions, boxes, points.

``evaluate`` parses a small expression language with :mod:`ast` and walks the tree
itself; nothing is ever passed to ``eval``. Allowed: the coordinates x, y (and z in
3D), ``pi``, numbers, + - * / ** and unary -/+, abs/sqrt/sin/cos, comparisons (chained
allowed), and/or/not and &/|/~. Comparisons use the geometric tolerance ``tol``:
``a == b`` is ``|a - b| <= tol``, ``a <= b`` is ``a <= b + tol``, ``a >= b`` is
``a >= b - tol``; ``<`` and ``>`` are strict.
"""

from __future__ import annotations

import ast
from collections.abc import Sequence

import numpy as np

from parsolve.errors import InputError

_FUNCTIONS = {"abs": np.abs, "sqrt": np.sqrt, "sin": np.sin, "cos": np.cos}
_CONSTANTS = {"pi": np.pi}
_COORDS = ("x", "y", "z")
_MAX_LENGTH = 2000  # selectors are short; refuse pathological input before parsing


class _Reject(Exception):
    """Internal: the expression is not acceptable (reason in args[0])."""


class _Evaluator:
    """Walks a parsed expression; values are (kind, array) with kind 'num' or 'bool'."""

    def __init__(self, points: np.ndarray, tol: float, t: float | None = None):
        self.tol = float(tol)
        self.points = points
        self.names = {name: points[:, d] for d, name in enumerate(_COORDS[: points.shape[1]])}
        if t is not None:   # a value that varies in time (a load): t is the step's time
            self.names["t"] = np.float64(t)

    def finite(self, value, node: ast.AST):
        """Every number an expression computes must be finite where it is evaluated:
        sqrt(-1 - x), 1/(x - x) or 10**10**10 are errors, not NaN in the results."""
        bad = ~np.isfinite(value)
        if np.any(bad):
            what = ast.unparse(node) if hasattr(ast, "unparse") else "a sub-expression"
            if np.ndim(value) == 0:
                raise _Reject(f"{what} is {float(value)} (not finite)")
            first = int(np.argmax(bad))
            where = ", ".join(f"{c:g}" for c in self.points[first])
            raise _Reject(f"{what} is not finite at {int(bad.sum())} of {bad.size} points "
                          f"(e.g. {float(value[first])} at ({where}))")
        return value

    def num(self, node: ast.AST):
        kind, val = self.visit(node)
        if kind != "num":
            raise _Reject("a condition is used where a number is expected")
        return val

    def cond(self, node: ast.AST):
        kind, val = self.visit(node)
        if kind != "bool":
            raise _Reject("a number is used where a condition is expected")
        return val

    def visit(self, node: ast.AST):
        method = getattr(self, "visit_" + type(node).__name__, None)
        if method is None:
            raise _Reject(f"{_describe(node)} is not allowed")
        return method(node)

    def visit_Expression(self, node: ast.Expression):
        return self.visit(node.body)

    def visit_Constant(self, node: ast.Constant):
        # bool is an int subclass: check it first
        if isinstance(node.value, bool):
            return "bool", np.bool_(node.value)
        if isinstance(node.value, (int, float)):
            try:  # floats: huge powers overflow, never hang
                return "num", self.finite(np.float64(node.value), node)
            except OverflowError:
                raise _Reject(f"number {node.value:.3g} is too large") from None
        raise _Reject(f"constant {node.value!r} is not allowed (numbers only)")

    def visit_Name(self, node: ast.Name):
        if node.id in self.names:
            return "num", self.names[node.id]
        if node.id in _CONSTANTS:
            return "num", np.float64(_CONSTANTS[node.id])
        if node.id in _COORDS:
            raise _Reject(f"coordinate {node.id!r} does not exist in a {len(self.names)}D mesh")
        raise _Reject(f"unknown name {node.id!r}")

    def visit_UnaryOp(self, node: ast.UnaryOp):
        if isinstance(node.op, (ast.Not, ast.Invert)):
            return "bool", np.logical_not(self.cond(node.operand))
        if isinstance(node.op, ast.USub):
            return "num", -self.num(node.operand)
        if isinstance(node.op, ast.UAdd):
            return "num", self.num(node.operand)
        raise _Reject(f"operator {type(node.op).__name__} is not allowed")

    _ARITH = {
        ast.Add: np.add,
        ast.Sub: np.subtract,
        ast.Mult: np.multiply,
        ast.Div: np.divide,
        ast.Pow: np.power,
    }

    def visit_BinOp(self, node: ast.BinOp):
        op = type(node.op)
        if op in (ast.BitAnd, ast.BitOr):
            f = np.logical_and if op is ast.BitAnd else np.logical_or
            return "bool", f(self.cond(node.left), self.cond(node.right))
        if op in self._ARITH:
            value = self._ARITH[op](self.num(node.left), self.num(node.right))
            return "num", self.finite(value, node)
        raise _Reject(f"operator {op.__name__} is not allowed")

    def visit_BoolOp(self, node: ast.BoolOp):
        f = np.logical_and if isinstance(node.op, ast.And) else np.logical_or
        out = self.cond(node.values[0])
        for v in node.values[1:]:
            out = f(out, self.cond(v))
        return "bool", out

    def visit_Compare(self, node: ast.Compare):
        tol = self.tol
        left = self.num(node.left)
        out = np.bool_(True)
        for op, right_node in zip(node.ops, node.comparators):
            right = self.num(right_node)
            if isinstance(op, ast.Eq):
                r = np.abs(left - right) <= tol
            elif isinstance(op, ast.NotEq):
                r = np.abs(left - right) > tol
            elif isinstance(op, ast.Lt):
                r = left < right
            elif isinstance(op, ast.LtE):
                r = left <= right + tol
            elif isinstance(op, ast.Gt):
                r = left > right
            elif isinstance(op, ast.GtE):
                r = left >= right - tol
            else:
                raise _Reject(f"comparison {type(op).__name__} is not allowed")
            out = np.logical_and(out, r)
            left = right
        return "bool", out

    def visit_Call(self, node: ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in _FUNCTIONS:
            what = node.func.id if isinstance(node.func, ast.Name) else _describe(node.func)
            raise _Reject(
                f"call of {what!r} is not allowed (functions: {', '.join(_FUNCTIONS)})"
            )
        if len(node.args) != 1 or node.keywords:
            raise _Reject(f"{node.func.id}() takes exactly one argument")
        if isinstance(node.args[0], ast.Starred):
            raise _Reject("starred arguments are not allowed")
        return "num", self.finite(_FUNCTIONS[node.func.id](self.num(node.args[0])), node)


def _describe(node: ast.AST) -> str:
    names = {
        "Attribute": "attribute access",
        "Subscript": "indexing",
        "Lambda": "lambda",
        "Call": "function call",
        "JoinedStr": "f-string",
        "IfExp": "conditional expression",
        "NamedExpr": "assignment",
    }
    kind = type(node).__name__
    return names.get(kind, f"syntax '{kind}'")


def _evaluate(
    expr: str,
    points: np.ndarray,
    tol: float,
    source: str | None = None,
    key: str | None = None,
    want: str = "bool",
    t: float | None = None,
) -> np.ndarray:
    """Evaluate a coordinate condition at ``points`` (npoints, gdim): bool mask (npoints,).

    Raises InputError (with ``source``/``key``) for anything outside the language.
    """
    points = np.asarray(points, dtype=float)

    def fail(reason: str) -> InputError:
        what = "selector" if want == "bool" else "expression"
        return InputError(f"invalid {what} {expr!r}: {reason}", source=source, key=key)

    if not isinstance(expr, str):
        raise fail("expected a string expression")
    if len(expr) > _MAX_LENGTH:
        raise fail(f"longer than {_MAX_LENGTH} characters")
    try:
        tree = ast.parse(expr.strip(), mode="eval")
    except SyntaxError as e:
        raise fail(f"syntax error ({e.msg})") from None
    except (ValueError, RecursionError, MemoryError):
        raise fail("cannot be parsed") from None
    try:
        with np.errstate(all="ignore"):  # non-finite values are reported, never warned about
            kind, val = _Evaluator(points, tol, t).visit(tree)
    except _Reject as e:
        raise fail(e.args[0]) from None
    except RecursionError:
        raise fail("too deeply nested") from None
    if kind != want:
        raise fail("not a condition (use a comparison such as 'x == 0')" if want == "bool"
                   else "a condition is used where a number is expected")
    return np.broadcast_to(val, (points.shape[0],)).astype(bool if want == "bool" else float)


def evaluate(expr: str, points: np.ndarray, tol: float, source: str | None = None,
             key: str | None = None) -> np.ndarray:
    """Evaluate a coordinate condition at ``points`` (npoints, gdim): bool mask (npoints,).

    Raises InputError (with ``source``/``key``) for anything outside the language.
    """
    return _evaluate(expr, points, tol, source, key, "bool")


def evaluate_value(expr: str, points: np.ndarray, source: str | None = None,
                   key: str | None = None, t: float | None = None) -> np.ndarray:
    """Evaluate a numeric expression of the coordinates (e.g. ``"1e-3 * x"``) at ``points``;
    with ``t`` given, of the time too (``"-10 * (x - t)"``)."""
    return _evaluate(expr, points, 0.0, source, key, "num", t)


def _as_point(p, gdim: int, what: str, source: str | None, key: str | None) -> np.ndarray:
    arr = np.asarray(p, dtype=float).ravel()
    if arr.shape != (gdim,):
        raise InputError(f"{what} must have {gdim} coordinates, got {list(arr)}", source, key)
    return arr


def box(
    lo: Sequence[float],
    hi: Sequence[float],
    points: np.ndarray,
    tol: float,
    source: str | None = None,
    key: str | None = None,
) -> np.ndarray:
    """Points inside the axis-aligned box [lo, hi] enlarged by ``tol``: bool mask."""
    gdim = points.shape[1]
    lo = _as_point(lo, gdim, "box lower corner", source, key)
    hi = _as_point(hi, gdim, "box upper corner", source, key)
    if np.any(lo > hi):
        raise InputError(
            f"box lower corner {list(lo)} exceeds upper corner {list(hi)}", source, key
        )
    return np.all((points >= lo - tol) & (points <= hi + tol), axis=1)


def near_point(
    p: Sequence[float],
    points: np.ndarray,
    tol: float,
    source: str | None = None,
    key: str | None = None,
) -> np.ndarray:
    """Points within distance ``tol`` of ``p``: bool mask."""
    p = _as_point(p, points.shape[1], "point", source, key)
    return np.linalg.norm(points - p, axis=1) <= tol
