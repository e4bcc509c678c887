"""parsolve: parallel finite elements with associated and non-associated linear relations."""

__version__ = "0.1.0"
