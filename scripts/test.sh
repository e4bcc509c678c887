#!/usr/bin/env bash
# The test suite: installs what it needs, then runs pytest on 1 rank (everything), on 2 and
# 3 ranks (every test that can run in parallel), the partition, distributed-mesh and
# empty-region tests on 4, builds the docs (strict) and runs every benchmark at its smallest
# size. Fails when any of them fails.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
PY=.venv/bin/python
export PYTHONDONTWRITEBYTECODE=1
echo "== pytest, 1 rank"
$PY -m pytest -q tests "$@"
# rank 0 reports; the other ranks run the same tests quietly. A hang is a failure too.
# A failing test aborts the job (tests/conftest.py); a hang dumps tracebacks, then times out.
parallel() {
  local n=$1; shift
  timeout 2400 bash scripts/mpirun.sh -n "$n" bash -c '
    opts="-q --color=no -p no:cacheprovider -o faulthandler_timeout=300"
    if [ "${OMPI_COMM_WORLD_RANK:-0}" = 0 ]; then exec '"$PY"' -m pytest $opts "$@";
    else exec '"$PY"' -m pytest $opts "$@" > /dev/null; fi' _ "$@"
}
for n in 2 3; do
  echo "== pytest, $n ranks (tests marked serial are skipped)"
  parallel "$n" tests "$@"
done
echo "== pytest, 4 ranks (oversubscribed): partition independence, distributed mesh, empty regions, relation owners, per-rank relation and contact counts, contact on the iterative preset"
# every shipped scene at 4 ranks against 1 rank, on both partitioners; ranks holding none of
# a load's or relation's region
parallel 4 tests/solvers/test_rank_independence.py tests/mesh/test_distribute.py \
  tests/mesh/test_partition.py tests/mesh/test_empty_parts.py tests/effects/test_empty_regions.py \
  tests/mesh/test_slices.py tests/mesh/test_mesh_cli.py tests/la/test_relation_owners.py \
  tests/la/test_relation_set.py tests/la/test_relation_memory.py \
  tests/relation_kinds/test_global_rows.py tests/mesh/test_xdmfmesh.py \
  tests/contact/test_sliding_per_rank.py tests/contact/test_obstacle_rows_per_rank.py \
  tests/effects/test_contact_penalty_per_rank.py tests/relation_kinds/test_strain_per_rank.py \
  tests/effects/test_solubility_distributed.py tests/relation_kinds/test_maximum_per_rank.py \
  "tests/solvers/test_iterative_scenes.py::test_iterative_preset_gives_the_direct_answers[contact_friction_3d]" \
  "tests/solvers/test_iterative_scenes.py::test_iterative_preset_gives_the_direct_answers[contact_block_friction]" \
  "tests/solvers/test_iterative_scenes.py::test_iterative_preset_gives_the_direct_answers[contact_mortar_sphere_3d]" \
  "$@"
echo "== docs: generated pages checked, mkdocs build --strict"
bash scripts/docs.sh
echo "== benchmarks, smoke (every scripts/bench_*.py at its smallest size)"
timeout 900 bash scripts/bench_smoke.sh
