"""The generated pages equal what their scripts generate now: a scene schema change or a new
benchmark result without regenerating the docs fails here (run the script named)."""
import runpy
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("script", ["docs_reference.py", "docs_benchmarks.py"])
def test_generated_page_is_current(script, capsys):
    module = runpy.run_path(str(ROOT / "scripts" / script))
    status = module["main"](["--check"])
    assert status == 0, capsys.readouterr().err


def test_reference_lists_every_section_of_the_shipped_scenes():
    """Spot check: keys the shipped scenes use are on the page."""
    page = (ROOT / "docs" / "reference" / "scene.md").read_text()
    for line in ("## `materials[]`", "| `E` | number |", "## `contact[]`", "| `friction` |",
                 "## `solubility`", "| `dual` |", "## `solver`"):
        assert line in page, line
