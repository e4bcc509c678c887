"""The docs' pictures: every picture scripts/render_docs.py makes is committed and shown by a
page, every numbered guide section and the home page show one, scripts/docs.sh regenerates
them, and the script draws a shipped scene's result into a PNG whose colors follow the field."""
import re
import runpy
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
IMAGES = ROOT / "docs" / "img" / "scenes"


@pytest.fixture(scope="module")
def script():
    return runpy.run_path(str(ROOT / "scripts" / "render_docs.py"))


def png_pixels(path: Path) -> np.ndarray:
    """(height, width, channels) of a PNG, top row first, read by VTK's PNG reader."""
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy

    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", path
    reader = vtk.vtkPNGReader()
    reader.SetFileName(str(path))
    reader.Update()
    image = reader.GetOutput()
    width, height, _ = image.GetDimensions()
    scalars = image.GetPointData().GetScalars()
    pixels = vtk_to_numpy(scalars).reshape(height, width, scalars.GetNumberOfComponents())
    return pixels[::-1]


def test_every_picture_is_committed_and_shown(script):
    names = {p.name for p in script["PICTURES"]}
    committed = {p.stem for p in IMAGES.glob("*.png")}
    assert committed == names, (committed ^ names)
    shown = set()
    for page in (ROOT / "docs").rglob("*.md"):
        shown |= set(re.findall(r"\]\(img/scenes/([\w-]+)\.png\)", page.read_text()))
    assert shown == names, (shown ^ names)
    for name in names:
        assert (IMAGES / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_home_page_and_every_guide_section_show_a_picture():
    index = (ROOT / "docs" / "index.md").read_text()
    assert "](img/scenes/" in index and "## Quick start" in index
    guide = (ROOT / "docs" / "guide.md").read_text()
    sections = re.split(r"^## (?=\d+\. )", guide, flags=re.M)[1:]
    assert len(sections) >= 9
    for section in sections:
        body = section.split("\n## ", 1)[0]
        assert re.search(r"!\[[^\]]*\]\(img/(scenes|benchmarks)/[\w-]+\.png\)", body), \
            section.splitlines()[0]


def test_docs_stage_regenerates_the_pictures():
    text = (ROOT / "scripts" / "docs.sh").read_text()
    render = text.index("scripts/render_docs.py")
    assert render < text.index("mkdocs build")


@pytest.mark.serial
def test_a_picture_is_drawn_from_its_scenes_result(script, tmp_path):
    """The shear laminate, drawn again: a PNG of the set size, the mesh in the field's color
    (σxy is uniform, so one color from the bar's middle), on white."""
    assert script["main"](["periodic_shear_laminate", "--out", str(tmp_path)]) == 0
    pixels = png_pixels(tmp_path / "periodic_shear_laminate.png")
    width, height = script["SIZE"]
    assert pixels.shape[:2] == (height, width)
    rgb = pixels[..., :3].reshape(-1, 3)
    white = np.all(rgb == 255, axis=1)
    assert 0.3 < white.mean() < 0.95                 # a drawing, on a white page
    model = pixels[int(0.2 * height):int(0.8 * height), :, :3].reshape(-1, 3)
    colored = model[~np.all(model == 255, axis=1) & (model.max(axis=1) - model.min(axis=1) > 100)]
    assert len(colored) > 1000
    # a uniform field sits mid-bar: the lookup table's green (hue 1/3), not blue nor red
    r, g, b = np.median(colored, axis=0)
    assert g > 200 and r < 100 and b < 100, (r, g, b)


@pytest.mark.serial
def test_own_result_is_drawn_with_the_guides_command(script, tmp_path, monkeypatch, capsys):
    """`render_docs.py --result RESULT.h5 ...` (the guide's §7): the laminate's σxy, uniform,
    mid-bar green; a field the file lacks is refused naming the fields it has."""
    from parsolve.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["run", str(ROOT / "configs" / "periodic_shear_laminate.toml"), "-o", "lam.h5"]) == 0
    capsys.readouterr()
    assert script["main"](["--result", "lam.h5", "--field", "fields/stress", "--component", "2",
                           "--png", "lam.png"]) == 0
    pixels = png_pixels(tmp_path / "lam.png")
    model = pixels[int(0.2 * pixels.shape[0]):int(0.8 * pixels.shape[0]), :, :3].reshape(-1, 3)
    colored = model[model.max(axis=1) - model.min(axis=1) > 100]
    r, g, b = np.median(colored, axis=0)
    assert g > 200 and r < 100 and b < 100, (r, g, b)
    with pytest.raises(SystemExit, match=r"no 'fields/pressure' \(known: fields/displacement"):
        script["main"](["--result", "lam.h5", "--field", "fields/pressure", "--png", "x.png"])
    assert not (tmp_path / "x.png").exists()
