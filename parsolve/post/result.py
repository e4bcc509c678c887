"""Read access to a result file (DESIGN §5) with input errors that name the file and the key."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from parsolve.errors import InputError

# Component names by (space dimension, number of components): vectors, then Voigt tensors.
COMPONENTS = {(2, 1): ("value",), (3, 1): ("value",),
              (2, 2): ("x", "y"), (3, 3): ("x", "y", "z"),
              (2, 3): ("xx", "yy", "xy"), (3, 6): ("xx", "yy", "zz", "yz", "xz", "xy")}


class Result:
    """An open result file; use as a context manager."""

    def __init__(self, path: str | Path):
        self.path = str(path)
        try:
            self.file = h5py.File(self.path, "r")
        except (OSError, ValueError) as exc:
            raise InputError(f"cannot open result file ({exc})", self.path) from None
        f = self.file
        if "mesh/points" not in f or "mesh/cells" not in f or "steps/time" not in f:
            self.close()
            raise InputError("not a parsolve result file (no /mesh or /steps)", self.path)
        self.points = f["mesh/points"][()]
        self.dim = self.points.shape[1]
        (self.cell_type, cells), = f["mesh/cells"].items()
        self.cells = cells[()]
        self.times = f["steps/time"][()]

    def __enter__(self) -> "Result":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self.file.close()

    @property
    def stem(self) -> str:
        return Path(self.path).stem

    @property
    def attrs(self) -> dict:
        return dict(self.file.attrs)

    def names(self, group: str) -> list[str]:
        return sorted(self.file[group]) if group in self.file else []

    def dataset(self, path: str, key: str) -> np.ndarray:
        """The dataset at ``path``; a missing one is an InputError naming ``key``."""
        if path not in self.file or not isinstance(self.file[path], h5py.Dataset):
            group = path.rsplit("/", 2)[0] if path.startswith("/relations") else path.rsplit("/", 1)[0]
            known = ", ".join(self.names(group)) or "none"
            raise InputError(f"no /{path} in the file (known under /{group}: {known})", self.path, key)
        return self.file[path][()]

    def component(self, ncomp: int, comp: str, key: str) -> int:
        """Index of a component given by name (x, y, z; xx, yy, ... in Voigt order) or number."""
        names = COMPONENTS.get((self.dim, ncomp), ())
        if comp in names:
            return names.index(comp)
        if comp.isdigit() and int(comp) < ncomp:
            return int(comp)
        raise InputError(f"no component {comp!r} (known: {', '.join(names) or 'none'}, "
                         f"or 0..{ncomp - 1})", self.path, key)
