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


SCALE = 1e100  # beyond any value a run writes; random bytes read as float64 mostly land here
NAN = "nan"    # a dataset's attribute: its NaN mean "no value" (post --derive), not damage


def _reason(exc: Exception) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


class Dataset:
    """An HDF5 dataset of a result whose reads are checked: a read HDF5 refuses (a Fletcher32
    checksum error, a truncated file) or a non-finite or out-of-scale value is an InputError
    naming the file and the dataset, never a number."""

    def __init__(self, ds: h5py.Dataset, path: str):
        self.h5, self.path = ds, path
        self.shape, self.dtype, self.attrs = ds.shape, ds.dtype, ds.attrs

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, key) -> np.ndarray:
        try:
            values = self.h5[key]
        except (OSError, RuntimeError, ValueError) as exc:
            raise InputError(f"{self.h5.name}: damaged data ({_reason(exc)})", self.path) from None
        if np.asarray(values).dtype.kind == "f":
            bad = np.isinf(values) | (np.abs(values) > SCALE)
            if NAN not in self.attrs:
                bad |= np.isnan(values)
            if np.any(bad):
                value = np.asarray(values)[bad].flat[0]
                raise InputError(f"{self.h5.name}: damaged data ({np.count_nonzero(bad)} "
                                 f"non-finite or out-of-scale value(s), e.g. {value:.3g})",
                                 self.path)
        return values


class Group:
    """An HDF5 group of a result: its datasets are :class:`Dataset` (checked reads)."""

    def __init__(self, group: h5py.Group, path: str):
        self.h5, self.path, self.attrs = group, path, group.attrs

    def _guard(self, action):
        try:
            return action()
        except (OSError, RuntimeError) as exc:
            raise InputError(f"{self.h5.name}: damaged file structure ({_reason(exc)})",
                             self.path) from None

    def __contains__(self, name: str) -> bool:
        return self._guard(lambda: name in self.h5)

    def __iter__(self):
        return iter(self._guard(lambda: list(self.h5)))

    def __len__(self) -> int:
        return self._guard(lambda: len(self.h5))

    def __getitem__(self, name: str) -> "Dataset | Group":
        obj = self._guard(lambda: self.h5[name])
        return Dataset(obj, self.path) if isinstance(obj, h5py.Dataset) else Group(obj, self.path)

    def get(self, name: str, default=None):
        return self[name] if name in self else default

    def keys(self) -> list[str]:
        return list(self)

    def items(self) -> list[tuple[str, "Dataset | Group"]]:
        return [(name, self[name]) for name in self]


class Result:
    """An open result file; use as a context manager. ``file`` gives checked reads
    (:class:`Group`, :class:`Dataset`): a damaged file is an InputError, never a number."""

    def __init__(self, path: str | Path):
        self.path = str(path)
        try:
            self.h5 = h5py.File(self.path, "r")
        except (OSError, ValueError) as exc:
            from parsolve.io.recover import being_written, lock_path

            if being_written(self.path):   # (HDF5's own words would say to h5clear it)
                raise InputError(f"a run is writing it now (lock held on {lock_path(self.path)}, "
                                 "the file open for writing): post reads it once the run has "
                                 "ended; meanwhile h5py.File(path, 'r', swmr=True) follows it",
                                 self.path) from None
            raise InputError(f"cannot open result file ({_reason(exc)})", self.path) from None
        f = self.file = Group(self.h5, self.path)
        try:
            if "mesh/points" not in f or "mesh/cells" not in f or "steps/time" not in f:
                raise InputError("not a parsolve result file (no /mesh or /steps)", self.path)
            self.points = f["mesh/points"][()]
            self.dim = self.points.shape[1]
            (self.cell_type, cells), = f["mesh/cells"].items()
            self.cells = cells[()]
            self.times = f["steps/time"][()]
        except BaseException:
            self.close()
            raise

    def verify(self) -> None:
        """Read every dataset (a step at a time): an InputError at the first damaged one."""
        def visit(group: Group) -> None:
            for name in group:
                obj = group[name]
                if isinstance(obj, Group):
                    visit(obj)
                elif obj.shape and obj.h5.chunks:
                    for start in range(0, obj.shape[0], obj.h5.chunks[0]):
                        obj[start:start + obj.h5.chunks[0]]
                else:
                    obj[()]
        visit(self.file)

    def __enter__(self) -> "Result":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self.h5.close()

    @property
    def stem(self) -> str:
        return Path(self.path).stem

    @property
    def attrs(self) -> dict:
        try:
            return dict(self.h5.attrs)
        except (OSError, RuntimeError) as exc:
            raise InputError(f"damaged attributes ({_reason(exc)})", self.path) from None

    def names(self, group: str) -> list[str]:
        return sorted(self.file[group]) if group in self.file else []

    def dataset(self, path: str, key: str) -> np.ndarray:
        """The dataset at ``path``; a missing one is an InputError naming ``key``."""
        if path not in self.file or not isinstance(self.file[path], Dataset):
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
