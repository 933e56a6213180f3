#!/usr/bin/env bash
# .ci/test.sh [--lane a|b] [--serial|--parallel] [--full] [extra pytest args...]
#
# Runs the test suite in one lane (see .ci/lane.sh): first serially (on every core through
# pytest-xdist), then as one MPI job of 2 ranks under the lane's own launcher. Default: lane a,
# both runs, the default tier. --full adds the slow tier (tests marked slow, the whole
# robustness matrix) and runs everything in either lane. On 2 ranks the tests marked serial
# and heavy are left out and a parametrised test runs a covering subset of its cases
# (tests/conftest.py says why). Lane b's run is reduced (pytest --reduced): its serial run
# takes the tests marked serial only, and both runs leave out the heavy tests and run the
# first case of each parametrised test. Anything not recognised (or
# everything after `--`) is passed to pytest, after the `tests` directory.
#
# Each run prints its time and the tests that took 30 s or more (no run fails on a time).
# Exit status is non-zero if any run fails. pytest's exit code 5 ("no tests
# collected") counts as a failure, like any other non-zero code.
#
# Environment: TEST_TIMEOUT (seconds per pytest run, default 2700) so that a deadlocked MPI
# test cannot eat the whole CI budget; TEST_WORKERS (serial run's xdist workers, default
# "auto" = one per core; 0 runs in one process).
set -euo pipefail

# shellcheck source-path=SCRIPTDIR source=lane.sh
source "$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)/lane.sh"

usage() { sed -n '2,20p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; }

lane=a
serial=1
parallel=1
extra=()
while (($#)); do
    case "$1" in
        --lane) [[ $# -ge 2 ]] || { usage >&2; exit 2; }; lane=$2; shift 2 ;;
        --lane=*) lane=${1#--lane=}; shift ;;
        --serial) serial=1; parallel=0; shift ;;
        --parallel) serial=0; parallel=1; shift ;;
        --full) extra+=(--full); shift ;;
        -h|--help) usage; exit 0 ;;
        --) shift; extra+=("$@"); break ;;
        *) extra+=("$1"); shift ;;
    esac
done

lane_setup "$lane" # sets PY, LAUNCHER, PYMPI; exports OMP_NUM_THREADS=1
cd "$REPO_ROOT"
# per pytest run; a hang is caught, a slow machine is not failed: lane A's serial run took
# 25.5 min on a slow machine of this kind (stop 20), 10 min on a quick one
timeout_s=${TEST_TIMEOUT:-2700}

failed=()
# run_pytest LABEL CMD... : run one pytest invocation under a timeout and
# record a failure (any non-zero exit, including 5 = no tests collected).
run_pytest() {
    local label=$1 rc=0 t0=$SECONDS
    shift
    echo "---- lane $lane, $label: $*"
    timeout --kill-after=30 "$timeout_s" "$@" || rc=$?
    case $rc in
        0) echo "---- lane $lane, $label: OK ($((SECONDS - t0))s)" ;;
        5) echo "---- lane $lane, $label: FAILED: pytest collected no tests (exit 5)" ;;
        124|137) echo "---- lane $lane, $label: FAILED: timed out after ${timeout_s}s" ;;
        *) echo "---- lane $lane, $label: FAILED (exit $rc)" ;;
    esac
    ((rc == 0)) || failed+=("$label")
}

# the default tier's slow tests, printed by every run (pytest's durations report)
report=(--durations=0 --durations-min=30)
workers=${TEST_WORKERS:-auto}
xdist=()
if [[ $workers != 0 ]] && "$PY" -c 'import xdist' >/dev/null 2>&1; then
    xdist=(-n "$workers")
fi
# lane b: the version-specific layer under every test function (tests/conftest.py)
lane_args=() serial_args=()
if [[ $lane == b && " ${extra[*]} " != *" --full "* ]]; then
    lane_args=(--reduced)
    serial_args=(-m serial)
fi
if ((serial)); then
    run_pytest "serial" "$PY" -m pytest -q "${xdist[@]}" "${report[@]}" "${serial_args[@]}" \
        "${lane_args[@]}" tests "${extra[@]}"
fi
if ((parallel)); then
    # --color=no: OpenMPI gives ranks a pty, so pytest would emit ANSI colour
    # codes into the CI log (a later --color in the extra args still wins).
    run_pytest "2 ranks" "${LAUNCHER[@]}" -n 2 "$PY" "${PYMPI[@]}" -m pytest -q --color=no \
        "${report[@]}" "${lane_args[@]}" tests "${extra[@]}"
fi

if ((${#failed[@]})); then
    echo "lane $lane: FAILED runs: ${failed[*]}" >&2
    exit 1
fi
