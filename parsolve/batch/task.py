"""One task of a SLURM job array: ``python -m parsolve.batch.task ROOT TASKS INDEX`` runs the
run named on line INDEX of the file TASKS (its folder under ROOT is already prepared)."""

from __future__ import annotations

import sys
from pathlib import Path

from parsolve.batch import runner


def main(argv: list[str]) -> int:
    root, tasks, index = Path(argv[0]), Path(argv[1]), int(argv[2])
    name = tasks.read_text().splitlines()[index]
    code = runner.run_here(root / name)
    print(f"parsolve batch task {index}: {name}: exit {code}: {runner.status_of(root / name)[0]}")
    return 0  # recorded: the run's failure is in its outcome, not the task's


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
