"""Baselines the benchmarks measure parsolve against (plain modules, imported as
``baselines.NAME`` from scripts/: see bench_harness)."""
