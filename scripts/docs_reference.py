"""Write docs/reference/scene.md: every key the scene parser accepts, from the parser itself.

The schema of a scene is its parser: ``parsolve.scene.parse_scene`` reads its own sections and
hands each physics section to its registry entry's ``parse`` (effects today, every registry
that joins them), all through one reading class, ``parsolve.scene.Table`` (``get``, ``floats``,
``table``, ``tables``, ``has``). This script explores that parser rather than the scenes that
happen to exist: it feeds ``parse_scene`` a probing table whose answers are decisions — is a
key present, which of its choices, which type of value, does a table of user names hold an
entry — and runs it again for every decision and answer it has not yet tried, starting from
the run that found the decision, until every answer of every decision was tried once. Every
``get`` on the way records its section, key, type, default and choices, and under which choice
of the same table it is read (a model's parameters, a generator's sizes). A key the parser
reads is found however rare it is in the shipped scenes; a new registry entry's keys appear
without a line here. The meanings come from ``docs/reference/meanings.toml`` (section → key →
one sentence) and from the registries (a relation kind's description); tests/docs/
test_reference.py fails on a key without one, or one the parser no longer reads.

    python scripts/docs_reference.py            # writes docs/reference/scene.md
    python scripts/docs_reference.py --check    # exit 1 if the committed page differs
"""
from __future__ import annotations

import argparse
import contextlib
import io
import re
import sys
import tomllib
from collections import deque
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "reference" / "scene.md"
MEANINGS = ROOT / "docs" / "reference" / "meanings.toml"
NAME = "<name>"          # the entry of a table whose keys are the user's names
GLOBAL = ("model",)      # tables whose choices shape every other section (the dimension)
MAX_RUNS = 50000         # a bound on the exploration (it needs a few thousand runs)

# the answers tried for a value of each type (the first is the default answer); several, so
# that a range check failing on one lets another go on to the keys read after it
CANDIDATES = {
    bool: [True, False],
    int: [1, 2, 3],
    float: [0.25, 1.0, 2.0],
    str: ["all", "x", "u", "xx", "ramp"],
    list: [[1.0, 1.0], ["x"], [[0.0, 0.0], [1.0, 1.0]]],
}


class Stop(Exception):
    """The run met a decision beyond the exploration's bound (never raised by the parser)."""


class Probe:
    """One run's answers: forced ones {decision: answer}, the rest the default (0)."""

    def __init__(self, forced: dict):
        self.forced = forced
        self.seen: dict[tuple, int] = {}          # decision -> number of answers, this run
        self.taken: dict[tuple, int] = {}         # decision -> answer given, this run
        self.records: list[tuple] = []            # (section, key, kind, default, choices, when)
        self.chosen: dict[str, dict] = {}         # table path -> {choice key: value}

    def decide(self, decision: tuple, count: int) -> int:
        self.seen[decision] = count
        answer = self.forced.get(decision, 0)
        self.taken[decision] = answer
        return answer


PROBE: Probe | None = None


def _section(path: str) -> str:
    return re.sub(r"\[\d+\]", "[]", path) or "(top level)"


def _context(path: str) -> tuple:
    """The choices that shape a decision: a decision under other choices is another one (a
    relation's ``component`` under ``type = "mean"``, a cylinder's keys under a 3D model).
    Those of the table itself and of the tables holding it, and the model's (its hypothesis
    and dimension give the dimension every section's reader receives)."""
    return tuple(sorted((p, k, v) for p, chosen in PROBE.chosen.items() for k, v in chosen.items()
                        if p in GLOBAL or path == p or path.startswith(p + ".") or not p))


class ProbeData(dict):
    """A TOML table whose keys are decided when the parser asks for them."""

    def __init__(self, path: str):
        super().__init__()
        self.path, self.absent, self.provisional, self.listed = path, set(), set(), False
        self.asked: set[str] = set()      # keys whose presence the parser asked before reading

    def __contains__(self, key) -> bool:
        if dict.__contains__(self, key):
            return True
        if key in self.absent:
            return False
        if PROBE.decide(("present", _section(self.path), key, _context(self.path)), 2):
            dict.__setitem__(self, key, 1.0)      # its value is made when a get asks its type
            self.provisional.add(key)
            self.asked.add(key)
            return True
        self.absent.add(key)
        return False

    def __iter__(self):
        # a table of user names (regions, evolutions, PETSc options): one entry, or none
        if not self.listed and not dict.__len__(self) and NAME not in self.path:
            self.listed = True
            if PROBE.decide(("entry", _section(self.path)), 2):
                dict.__setitem__(self, NAME, 1.0)
                self.provisional.add(NAME)
                self.asked.add(NAME)
        return dict.__iter__(self)

    def keys(self):
        return list(iter(self))


