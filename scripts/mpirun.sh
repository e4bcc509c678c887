#!/usr/bin/env bash
# mpirun with the settings this kind of machine needs (root, more ranks than cores).
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
export OMPI_MCA_btl_vader_single_copy_mechanism=none
# SIGTERM / SIGINT sent to this script reach every rank at once, as SIGUSR2 / SIGUSR1 (the
# signals mpirun forwards; parsolve reads them as SIGTERM / SIGINT: parsolve/interrupts.py),
# and the script exits with the ranks' status (143 / 130). Signalled itself, Open MPI 4's
# mpirun would send the ranks SIGTERM only a second later, SIGKILL a second after that, and exit 1.
mpirun "$@" &
pid=$!
trap 'kill -USR2 "$pid" 2>/dev/null' TERM
trap 'kill -USR1 "$pid" 2>/dev/null' INT
while :; do
    wait "$pid"
    rc=$?
    kill -0 "$pid" 2>/dev/null || break   # wait returned for a trapped signal: mpirun still runs
done
exit "$rc"
