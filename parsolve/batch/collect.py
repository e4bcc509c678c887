"""``python -m parsolve.batch.collect ROOT``: rewrite ROOT/manifest.csv from the run folders
(the SLURM post-processing job; also ``parsolve batch JOBS.toml --collect``)."""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

from parsolve.batch import manifest


def collect(root: Path) -> list[dict]:
    return manifest.write(root, manifest.load_runs(root))


def summary(rows: list[dict]) -> str:
    counts = Counter(r["status"].split(":")[0] for r in rows)
    return ", ".join(f"{n} {s}" for s, n in sorted(counts.items()))


if __name__ == "__main__":
    root = Path(sys.argv[1]).resolve()
    rows = collect(root)
    print(f"{root / manifest.MANIFEST}: {len(rows)} runs: {summary(rows)}")
