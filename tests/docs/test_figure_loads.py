"""The guide's picture of the loads (docs/img/loads.png: the shipped thick cylinder under
pressure and the fin cooled by convection, each against its closed form) is
scripts/figure_loads.py's: the guide shows it and names the script, and the script draws it
again from the shipped scenes, pixel for pixel up to anti-aliasing."""

import re
import runpy
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
FIGURE = ROOT / "docs" / "img" / "loads.png"


def test_the_loads_section_shows_the_figure_and_names_its_script():
    guide = (ROOT / "docs" / "guide.md").read_text()
    loads = guide.split("\n## 10. Loads\n", 1)[1].split("\n## ", 1)[0]
    assert re.search(r"!\[[^\]]+\]\(img/loads\.png\)", loads)
    assert "`scripts/figure_loads.py`" in loads


@pytest.mark.serial   # runs two shipped scenes on one rank
def test_the_script_draws_the_committed_figure(tmp_path):
    from matplotlib.image import imread

    script = runpy.run_path(str(ROOT / "scripts" / "figure_loads.py"))
    script["main"](tmp_path / "loads.png")
    new, committed = imread(tmp_path / "loads.png"), imread(FIGURE)
    assert new.shape == committed.shape
    assert np.abs(new - committed).mean() < 1e-3, np.abs(new - committed).mean()
