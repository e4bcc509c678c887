"""parsolve: parallel finite elements with associated and non-associated linear relations."""

__version__ = "0.1.0"


def __getattr__(name: str):
    """The Python API (``parsolve.api``) on first use: ``import parsolve`` alone stays light
    and initializes neither MPI nor PETSc (the command line initializes PETSc with its options
    first)."""
    if name in ("Scene", "Result", "Step", "run", "check", "load", "api"):
        import importlib

        api = importlib.import_module("parsolve.api")
        return api if name == "api" else getattr(api, name)
    raise AttributeError(f"module 'parsolve' has no attribute {name!r}")