def _value(data: ProbeData, name: str, kind, choices):
    """The value a present key takes: a decision among its choices or its types' answers."""
    key = data.path + "." + name if data.path else name
    if choices is not None:
        options = list(choices)
    else:
        kinds = kind if isinstance(kind, tuple) else (kind,)
        options = []
        for k in kinds:
            options += [ProbeData(key)] if k is dict else CANDIDATES.get(k, [])
    return options[PROBE.decide(("value", _section(data.path), name, _context(data.path)),
                                len(options))]


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


def _patched(table_cls):
    """The reading methods of ``Table`` wrapped to record and to answer from the probe."""
    original = {n: getattr(table_cls, n) for n in ("get", "floats", "tables", "done")}
    inner: dict[int, str] = {}     # table id -> name being read by floats/tables (not re-recorded)
    read: dict[int, set] = {}      # table id -> names recorded (a key accepted but never read:
    #                                 at done(), e.g. a deprecated key taken whatever its value)

    def _asked(self, name: str, default):
        """A key read as required after the parser asked whether it is there may be left out
        (one of several, or a choice's alternative): its default is (none), not required."""
        if default is ... and isinstance(self.data, ProbeData) and name in self.data.asked:
            return None
        return default

    def prepare(self, name: str, default, make):
        data = self.data
        if not isinstance(data, ProbeData):
            return
        if dict.__contains__(data, name) and name not in data.provisional:
            return
        if default is ... or name in data.provisional or name in data:
            dict.__setitem__(data, name, make())
            data.provisional.discard(name)

    def record(self, name, kind_text, default, choices):
        read.setdefault(id(self), set()).add(name)
        section = _section(self.path)
        when = tuple(sorted(PROBE.chosen.get(self.path, {}).items()))
        PROBE.records.append((section, name, kind_text, _default(default),
                              None if choices is None else tuple(choices), when))

    def get(self, name, kind, default=..., choices=None):
        if "[" in name or not isinstance(self.data, ProbeData):   # the parser's own sub-tables
            return original["get"](self, name, kind, default, choices)
        if inner.get(id(self)) != name:
            record(self, name, _kind(kind), _asked(self, name, default), choices)
        prepare(self, name, default, lambda: _value(self.data, name, kind, choices))
        value = original["get"](self, name, kind, default, choices)
        if choices is not None:
            PROBE.chosen.setdefault(self.path, {})[name] = value
        return value

    def floats(self, name, length=None, default=...):
        if not isinstance(self.data, ProbeData):
            return original["floats"](self, name, length, default)
        record(self, name, "array of numbers" + (f" ({length})" if length else ""),
               _asked(self, name, default), None)
        prepare(self, name, default, lambda: [float(i + 1) for i in range(length or 2)])
        inner[id(self)] = name
        try:
            return original["floats"](self, name, length, default)
        finally:
            inner.pop(id(self), None)

    def tables(self, name):
        if not isinstance(self.data, ProbeData):
            return original["tables"](self, name)
        record(self, name, "array of tables", [], None)
        path = self.key(name)
        prepare(self, name, [], lambda: [ProbeData(path + "[0]")])
        inner[id(self)] = name
        try:
            return original["tables"](self, name)
        finally:
            inner.pop(id(self), None)

    def done(self):
        if isinstance(self.data, ProbeData):
            for name in sorted(self.used - read.get(id(self), set())):
                record(self, name, "any", None, None)
        return original["done"](self)

    return original, {"get": get, "floats": floats, "tables": tables, "done": done}


def _table_class(scene_mod):
    """The one reading class: ``parsolve.schema.Table`` where the reading primitives live in
    their own module, else the scene module's."""
    try:
        from parsolve import schema
    except ImportError:
        return scene_mod.Table
    return getattr(schema, "Table", scene_mod.Table)


