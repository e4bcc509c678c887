#!/usr/bin/env bash
# The main demo: Kirsch's plate with a hole on 2 ranks; prints the stress concentration.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
mkdir -p out
bash scripts/mpirun.sh -n 2 .venv/bin/parsolve run configs/kirsch.toml -o out/kirsch.h5
.venv/bin/python scripts/kirsch_report.py out/kirsch.h5
