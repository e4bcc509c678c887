"""Make a result left by a hard kill (SIGKILL, OOM killer, node failure) readable by any reader:
``parsolve post RESULT.h5 --recover``.

Such a file says ``status = running``. In the swmr output mode HDF5's "open for writing"
flags are still set, so a plain ``h5py.File(path, "r")`` refuses it (only ``swmr=True`` opens
it); in either mode a per-step dataset may hold one unfinished row after the last finished
step. Recovering copies everything into a clean file beside it (h5py's ``copy``: attributes,
chunks and growable shapes kept), cuts every per-step dataset to the steps every one of them
holds (``len(/steps/time)``, the commit marker written last, or fewer if a dataset holds
fewer: :func:`whole_steps`), sets ``status`` to "interrupted: killed (recovered)" and renames the
copy over the original (same name: the XDMF beside it keeps pointing at it). The same as
``h5clear -s`` plus the trimming, without needing hdf5-tools; it costs one copy of the file.
"""

from __future__ import annotations

import errno
import fcntl
import os
from pathlib import Path

import h5py

from parsolve.io.hdf5 import COMMIT
from parsolve.io.lock import lock_path

RECOVERED = "interrupted: killed (recovered)"
NO_ROOM = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM)


def killed(path: str | Path) -> bool:
    """True for a result a killed run left: status "running" and no writer holding it. (A
    result being written now is locked, parsolve.io.lock: that one is not "killed".)"""
    try:
        with h5py.File(path, "r", swmr=True) as f:
            if f.attrs.get("status") != "running":
                return False
    except (OSError, ValueError, RuntimeError):
        return False
    return not being_written(path)


def being_written(path: str | Path) -> bool:
    """True while a run holds the lock beside ``path`` (parsolve.io.lock)."""
    try:
        fd = os.open(lock_path(path), os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return False
    except BlockingIOError:
        return True       # a run holds it: still running
    finally:
        os.close(fd)


def hint(path: str | Path) -> str:
    """What ``post`` adds to its message about a file it cannot read."""
    if path is None:
        return ""
    if being_written(path):
        return f"; a run is writing it now (lock held on {lock_path(path)})"
    if not killed(path):
        return ""
    return (f"; the run writing it was killed (status running): `parsolve post {path} --recover` "
            "makes its finished steps readable")


def recover(path: str | Path) -> tuple[int, str]:
    """(finished steps, message). Only a killed run's file is changed; a file HDF5 cannot read
    (truncated, overwritten) or one a run is writing now is an InputError."""
    from parsolve.errors import InputError

    path = Path(path)
    if not path.is_file():
        raise InputError("no such result file", str(path), "--recover")
    if being_written(path):   # (its per-step datasets may hold a step being written)
        raise InputError(f"a run is writing it now (lock held on {lock_path(path)}): --recover "
                         "mends a killed run's file; a live one reads as it is once the run "
                         "has ended", str(path), "--recover")
    try:
        with h5py.File(path, "r", swmr=True):
            pass
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot recover: the file is damaged or truncated ({_reason(exc)})",
                         str(path), "--recover") from None
    if not killed(path):
        return -1, f"{path}: nothing to recover (not a killed run's result)"
    tmp = path.with_name(path.name + ".recover")
    try:
        with h5py.File(path, "r", swmr=True) as src, h5py.File(tmp, "w", libver="latest") as dst:
            n = whole_steps(src)
            for key, value in src.attrs.items():
                dst.attrs[key] = value
            for name in src:
                src.copy(src[name], dst, name=name)
            trimmed = _trim(dst, n)
            dst.attrs["status"] = RECOVERED
        tmp.replace(path)
    except (OSError, RuntimeError, KeyError) as exc:
        if getattr(exc, "errno", None) in NO_ROOM:   # writing the copy, not reading the file
            raise InputError(f"cannot recover: no room for its copy beside it "
                             f"({os.strerror(exc.errno)}); the file is unchanged: recovering "
                             f"takes one copy of it ({path.stat().st_size / 1e6:.3g} MB), make "
                             "room and recover again", str(path), "--recover") from None
        raise InputError(f"cannot recover: the file is damaged ({_reason(exc)})", str(path),
                         "--recover") from None
    finally:
        tmp.unlink(missing_ok=True)
    cut = f", {trimmed} unfinished row(s) cut" if trimmed else ""
    return n, f"{path}: recovered {n} finished step(s){cut}; status \"{RECOVERED}\""


def _reason(exc: Exception) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _per_step(f: h5py.File) -> list[str]:
    """The growable datasets (the per-step ones) by name."""
    names = []

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and obj.maxshape and obj.maxshape[0] is None:
            names.append(name)
    f.visititems(visit)
    return names


def whole_steps(f: h5py.File) -> int:
    """The steps every per-step dataset holds: the commit marker ``/steps/time`` (written last)
    says how many finished, and no dataset may hold fewer (it never does when the writer's
    order held; the minimum keeps the recovered file whole whatever happened)."""
    return min([len(f[COMMIT])] + [f[name].shape[0] for name in _per_step(f)])


def _trim(f: h5py.File, n: int) -> int:
    """Cut every per-step dataset to ``n`` rows; how many were longer."""
    longer = [name for name in _per_step(f) if f[name].shape[0] > n]
    for name in longer:
        f[name].resize(n, axis=0)
    return len(longer)
