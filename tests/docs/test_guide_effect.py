"""The guide's "Adding an effect" stays true: its code is the shipped exchange module's and its
registry entry's, word for word (each ```python block marked ``<!-- excerpt: PATH -->`` is in
PATH, its parts between ``...`` lines in order), the class shown is the module's last
definition, the module's line count is the one the guide gives, and nothing in the package
besides the registry names the module (one module + one registry entry)."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "guide.md"
EXCERPT = re.compile(r"^<!-- excerpt: ([\w/.]+) -->\n```python\n(.*?)^```", re.S | re.M)


def section() -> str:
    text = GUIDE.read_text()
    return text.split("\n## Adding an effect\n", 1)[1].split("\n## ", 1)[0]


def excerpts() -> list[tuple[str, str]]:
    return EXCERPT.findall(section())


def test_every_excerpt_is_the_shipped_code():
    found = excerpts()
    assert [path for path, _ in found] == ["parsolve/effects/exchange.py"] * 2 \
        + ["parsolve/effects/registry.py"]
    for path, code in found:
        source = (ROOT / path).read_text()
        at = 0
        for part in re.split(r"^\.\.\.\n", code, flags=re.M):
            where = source.find(part, at)
            assert part.strip() and where >= 0, f"{path}: not in the module:\n{part}"
            at = where + len(part)


def test_the_class_shown_is_the_whole_effect():
    """The module ends with the class the guide shows (no method of it left out)."""
    (_, cls), = [(p, c) for p, c in excerpts() if c.startswith("class Exchange(Effect):")]
    source = (ROOT / "parsolve" / "effects" / "exchange.py").read_text()
    assert source.endswith(cls)


def test_the_line_counts_the_guide_gives():
    text = section()
    lines = len((ROOT / "parsolve" / "effects" / "exchange.py").read_text().splitlines())
    assert f"`parsolve/effects/exchange.py` ({lines} lines" in " ".join(text.split())
    _, entry = excerpts()[-1]
    assert len(entry.splitlines()) == 3 and "three lines of the registry" in " ".join(text.split())


def test_only_the_registry_names_the_module():
    """Adding the condition touched its module and the registry, nothing else of the package."""
    naming = re.compile(r"\bexchange\.(?:parse|build|regions|Exchange)\b|effects\.exchange\b|"
                        r"from parsolve\.effects import (?:\([^)]*|[^\n]*)\bexchange\b")
    hits = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "parsolve").rglob("*.py")
                  if p.name != "exchange.py" and naming.search(p.read_text()))
    assert hits == ["parsolve/effects/registry.py"], hits


def test_the_interface_the_section_names():
    """The Term fields and the Effect methods the section names, with the instant ``at`` where
    it says time reaches."""
    import dataclasses
    import inspect

    from parsolve.effects.base import Effect
    from parsolve.fem.element_matrices import Term

    text = section()
    fields = {f.name for f in dataclasses.fields(Term)}
    for name in ("symmetric", "linear", "rate", "cells", "facets", "nodes"):
        assert name in fields and re.search(rf"\b{name}\b", text), name
    for method, at in (("terms", False), ("term_values", False), ("evaluate", True),
                       ("vector_values", True), ("begin_step", True)):
        assert f"`{method}" in text, method
        params = list(inspect.signature(getattr(Effect, method)).parameters)
        assert ("at" in params) == at, (method, params)
    assert "`restructured`" in text and hasattr(Effect, "restructured")
