"""Write docs/reference/scene.md: every scene key, recorded from the parser itself.

How: every key of a scene is read through ``parsolve.scene.Table.get`` (``floats``, ``table``
and ``tables`` go through it too), by ``parsolve/scene.py`` and by each effect's ``parse``.
This script wraps ``Table.get`` to record (section, key, type, default, choices) while
``load_scene`` reads every shipped scene (``configs/*.toml``) and every scene of the docs
(the ```toml blocks of docs/**/*.md) and the few scenes of tests/docs/scenes/ written for
the keys no other scene uses (tests/docs/test_snippets.py checks all of these). Recording
beats reading the source with ``ast``: the section of a key is known at run time only (the
same helper reads ``relations[]`` and ``contact[].obstacle``), and so are defaults computed
from other keys. What recording cannot see — a key that no scene uses — is caught by an
``ast`` pass over parsolve/scene.py and parsolve/effects/: every literal ``get("key", ...)`` name not recorded is listed at
the end of the page, so nothing the code reads is silently missing.

    python scripts/docs_reference.py            # writes docs/reference/scene.md
    python scripts/docs_reference.py --check    # exit 1 if the committed page differs
"""
from __future__ import annotations

import argparse
import ast
import re
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "reference" / "scene.md"
FENCE = re.compile(r"^```toml\n(.*?)^```", re.S | re.M)
MAXIMAL = ROOT / "tests" / "docs" / "scenes"   # scenes for the keys configs/ does not use
USER_NAMED = ("regions", "evolutions")         # tables whose keys are the user's names


def doc_scenes() -> list[tuple[str, str]]:
    """(name, text) of every ```toml block of the docs (the generated page excluded)."""
    out = []
    for md in sorted((ROOT / "docs").rglob("*.md")):
        if md == PAGE:
            continue
        for i, m in enumerate(FENCE.finditer(md.read_text())):
            out.append((f"{md.relative_to(ROOT)}#{i + 1}", m.group(1)))
    return out


def _kind(kind) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    names = {"str": "string", "int": "integer", "float": "number", "bool": "boolean",
             "list": "array", "dict": "table"}
    return " or ".join(names.get(k.__name__, k.__name__) for k in kinds)


def _default(value) -> str:
    if value is ...:
        return "required"
    if isinstance(value, str):
        return f'`"{value}"`'
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if value is None:
        return "(none)"
    if isinstance(value, (dict, list)) and not value:
        return "`{}`" if isinstance(value, dict) else "`[]`"
    return f"`{value!r}`"


def record() -> tuple[dict, list[str]]:
    """{section: {key: {kinds, defaults, choices}}} over every scene, and the scenes read."""
    from parsolve import scene as scene_mod

    seen: dict[str, dict[str, dict]] = {}
    original = scene_mod.Table.get

    def get(self, name, kind, default=..., choices=None):
        if "[" in name:  # the parser's own sub-tables of list items (regions' box[0])
            return original(self, name, kind, default, choices)
        section = re.sub(r"\[\d+\]", "[]", self.path) or "(top level)"
        head, _, rest = section.partition(".")
        if section in USER_NAMED:
            name_shown = "<name>"
        else:
            name_shown = name
            if head in USER_NAMED and rest:
                section = head + ".<name>" + rest[rest.find(".") :] if "." in rest else head + ".<name>"
        entry = seen.setdefault(section, {}).setdefault(
            name_shown, {"kinds": [], "defaults": [], "choices": None})
        for lst, v in ((entry["kinds"], _kind(kind)), (entry["defaults"], _default(default))):
            if v not in lst:
                lst.append(v)
        if choices is not None:
            entry["choices"] = ", ".join(f"`{c}`" for c in choices)
        return original(self, name, kind, default, choices)

    names = []
    scene_mod.Table.get = get
    try:
        for path in sorted((ROOT / "configs").glob("*.toml")) + sorted(MAXIMAL.glob("*.toml")):
            scene_mod.load_scene(path)
            names.append(str(path.relative_to(ROOT)))
        with tempfile.TemporaryDirectory() as tmp:
            for name, text in doc_scenes():
                path = Path(tmp) / "scene.toml"
                path.write_text(text)
                scene_mod.load_scene(path)
                names.append(name)
    finally:
        scene_mod.Table.get = original
    return seen, names


