"""Bad study input: exit 2, one line naming the file and the key, nothing written, before any
run (serial: in-process command line; nothing here runs a solve)."""

import time

import pytest

from conftest import CONFIGS
from parsolve.study.cli import main
from parsolve.study.expression import evaluate_expression

STUDY = f"""
title = "bar"
scene = "{CONFIGS / 'controlled_bar.toml'}"
ranks = 1
parallel = 1
[refine]
keys = ["mesh.nx", "mesh.ny"]
levels = [1, 2]
[vary]
"mesh.cell" = ["quad", "triangle"]
[[quantities]]
name = "force"
spec = "relation:control:multiplier"
reference = "1e4"
"""

pytestmark = pytest.mark.serial

# (change to the study file, extra command-line arguments, key in the message, fragment)
CASES = [
    (("levels = [1, 2]", f"levels = {list(range(1, 1001))}"), [], "refine.levels", "more than 12"),
    (('"mesh.cell" = ["quad", "triangle"]', '"mesh.cell" = ["quad", "triangle"]\n'
      '"materials[0].E" = [' + ", ".join(["1e9"] * 101) + "]"), [], "vary", "more than 200"),
    (("relation:control:multiplier", "field:temperature:0@0.5,0.05"), [], "quantities[0].spec",
     "no field 'temperature'"),
    (("relation:control:multiplier", "cell_field:strain:xx@0.5,0.05"), [], "quantities[0].spec",
     "no cell field 'strain'"),
    # a cell field an elastic run never writes (damage: a damage material's state)
    (("relation:control:multiplier", "cell_field:damage@0.5,0.05"), [], "quantities[0].spec",
     "no cell field 'damage' (known: stress)"),
    # a family's value the model refuses (not its scene parser): the family's key
    (('[vary]\n"mesh.cell" = ["quad", "triangle"]', '[[families]]\nname = "none"\nset = { "mesh.nx" = 0 }'),
     [], "families[0]", "mesh.nx: invalid generator parameters"),
    (("relation:control:multiplier", "field:displacement:x@5,0.05"), [], "quantities[0].spec",
     "is outside the mesh"),
    (("relation:control:multiplier", "field:displacement:x@0.5,0.05,0"), [], "quantities[0].spec",
     "needs 2 coordinates"),
    (("relation:control:multiplier", "max:field:displacement:x@nowhere"), [], "quantities[0].spec",
     "region 'nowhere'"),
    (('reference = "1e4"', 'reference = "1 / 0"'), [], "quantities[0].reference", "division by zero"),
    (('reference = "1e4"', 'reference = "exp(1000)"'), [], "quantities[0].reference", "overflows"),
    (('reference = "1e4"', 'reference = "9**9**9"'), [], "quantities[0].reference", "overflows"),
    (('reference = "1e4"', 'reference = "' + "1+" * 150 + '1"'), [], "quantities[0].reference",
     "longer than"),
    (('reference = "1e4"', 'reference = "' + "-" * 60 + '1"'), [], "quantities[0].reference",
     "nested deeper"),
    (('reference = "1e4"', "reference = inf"), [], "quantities[0].reference", "finite"),
    (("relation:control:multiplier", "field:displacement:q@0.5,0.05"), [], "quantities[0].spec",
     "no component 'q' of 'displacement'"),
    (("ranks = 1", 'args = ["-ksp_type", "nosuch"]\nranks = 1'), [], "args",
     "-ksp_type: unknown type ('nosuch')"),
    (('"mesh.cell" = ["quad", "triangle"]', '"mesh.cell" = ["quad", "triangle"]\n'
      '"solver.petsc.pc_type" = ["nosuch"]'), [], "vary", "unknown type ('nosuch')"),
    (("[refine]\nkeys = [\"mesh.nx\", \"mesh.ny\"]\nlevels = [1, 2]",
      '[refine]\nfiles = ["coarse.msh", "fine.msh"]'), [], "refine.files[0]", "no mesh file"),
    (("relation:control:multiplier", "relation:left_x:multiplier"), [], "quantities[0].spec",
     "relation 'left_x' has 4 rows: add :sum, :mean"),
    (("relation:control:multiplier", "relation:control:multiplier:1"), [], "quantities[0].spec",
     "relation 'control' has 1 rows"),
    (("relation:control:multiplier", "relation:left_x:resultant:z"), [], "quantities[0].spec",
     "no resultant component 'z' (known: x, y, mz)"),
    (("ranks = 1", "ranks = 0"), [], "ranks", "at least 1"),
    (("parallel = 1", "parallel = 0"), [], "parallel", "at least 1"),
    (("ranks = 1", "ranks = 1\ntarget = -1.0"), [], "target", "positive"),
    (None, ["--parallel", "0"], "--parallel", "positive integer"),
    (None, ["--target", "0"], "--target", "positive finite"),
    (None, ["--target", "nan"], "--target", "positive finite"),
    (None, ["--target", "abc"], "--target", "positive finite"),
    (None, ["--out", "{file}"], "--out", "is a file"),
    (None, ["--out", "{file}/runs"], "--out", "is a file, not a folder"),
    (None, ["--save", "{file}/saved"], "--save", "is a file, not a folder"),
]


@pytest.mark.parametrize("change, extra, key, fragment", CASES)
def test_bad_study_input(tmp_path, capsys, change, extra, key, fragment):
    path = tmp_path / "study.toml"
    path.write_text(STUDY.replace(*change) if change else STUDY)
    afile = tmp_path / "a_file"
    afile.write_text("not a folder")
    before = sorted(p.name for p in tmp_path.iterdir())
    extra = [a.replace("{file}", str(afile)) for a in extra]
    out = [] if "--out" in extra else ["--out", str(tmp_path / "runs")]
    start = time.perf_counter()
    assert main([str(path)] + out + extra) == 2
    assert time.perf_counter() - start < 60  # refused before any run (generous, not a timing)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    where = "command line" if key.startswith("--") else str(path)
    assert err[0].startswith(f"parsolve study: {where}: {key}: "), err[0]
    assert fragment in err[0], err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == before   # nothing written
    assert afile.read_text() == "not a folder"


@pytest.mark.parametrize("text, fragment", [
    ("9**9**9", "overflows"),
    ("10.0**400", "overflows"),
    ("1e308 * 10", "overflows"),
    ("exp(1000)", "overflows"),
    ("1 / 0", "division by zero"),
    ("0 ** -1", "outside its domain"),
    ("(-8) ** (1 / 3)", "outside its domain"),
    ("sqrt(-1)", "outside its domain"),
    ("log(0)", "outside its domain"),
    ("1e999", "not finite"),
    ("(" * 150 + "1" + ")" * 150, "longer than"),
    ("abs(-" * 20 + "1" + ")" * 20, "nested deeper"),
    ("-" * 199 + "1", "nested deeper"),
    ("1" * 5000, "longer than"),
    ("x", "unsupported"),
    ("__import__('os')", "unsupported"),
])
def test_bad_expressions(text, fragment):
    with pytest.raises(ValueError, match=fragment.replace("(", r"\(")):
        evaluate_expression(text)


def test_expressions_in_floats():
    assert evaluate_expression("2 ** 10") == 1024.0
    assert evaluate_expression("2 ** -1074") == 5e-324
    assert evaluate_expression("(-2) ** 3") == -8.0
    assert evaluate_expression("-" * 30 + "1") == 1.0
