"""Analytic reference values written as arithmetic: numbers, + - * / **, parentheses, pi, e,
sqrt, sin, cos, tan, exp, log, abs. Nothing else is evaluated.

Evaluated in floats (never Python integers: ``9**9**9`` would take hours), so an overflow is
an immediate error; the text is bounded in length and nesting so that neither the parser nor
the evaluator can exhaust the stack or the memory."""

from __future__ import annotations

import ast
import math
import operator

MAX_LENGTH = 200      # characters
MAX_DEPTH = 32        # nesting of the expression tree

_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
           ast.Div: operator.truediv, ast.Pow: math.pow}
_UNARY = {ast.UAdd: operator.pos, ast.USub: operator.neg}
_NAMES = {"pi": math.pi, "e": math.e}
_FUNCS = {"sqrt": math.sqrt, "sin": math.sin, "cos": math.cos, "tan": math.tan, "exp": math.exp,
          "log": math.log, "abs": abs}


def evaluate_expression(text: str) -> float:
    """The finite value of ``text``; ValueError for anything but the arithmetic above, and for
    a result or an intermediate value that is not a finite float (1 / 0, exp(1000), 9**9**9)."""
    if len(text) > MAX_LENGTH:
        raise ValueError(f"longer than {MAX_LENGTH} characters")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError:
        raise ValueError(f"cannot parse {text!r}") from None
    except (ValueError, RecursionError, MemoryError):
        raise ValueError("cannot be parsed (too long or too deeply nested)") from None
    if _depth(tree.body) > MAX_DEPTH:
        raise ValueError(f"nested deeper than {MAX_DEPTH} levels")
    try:
        value = _eval(tree.body)
    except ZeroDivisionError:
        raise ValueError("division by zero") from None
    except OverflowError:
        raise ValueError("overflows a float") from None
    except TypeError:  # e.g. a negative number to a fractional power (complex)
        raise ValueError("not a real number") from None
    if not math.isfinite(value):
        raise ValueError(f"is not finite ({value})")
    return value


def _depth(node: ast.AST) -> int:
    """Depth of the tree, iteratively (a recursive walk could itself overflow the stack)."""
    deepest, todo = 0, [(node, 1)]
    while todo:
        n, d = todo.pop()
        deepest = max(deepest, d)
        todo.extend((c, d + 1) for c in ast.iter_child_nodes(n))
    return deepest


def _eval(node) -> float:
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        return float(node.value)
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        try:
            return _finite(_BINARY[type(node.op)](_eval(node.left), _eval(node.right)))
        except ValueError as exc:  # math.pow: (-8) ** (1/3), 0 ** -1
            if str(exc) != "math domain error":
                raise
            raise ValueError("a power outside its domain (negative base, fractional exponent; "
                             "or 0 to a negative power)") from None
    if isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
        return _UNARY[type(node.op)](_eval(node.operand))
    if isinstance(node, ast.Name) and node.id in _NAMES:
        return _NAMES[node.id]
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCS
            and len(node.args) == 1 and not node.keywords):
        try:
            return _finite(float(_FUNCS[node.func.id](_eval(node.args[0]))))
        except ValueError:  # math domain error: sqrt(-1), log(0)
            raise ValueError(f"{node.func.id}() of a value outside its domain") from None
    raise ValueError(f"unsupported element {ast.dump(node)[:40]}")


def _finite(value: float) -> float:
    """Every intermediate value finite: 1e308 * 10 is an overflow, not inf."""
    if not math.isfinite(value):
        raise OverflowError
    return value
