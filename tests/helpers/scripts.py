"""A script of scripts/ as a module (e.g. the generator of a shipped mesh, which a test checks
against the shipped file and reuses for variants)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


def load_script(name: str):
    """scripts/<name>.py, imported under its own name; its own imports of the other scripts
    resolve as when it runs from scripts/ (the folder first on the path while it loads)."""
    spec = importlib.util.spec_from_file_location(name, SCRIPTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(SCRIPTS))
    try:
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(SCRIPTS))
    return module
