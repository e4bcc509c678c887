#!/usr/bin/env bash
# Installs Debian's PETSc/MPI stack (if missing) and parsolve into .venv. Idempotent.
# Usage: bash scripts/setup.sh        (Debian 12; root or sudo for apt-get)
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES="python3-petsc4py python3-mpi4py python3-numpy python3-h5py-mpi python3-venv \
python3-pytest python3-yaml python3-matplotlib openmpi-bin libopenblas0-serial mkdocs"
PETSC_DIR_DEB=/usr/lib/petscdir/petsc3.18/x86_64-linux-gnu-real

missing=""
for p in $PACKAGES; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  echo "setup: installing Debian packages:$missing"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing >/dev/null
fi

# Debian's Python, so the venv sees Debian's petsc4py, mpi4py, numpy (<2) and MPI h5py.
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  /usr/bin/python3 -m venv --system-site-packages .venv
fi
site=$(.venv/bin/python -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")
petsc_dir=$(ls -d /usr/lib/petscdir/petsc3.*/x86_64-linux-gnu-real 2>/dev/null | head -n 1)
echo "${petsc_dir:-$PETSC_DIR_DEB}/lib/python3/dist-packages" > "$site/petsc.pth"

# --no-deps: declaring h5py/numpy would pull wheels that shadow Debian's MPI builds.
if ! .venv/bin/python -c "import meshio" 2>/dev/null; then
  .venv/bin/pip install -q --disable-pip-version-check "meshio>=5,<6"
fi
# VTK's XDMF reader (the one ParaView uses) checks the files parsolve writes; --no-deps keeps
# pip from replacing Debian's numpy / matplotlib.
if ! .venv/bin/python -c "import vtk" 2>/dev/null; then
  .venv/bin/pip install -q --disable-pip-version-check --no-deps "vtk>=9.2"
fi
if ! .venv/bin/python -c "import parsolve, sys; sys.exit(0 if parsolve.__file__.startswith('$PWD') else 1)" 2>/dev/null \
   || [ ! -x .venv/bin/parsolve ]; then
  .venv/bin/pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
fi
.venv/bin/python -c "from petsc4py import PETSc; import mpi4py, h5py, meshio, numpy, parsolve; \
print('setup: ok  parsolve', parsolve.__version__, ' PETSc', '.'.join(map(str, PETSc.Sys.getVersion())), ' numpy', numpy.__version__)"
