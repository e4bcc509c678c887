"""Shared by the batch tests: the command line in a subprocess, and the controlled bar's
analytic end force."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs"
BAR = CONFIGS / "controlled_bar.toml"


def clean_env() -> dict[str, str]:
    """This pytest process may be an MPI singleton: keep its MPI variables from the child."""
    return {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}


def parsolve(*args, cwd=None, timeout=600, env=None) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "parsolve", *map(str, args)]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=cwd, timeout=timeout,
                          env=env or clean_env())


def end_force(E: float) -> float:
    """The control's multiplier at the last step: E·H·δ/L with H = 0.1, δ = 1e-4, L = 1."""
    return E * 0.1 * 1e-4 / 1.0


def check_bar(result: Path, E: float, steps: int) -> None:
    """The controlled bar's result: complete, δ ramps to 1e-4, the end force is E·H·δ/L."""
    with h5py.File(result, "r") as f:
        assert f.attrs["status"] == "complete"
        delta = f["relations/control/primal"][:, 0]
        force = f["relations/control/multiplier"][:, 0]
    np.testing.assert_allclose(delta, 1e-4 * np.arange(1, steps + 1) / steps, rtol=1e-12)
    np.testing.assert_allclose(force[-1], end_force(E), rtol=1e-10)


def jobs_file(folder: Path, body: str, name: str = "jobs.toml") -> Path:
    path = folder / name
    path.write_text(f'scene = "{BAR}"\noutput = "runs"\n' + body)
    return path
