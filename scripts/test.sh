#!/usr/bin/env bash
# The test suite: installs what it needs, then runs pytest on 1 rank (everything), on 2 and
# 3 ranks (every test that can run in parallel; scenes on the distributed mesh, the default),
# once more on 2 ranks with every scene the tests run on the replicated mesh, and the partition
# and distributed-mesh tests on 4. Fails when any test fails.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
PY=.venv/bin/python
export PYTHONDONTWRITEBYTECODE=1
echo "== pytest, 1 rank"
$PY -m pytest -q tests "$@"
for n in 2 3; do
  echo "== pytest, $n ranks (tests marked serial are skipped)"
  # rank 0 reports; the other ranks run the same tests quietly. A hang is a failure too.
  # A failing test aborts the job (tests/conftest.py); a hang dumps tracebacks, then times out.
  timeout 1200 bash scripts/mpirun.sh -n "$n" bash -c '
    opts="-q --color=no -p no:cacheprovider -o faulthandler_timeout=300"
    if [ "${OMPI_COMM_WORLD_RANK:-0}" = 0 ]; then exec '"$PY"' -m pytest $opts tests "$@";
    else exec '"$PY"' -m pytest $opts tests "$@" > /dev/null; fi' _ "$@"
done
echo "== pytest, 2 ranks, every test's scene on the replicated mesh (PARSOLVE_TEST_MESH)"
PARSOLVE_TEST_MESH=replicated timeout 1200 bash scripts/mpirun.sh -n 2 bash -c '
  opts="-q --color=no -p no:cacheprovider -o faulthandler_timeout=300"
  if [ "${OMPI_COMM_WORLD_RANK:-0}" = 0 ]; then exec '"$PY"' -m pytest $opts tests "$@";
  else exec '"$PY"' -m pytest $opts tests "$@" > /dev/null; fi' _ "$@"
echo "== pytest, 4 ranks (oversubscribed): partition independence, distributed mesh"
# every shipped scene at 4 ranks against 1 rank, on both partitioners and on the parts
FOUR="tests/solvers/test_rank_independence.py tests/mesh/test_distribute.py tests/mesh/test_partition.py tests/mesh/test_empty_parts.py"
timeout 1200 bash scripts/mpirun.sh -n 4 bash -c '
  opts="-q --color=no -p no:cacheprovider -o faulthandler_timeout=300"
  if [ "${OMPI_COMM_WORLD_RANK:-0}" = 0 ]; then exec '"$PY"' -m pytest $opts '"$FOUR"' "$@";
  else exec '"$PY"' -m pytest $opts '"$FOUR"' "$@" > /dev/null; fi' _ "$@"
