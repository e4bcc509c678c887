"""PETSc options: defaults in code, then the scene, then the command line; inserted under the
solver's prefix only for the life of a solve (petsctools' way), so that two solvers never see
each other's settings."""

from __future__ import annotations

import math
import re
from contextlib import contextmanager
from typing import Iterator

from petsc4py import PETSc


def parse_cli(args: list[str]) -> dict[str, str]:
    """``-key value`` / ``-flag`` pairs from the command line, leading dash removed."""
    opts: dict[str, str] = {}
    i = 0
    while i < len(args):
        key = args[i]
        if not key.startswith("-") or len(key) < 2:
            raise ValueError(f"expected a PETSc option, got {key!r}")
        value = ""
        if i + 1 < len(args) and not _is_option(args[i + 1]):
            value = args[i + 1]
            i += 1
        opts[key.lstrip("-")] = value
        i += 1
    return opts


def _is_option(word: str) -> bool:
    if not word.startswith("-"):
        return False
    try:
        float(word)  # a negative number is a value
        return False
    except ValueError:
        return True


def merge(*layers: dict[str, str]) -> dict[str, str]:
    """Later layers win."""
    out: dict[str, str] = {}
    for layer in layers:
        out.update(layer)
    return out


# Full names (prefix included, no dash) of the options some PETSc object read while they were
# inserted: what -options_left would not list. Filled by ``inserted``.
_USED: set[str] = set()
# options PETSc itself reads at start-up or at the end (never by a solver object)
GLOBAL_OPTIONS = ("options_left", "options_file", "options_monitor", "options_view",
                  "on_error_abort", "on_error_attach_debugger", "log_view", "log_summary",
                  "log_trace", "memory_view", "malloc_debug", "malloc_dump", "info", "help",
                  "version", "fp_trap", "no_signal_handler", "start_in_debugger", "history")


#: Options PETSc reads under no prefix whatever the solver's: the matrix products of an AMG's
#: set-up (its coarse operators P^T A P carry no options prefix). Inserted as they are named.
UNPREFIXED = ("matptap_via", "matmatmult_via", "mattransposematmult_via", "mat_product_clear")
#: P^T A P algorithms of the distributed product only (PETSc 3.18): one process's product
#: ("scalable", "rap") fails its set-up on them, so a value chosen for many ranks is left out
#: on one (and reported unused) rather than stop the run.
DISTRIBUTED_PTAP = ("allatonce", "allatonce_merged", "nonscalable", "backend")


#: The plain AMG's Galerkin products (the iterative preset without multipliers): each coarse
#: operator's P^T A P intermediates freed once it is computed. GAMG makes its hierarchy anew at
#: every set-up (it does not reuse the products), so they were only held. On several ranks the
#: distributed product's default stores A P, P's local and remote rows and its transposed parts
#: on every level: on the 3D box at 398k DOFs on 2 ranks GAMG's set-up grew the peak by 362 MiB
#: per rank with them kept, 314 freed (the summed peak 1.83x -> 1.68x the 1-rank one; the same
#: hierarchy, iterations and answers; scripts/results/bench_scale_gamg.md). The rest is those
#: intermediates while each product is formed: "-matptap_via allatonce" forms none (81 MiB per
#: rank, the summed peak 1.20x) but took 6x the set-up's CPU time (3.4 -> 20.6 s per rank, 3.3x
#: the whole 1-rank set-up): memory is chosen over time on the command line or in the scene.
AMG_PRODUCTS = {"mat_product_clear": ""}


def product_clear() -> bool | None:
    """``-mat_product_clear`` as PETSc's options hold it now (under no prefix: UNPREFIXED),
    None when absent: the condensed V-cycle's set-up adds it only then, and a tied S reuses
    its product's symbolic part only when it is not true (PETSc aborts on a cleared one)."""
    db = PETSc.Options()
    return db.getBool("mat_product_clear") if db.hasName("mat_product_clear") else None


