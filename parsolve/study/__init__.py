"""Accuracy against cost: ``parsolve study STUDY.toml`` (see ``config`` for the file format)."""