def code_keys() -> dict[str, set[str]]:
    """{module: literal names of ``get("name", kind, ...)`` calls} in the scene's parsers."""
    keys: dict[str, set[str]] = {}
    modules = [ROOT / "parsolve" / "scene.py", *sorted((ROOT / "parsolve" / "effects").rglob("*.py"))]
    for path in modules:
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr in ("get", "floats", "table", "tables")
                    and len(node.args) >= 2 - (node.func.attr in ("table", "tables"))
                    and isinstance(node.args[0], ast.Constant)
                    and isinstance(node.args[0].value, str)):
                keys.setdefault(str(path.relative_to(ROOT)), set()).add(node.args[0].value)
    return keys


def render() -> str:
    seen, names = record()
    lines = [
        "# Scene reference",
        "",
        "<!-- generated by scripts/docs_reference.py: do not edit; run it after a schema change"
        " (tests/docs/test_reference.py fails until you do) -->",
        "",
        "Every key below was recorded from the parser itself: `scripts/docs_reference.py` wraps",
        "`parsolve.scene.Table.get` — the one call through which `parsolve/scene.py` and every",
        "effect's `parse` read a scene — and loads every shipped scene (`configs/`), every scene of",
        "these docs and the scenes of `tests/docs/scenes/` written for the keys no other scene",
        "uses. Recording rather than reading the source: a key's section and a default computed",
        "from other keys are known only at run time. Keys the code reads that none of those",
        "scenes uses are listed at the end, found by reading the source (`ast`).",
        "",
        "*Section* `relations[]` is every entry of `[[relations]]`, `regions.<name>` any region;",
        "`(none)`: the key may be left out (the code then does without it or computes a value,",
        "e.g. `penalty`: 100 × E_max / h; see the guide and the theory);",
        "several defaults mean the default depends on other keys.",
        "Physics sections (`[[diffusion]]`, `[solubility]`, `[[contact]]`, ...) are read only when",
        "present: *required* there means required inside the section.",
        "Values are also range-checked (see the [guide](../guide.md#the-command-line)).",
        "",
    ]
    from parsolve.scene import _registry

    physics = {entry.section for entry in _registry().values()}
    used: dict[str, set[str]] = {}
    for section in sorted(seen, key=lambda s: (s != "(top level)", s)):
        lines += [f"## `{section}`", "", "| key | type | default | choices |",
                  "|---|---|---|---|"]
        for key in sorted(seen[section]):
            e = seen[section][key]
            if section == "(top level)" and key in physics:
                e = {**e, "defaults": ["(none): a physics section, read when present"]}
            used.setdefault(key, set()).add(section)
            lines.append(f"| `{key}` | {' / '.join(e['kinds'])} | {' / '.join(e['defaults'])}"
                         f" | {e['choices'] or ''} |")
        lines.append("")
    missing = {mod: sorted(k for k in ks if k not in used) for mod, ks in code_keys().items()}
    missing = {m: ks for m, ks in missing.items() if ks}
    lines += ["## Keys no recorded scene uses", ""]
    if missing:
        lines += ["Read by the code (literal names of `get(...)` calls, per module) but in none of",
                  "the scenes above, so their section, type and default are not recorded here;",
                  "see the module.",
                  ""]
        lines += [f"- `{m}`: " + ", ".join(f"`{k}`" for k in ks) for m, ks in sorted(missing.items())]
    else:
        lines.append("None.")
    lines += ["", "## Scenes recorded", "", ", ".join(f"`{n}`" for n in names), ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare, do not write")
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        if not PAGE.exists() or PAGE.read_text() != text:
            print(f"{PAGE.relative_to(ROOT)} is stale: run python scripts/docs_reference.py",
                  file=sys.stderr)
            return 1
        return 0
    PAGE.parent.mkdir(parents=True, exist_ok=True)
    PAGE.write_text(text)
    print(f"wrote {PAGE.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