def _applies(key: str, value: str) -> bool:
    return not (key == "matptap_via" and PETSc.COMM_WORLD.getSize() == 1
                and str(value) in DISTRIBUTED_PTAP)


def _database_key(prefix: str, key: str) -> str:
    if key in UNPREFIXED:
        return key
    return key if key.startswith(prefix) else prefix + key


@contextmanager
def inserted(prefix: str, options: dict[str, str], record: bool = True) -> Iterator[None]:
    """Put ``options`` under ``prefix`` in PETSc's database (those of UNPREFIXED under no
    prefix), and take them out afterwards (noting first, unless ``record`` is false, which of
    them some object used, by their prefixed names)."""
    db = PETSc.Options()
    options = {k: v for k, v in options.items() if _applies(k, v)}
    keys = [_database_key(prefix, k) for k in options]
    saved = {k: db.getString(k) for k in keys if db.hasName(k)}
    for k, v in zip(keys, options.values()):
        db.setValue(k, v)
    try:
        yield
    finally:
        if record:
            _USED.update(prefix + k if k in UNPREFIXED else k for k in keys if _was_used(k))
        for k in keys:
            db.delValue(k)
        for k, v in saved.items():
            db.setValue(k, v)


def unused_options(prefix: str, settings: dict[str, str]) -> list[str]:
    """The options of ``settings`` that no PETSc object read during any ``inserted`` block so
    far, as ``-prefix_key`` (what -options_left reports). Empty when PETSc's query is not
    reachable (then nothing can be said)."""
    if _options_used() is None:
        return []
    out = []
    for key in settings:
        full = key if key.startswith(prefix) else prefix + key
        # a command-line option also sits unprefixed in the global database, where PETSc's
        # own set-up may have read it (-log_view, -options_left)
        if full not in _USED and not _was_used(key) and key not in GLOBAL_OPTIONS:
            out.append(f"-{full}")
    return out


def _options_used():
    """PetscOptionsUsed from the loaded PETSc library (petsc4py 3.18 does not wrap it)."""
    global _USED_FN
    if _USED_FN is False:
        return None
    if _USED_FN is None:
        _USED_FN = False
        try:
            import ctypes

            with open("/proc/self/maps") as f:
                libs = sorted({line.split()[-1] for line in f if "/libpetsc" in line})
            for path in libs:
                fn = getattr(ctypes.CDLL(path), "PetscOptionsUsed", None)
                if fn is not None:
                    fn.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.POINTER(ctypes.c_int)]
                    _USED_FN = fn
                    break
        except OSError:
            pass
    return _USED_FN or None


_USED_FN = None


def _was_used(name: str) -> bool:
    import ctypes

    fn = _options_used()
    if fn is None:
        return True
    flag = ctypes.c_int(0)
    return fn(None, name.encode(), ctypes.byref(flag)) == 0 and bool(flag.value)


# ---------------------------------------------------------------- validation

# PETSc error codes of a rejected option, in words
_REASONS = {86: "unknown type", 63: "not a valid value", 62: "not a valid value",
            92: "not available in this PETSc (missing package)", 56: "not supported here"}


