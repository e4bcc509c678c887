"""Helpers shared by several test modules (a test module imports no other test module)."""
