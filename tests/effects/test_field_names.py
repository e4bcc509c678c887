"""No field name is written outside the effect that declares it: the displacement "u" is
elasticity's (the others find it by its ``Field.displacement`` flag: ``displacement_field``,
``Scene.primary``), so an effect, a load or a relation kind works on a model whose fields are
named otherwise. Read from the package's syntax trees (string constants, docstrings aside)."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "parsolve"
DECLARER = PACKAGE / "effects" / "elasticity.py"


def string_constants(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text())
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                                       ast.AsyncFunctionDef))
                  and node.body and isinstance(node.body[0], ast.Expr)
                  and isinstance(node.body[0].value, ast.Constant)}
    return [(node.lineno, node.value) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str)
            and id(node) not in docstrings]


def test_the_displacement_is_named_only_by_elasticity():
    named = [f"{path.relative_to(PACKAGE.parent)}:{line}"
             for path in sorted(PACKAGE.rglob("*.py")) if path != DECLARER
             for line, value in string_constants(path) if value == "u"]
    assert not named, named
    assert any(value == "u" for _, value in string_constants(DECLARER))
