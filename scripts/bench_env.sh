#!/usr/bin/env bash
# Install the PEER codes that scripts/bench_peers.py measures parsolve against.
#
#   * DOLFINx 0.5 from Debian (python3-dolfinx-real): same PETSc 3.18 / petsc4py / OpenMPI as parsolve,
#     lands in Debian's system site-packages, so /usr/bin/python3 and /work/main/.venv (which uses
#     --system-site-packages) both see it.
#   * scikit-fem from PyPI, in a SEPARATE venv (default /work/bench-venv, override with BENCH_VENV),
#     created from Debian's /usr/bin/python3 with --system-site-packages and numpy<2 pinned, because
#     Debian's petsc4py is built against numpy 1.x.
#
# Idempotent: each step checks first and says whether it did anything. Not run by CI; benchmarks only.
# Needs root (apt-get). Usage:  bash scripts/bench_env.sh
set -euo pipefail

BENCH_VENV="${BENCH_VENV:-/work/bench-venv}"
PY=/usr/bin/python3
export DEBIAN_FRONTEND=noninteractive

say() { printf '[bench_env] %s\n' "$*"; }

# --- (a) DOLFINx 0.5 (Debian) -------------------------------------------------------------------
if "$PY" -c 'import dolfinx' >/dev/null 2>&1; then
    say "dolfinx already importable by $PY: skipping apt-get"
else
    say "apt-get update"
    apt-get update -qq
    say "apt-get install -y --no-install-recommends python3-dolfinx-real"
    apt-get install -y -qq --no-install-recommends python3-dolfinx-real
fi
say "dolfinx: $("$PY" -c 'import dolfinx; print(dolfinx.__version__, dolfinx.__file__)')"
say "petsc4py: $("$PY" -c 'import petsc4py; print(petsc4py.__version__)')"

# DOLFINx JIT-compiles forms with FFCx + cffi, which needs a C compiler and Python headers.
if ! command -v cc >/dev/null 2>&1; then
    say "no C compiler: apt-get install -y --no-install-recommends gcc libc6-dev"
    apt-get install -y -qq --no-install-recommends gcc libc6-dev
fi
if [ ! -f /usr/include/python3.11/Python.h ]; then
    say "no Python.h: apt-get install -y --no-install-recommends python3-dev"
    apt-get install -y -qq --no-install-recommends python3-dev
fi

# --- (b) scikit-fem venv ------------------------------------------------------------------------
if [ -x "$BENCH_VENV/bin/python" ]; then
    say "venv $BENCH_VENV exists"
else
    say "$PY -m venv --system-site-packages $BENCH_VENV"
    "$PY" -m venv --system-site-packages "$BENCH_VENV"
fi
if "$BENCH_VENV/bin/python" -c 'import skfem, scipy, numpy; assert int(numpy.__version__.split(".")[0]) < 2' >/dev/null 2>&1; then
    say "scikit-fem already installed in $BENCH_VENV: skipping pip"
else
    say "$BENCH_VENV/bin/pip install 'scikit-fem' 'numpy<2'"
    "$BENCH_VENV/bin/pip" install -q 'scikit-fem' 'numpy<2'
fi
say "bench-venv: $("$BENCH_VENV/bin/python" -c 'import skfem, scipy, numpy; print("scikit-fem", skfem.__version__, "scipy", scipy.__version__, "(" + scipy.__file__.rsplit("/", 2)[0] + ")", "numpy", numpy.__version__)')"
say "done. Run e.g.:"
say "  $PY scripts/bench_peers.py dolfinx --n 64 128 --cell triangle quad --json dolfinx.json"
say "  $BENCH_VENV/bin/python scripts/bench_peers.py skfem --n 64 128 --cell triangle quad --json skfem.json"
say "  bash scripts/bench_smoke.sh     # every benchmark at its smallest size, the peers above included"