def explore() -> tuple[dict, int]:
    """{section: {key: entry}} over every answer of every decision of ``parse_scene``, and
    the number of runs."""
    global PROBE
    from parsolve import scene as scene_mod
    from parsolve.errors import InputError

    table_cls = _table_class(scene_mod)
    original, patched = _patched(table_cls)
    found: dict[str, dict[str, dict]] = {}
    tried: set[tuple] = set()
    queue = deque([{}])
    runs = 0
    for n, f in patched.items():
        setattr(table_cls, n, f)
    try:
        while queue and runs < MAX_RUNS:
            forced = queue.popleft()
            PROBE = Probe(forced)
            runs += 1
            try:
                with contextlib.redirect_stderr(io.StringIO()):   # warnings of probe values
                    scene_mod.parse_scene(ProbeData(""), "probe.toml")
            except (InputError, Stop):
                pass                       # the keys read up to the error are the parser's
            except (TypeError, ValueError, KeyError, AttributeError, IndexError, ZeroDivisionError):
                pass                       # a probe value no scene could hold (not TOML's)
            _collect(found, PROBE.records)
            for decision, count in PROBE.seen.items():
                if decision in forced:
                    continue
                for answer in range(1, count):
                    if (decision, answer) not in tried:
                        tried.add((decision, answer))
                        queue.append({**forced, decision: answer})
    finally:
        for n, f in original.items():
            setattr(table_cls, n, f)
        PROBE = None
    if queue:
        raise RuntimeError(f"the parser's exploration needs more than {MAX_RUNS} runs")
    return found, runs


def _collect(found: dict, records: list) -> None:
    for section, key, kind, default, choices, when in records:
        entry = found.setdefault(section, {}).setdefault(
            key, {"kinds": [], "defaults": [], "choices": None, "when": []})
        for lst, v in ((entry["kinds"], kind), (entry["defaults"], default)):
            if v not in lst:
                lst.append(v)
        if choices is not None:
            entry["choices"] = choices
        entry["when"].append(dict(when))


def _condition(section: str, key: str, found: dict) -> str:
    """'model = von_mises' when the key is read under some answers of a choice only."""
    entry = found[section][key]
    parts = []
    for choice, chosen in found[section].items():
        if choice == key or chosen["choices"] is None:
            continue
        under = {w.get(choice, None) for w in entry["when"]}
        if None in under:           # read before that choice, or without it
            continue
        if set(under) != set(chosen["choices"]):
            parts.append(f"{choice} = " + " or ".join(f"`{v}`" for v in chosen["choices"]
                                                       if v in under))
    return "; ".join(parts)


def registry_meanings() -> dict[str, dict[str, str]]:
    """Meanings the registries give of their own entries: a relation's ``type`` from each
    kind's description (``parsolve.relation_kinds.registry``), so that a kind is described
    where it is added."""
    from parsolve.relation_kinds.registry import RELATIONS

    kinds = "; ".join(f"`{name}`: {entry.description}" for name, entry in RELATIONS.items())
    return {"relations[]": {"type": f"The relation's kind. {kinds}."}}


def meanings() -> dict[str, dict[str, str]]:
    """docs/reference/meanings.toml, with the registries' own meanings."""
    out = tomllib.loads(MEANINGS.read_text()) if MEANINGS.exists() else {}
    for section, keys in registry_meanings().items():
        out.setdefault(section, {}).update(keys)
    return out


def render() -> str:
    found, runs = explore()
    means = meanings()
    lines = [
        "# Scene reference",
        "",
        "<!-- generated by scripts/docs_reference.py from the parser and"
        " docs/reference/meanings.toml: do not edit -->",
        "",
        "Every key the scene parser accepts, found by exploring the parser itself",
        "(`scripts/docs_reference.py` answers every question `parsolve/scene.py` and each registry",
        "entry's `parse` ask of a scene — is this key present, which choice, which type — in",
        "every way once), with its type, default, choices and meaning. *Section* `relations[]`",
        "is every entry of `[[relations]]`; `<name>` a name of your own (a region, an evolution,",
        "a PETSc option). *Default* `required`: the key must be given (inside its section, for a",
        "section read only when present); `(none)`: it may be left out (the code then does",
        "without it or computes a value); several defaults: the default depends on other keys.",
        "*When*: the key is read only under that choice of another key of the same table.",
        "Values are also range-checked (see the [guide](../guide.md#the-command-line)).",
        "",
    ]
    for section in sorted(found, key=lambda s: (s != "(top level)", s)):
        lines += [f"## `{section}`", "", "| key | type | default | choices | when | meaning |",
                  "|---|---|---|---|---|---|"]
        for key in sorted(found[section], key=str.lower):
            e = found[section][key]
            choices = ", ".join(f"`{c}`" for c in e["choices"]) if e["choices"] else ""
            meaning = means.get(section, {}).get(key, "")
            lines.append(f"| `{key}` | {' / '.join(e['kinds'])} | {' / '.join(e['defaults'])}"
                         f" | {choices} | {_condition(section, key, found)} | {meaning} |")
        lines.append("")
    return "\n".join(lines)


def accepted() -> dict[str, set[str]]:
    """{section: keys} the parser accepts (for the tests)."""
    found, _ = explore()
    return {s: set(keys) for s, keys in found.items()}


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