def validate(comm, prefix: str, preset: dict[str, str], scene: dict[str, str],
             cli: dict[str, str], source: str) -> None:
    """Exit-2 errors for PETSc options before anything is solved or written: unknown types,
    bad numbers, missing values. A tiny system (``probe``) is set up with the options layered
    as the run will (preset < scene < command line); when PETSc refuses, the options are added
    one by one to find the culprit, named by its scene key (``solver.petsc.<key>``) or as a
    command-line option."""
    from parsolve.errors import InputError

    items = [(k, v, "scene") for k, v in scene.items()] + [(k, v, "cli") for k, v in cli.items()]

    def error(key: str, value: str, origin: str, what: str) -> InputError:
        given = f" ({value!r})" if value else ""
        if origin == "scene":
            return InputError(f"{what}{given} (PETSc option -{prefix}{key})", source,
                              f"solver.petsc.{key}")
        return InputError(f"{what}{given}", "command line", f"-{key}")

    for key, value, origin in items:  # numbers PETSc may not read in this configuration
        what = _number_problem(key, value)
        if what:
            raise error(key, value, origin, what)
    merged = merge(preset, scene, cli)
    code = probe(comm, prefix, merged)
    if code:
        for i, (key, value, origin) in enumerate(items):
            c = probe(comm, prefix, merge(preset, {k: v for k, v, _ in items[:i + 1]}))
            if c:
                what = "missing value" if value == "" and c in (62, 63, 86) else \
                    _REASONS.get(c, f"rejected (PETSc error {c})")
                raise error(key, value, origin, what)
        raise InputError(f"PETSc rejects the solver options (error {code})", source, "solver.petsc")
    final = {k: o for k, _, o in items}  # the layer each final value comes from
    for key, value in merged.items():
        if value == "" and key in final:
            # an empty option is a flag, a viewer or a missing value: a number or a type
            # given 'true' is refused, a flag or a viewer is not refused that way
            c = probe(comm, prefix, merge(merged, {key: "true"}))
            if c in (62, 63, 86):
                raise error(key, "", final[key], "missing value")


# options that always take a number (PETSc reads some only in some configurations, e.g. no
# tolerance with preonly: check them by name as well; parsolve's own, which the probe's KSP
# never reads: the condensed V-cycle's sweeps and reuse, the augmented form's γ)
_INTEGER = re.compile(r".*(_max_it|_restart|_icntl_\d+|_levels|_lag|_max_levels|_fine_sweeps)$")
_REAL = re.compile(r".*(_rtol|_atol|_divtol|_dtol|_cntl_\d+|_threshold|_shift_amount"
                   r"|_reuse_growth|augmented_gamma)$")


def _number_problem(key: str, value: str) -> str | None:
    kind = int if _INTEGER.fullmatch(key) else float if _REAL.fullmatch(key) else None
    if kind is None:
        return None
    if value == "":
        return "missing value"
    try:
        number = kind(value) if kind is int else float(value)
    except ValueError:
        return f"not a valid {'integer' if kind is int else 'number'}"
    if kind is float and not math.isfinite(number):
        return "must be finite"
    return None


def probe(comm, prefix: str, settings: dict[str, str]) -> int:
    """Set up a KSP with ``settings`` under ``prefix`` on a tiny saddle-like system split into
    fields q and lambda, as the real solver does; 0 or PETSc's error code."""
    n = 4  # rows per rank: 3 of q, 1 of lambda
    A = PETSc.Mat().createAIJ(((n, None), (n, None)), nnz=(3, 1), comm=comm)
    lo, hi = A.getOwnershipRange()
    for i in range(lo, hi):
        A.setValue(i, i, 4.0)
        if i + 1 < hi:
            A.setValue(i, i + 1, -1.0)
            A.setValue(i + 1, i, -1.0)
    A.assemble()
    rows = list(range(lo, hi))
    is_q = PETSc.IS().createGeneral(rows[:3], comm=comm)
    is_l = PETSc.IS().createGeneral(rows[3:], comm=comm)
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    code = 0
    try:
        with inserted(prefix, settings, record=False):
            if settings.get("pc_type") == "fieldsplit":
                pc = ksp.getPC()
                pc.setType("fieldsplit")
                pc.setFieldSplitIS(("q", is_q), ("lambda", is_l))
            ksp.setFromOptions()
            ksp.setUp()
    except PETSc.Error as exc:
        code = exc.ierr
    finally:
        ksp.destroy()
        A.destroy()
        is_q.destroy()
        is_l.destroy()
    return comm.allreduce(code, op=_max())


def _max():
    from mpi4py import MPI

    return MPI.MAX
