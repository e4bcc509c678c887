"""``ROOT/manifest.csv``: every run of a batch with its parameters, status, exit code, seconds
and result path; ``ROOT/runs.json``: the runs themselves, so that a later ``--collect`` (the
SLURM post-processing job) can rebuild the manifest without the job file."""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path

from parsolve.batch.runner import RESULT, status_of
from parsolve.io.whole import write_whole

MANIFEST, RUNS = "manifest.csv", "runs.json"


def save_runs(root: Path, runs: list[dict]) -> None:
    _replace(root / RUNS, json.dumps(runs, indent=1, default=str))


def _replace(path: Path, text: str) -> None:
    """``path`` written whole or not at all (a full disk leaves no empty or cut file:
    ``--collect`` reads it; the SLURM collect job may write it too)."""
    write_whole(path, lambda name: Path(name).write_text(text))


def load_runs(root: Path) -> list[dict]:
    return json.loads((root / RUNS).read_text())


def write(root: Path, runs: list[dict]) -> list[dict]:
    """Read every run's status from its folder and (re)write the manifest; returns its rows."""
    keys: list[str] = []
    for run in runs:
        keys += [k for k in run.get("params", {}) if k not in keys and k != "ranks"]
    rows = []
    for run in runs:
        folder = root / run["name"]
        status, code, seconds = status_of(folder)
        row = {"name": run["name"]}
        row.update({k: _cell(run.get("params", {}).get(k, "")) for k in keys})
        row.update({"ranks": run.get("ranks", 1), "status": status,
                    "exit_code": "" if code is None else code,
                    "seconds": "" if seconds is None else seconds,
                    "result": str(folder / RESULT)})
        rows.append(row)
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=["name", *keys, "ranks", "status", "exit_code",
                                              "seconds", "result"])
    writer.writeheader()
    writer.writerows(rows)
    _replace(root / MANIFEST, text.getvalue())
    return rows


def _cell(value) -> str:
    return value if isinstance(value, str) else json.dumps(value, default=str)


def read(root: Path) -> list[dict]:
    with open(root / MANIFEST, newline="") as f:
        return list(csv.DictReader(f))
