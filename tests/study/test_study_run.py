"""parsolve study end to end (runs through the batch API in subprocesses: serial tests).

Observed orders against theory on a smooth problem (tests/study/smooth_hole.toml: a hole pushed
out radially inside a box of rollers; every corner is regular): the relative energy-norm error
sqrt(|W_h - W| / W) of the strain energy W converges like h for P1 and h² for P2 triangles."""

import csv
from pathlib import Path

import numpy as np
import pytest

from parsolve.study.cli import main

HERE = Path(__file__).resolve().parent

SMOOTH = f"""
title = "smooth hole"
scene = "{HERE / 'smooth_hole.toml'}"
cost = "compute"
ranks = RANKS
parallel = 2
target = 0.05

[refine]
keys = ["mesh.n_radial", "mesh.n_angular"]
levels = [1, 2, 4, 8]

[[families]]
name = "P1"
set = {{ "mesh.cell" = "triangle" }}

[[families]]
name = "P2"
set = {{ "mesh.cell" = "triangle6" }}

[[quantities]]
name = "energy"
spec = "energy"
reference = "richardson"
error = "energy_norm"

[[quantities]]
name = "ux"
spec = "field:displacement:x@2,0.5"
reference = "richardson"
"""


def rows(path):
    return list(csv.DictReader(open(path)))


def run_study(tmp_path, name, ranks, reduced=False):
    study = tmp_path / f"{name}.toml"
    study.write_text(SMOOTH.replace("RANKS", str(ranks)) + '[reduced]\n"refine.levels" = [1, 2]\n')
    out = tmp_path / f"{name}_runs"
    flags = ["--reduced"] if reduced else []
    assert main([str(study), "--out", str(out), "--save", str(tmp_path / f"{name}_saved")] + flags) == 0
    return out, rows(out / "study.csv")


@pytest.mark.slow
@pytest.mark.serial
def test_study_observed_orders_match_theory(tmp_path, capsys):
    out, table = run_study(tmp_path, "smooth", 1)
    assert [r["status"] for r in table] == ["complete"] * 8
    order = {fam: [float(r["order(energy)"]) for r in table if r["family"] == fam and r["order(energy)"]]
             for fam in ("P1", "P2")}
    assert all(0.95 < p < 1.2 for p in order["P1"]), order      # theory: 1
    assert all(1.7 < p < 2.2 for p in order["P2"]), order       # theory: 2
    # the displacement at a point converges like h² (P1) and h³-h⁴ (P2, superconvergent here)
    ux = {fam: [float(r["order(ux)"]) for r in table if r["family"] == fam and r["order(ux)"]]
          for fam in ("P1", "P2")}
    assert 1.7 < ux["P1"][-1] < 2.3 and ux["P2"][-1] > 2.7, ux
    md = (out / "study.md").read_text()
    assert "Richardson extrapolation of P2 (its 3 finest levels, observed order" in md
    # the answer is the cheapest row under the target (compute seconds are noisy: recompute it)
    ok = [r for r in table if float(r["error(energy)"]) <= 0.05]
    best = min(ok, key=lambda r: float(r["compute s"]))
    assert (f"Cheapest setting with error(energy) ≤ 0.05: {best['family']}, level {best['level']} "
            in capsys.readouterr().out)
    assert (tmp_path / "smooth_saved.png").read_bytes()[:4] == b"\x89PNG"
    assert (tmp_path / "smooth_saved.md").read_text() == md
    mem = [float(r["peak MB/rank"]) for r in table]
    assert all(20 < m < 2000 for m in mem), mem                 # PETSc's -memory_view
    # the same study on 2 ranks per run (two levels): same numbers
    _, two = run_study(tmp_path, "smooth2", 2, reduced=True)
    assert [(r["family"], r["level"]) for r in two] == [("P1", "x1"), ("P1", "x2"), ("P2", "x1"), ("P2", "x2")]
    for a, b in zip([r for r in table if r["level"] in ("x1", "x2")], two):
        assert a["DOFs"] == b["DOFs"]
        np.testing.assert_allclose(float(a["energy"]), float(b["energy"]), rtol=1e-9)
        np.testing.assert_allclose(float(a["ux"]), float(b["ux"]), rtol=1e-9)


@pytest.mark.serial
def test_missing_field_exits_2_after_the_first_run(tmp_path, capsys):
    study = tmp_path / "bad.toml"
    study.write_text(SMOOTH.replace("RANKS", "1").replace("field:displacement:x@2,0.5",
                                                          "field:temperature:x@2,0.5"))
    assert main([str(study), "--out", str(tmp_path / "runs")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"parsolve study: {study}: quantities[1].spec: no field 'temperature'"), err
    assert not (tmp_path / "runs" / "01_P1_01").exists()          # stopped after the first run
