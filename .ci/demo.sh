#!/usr/bin/env bash
# .ci/demo.sh [--lane a|b] [--np N] [extra demo args...]
#
# Runs the cantilever demo in one lane (see .ci/lane.sh):
#   demos/cantilever.py --h 3 1.5 1 0.75 0.5 \
#       --json out/cantilever.json [extra demo args...]
# from the repository root, serially, or with --np N > 1 as one MPI job of N
# ranks under the lane's own launcher. Extra args come after the defaults,
# so e.g. `--method sph` or `--h 1 0.5` override them (argparse keeps the
# last occurrence). Everything after `--` is passed through unparsed.
set -euo pipefail

# shellcheck source-path=SCRIPTDIR source=lane.sh
source "$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)/lane.sh"

usage() { sed -n '2,10p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; }

lane=a
np=1
extra=()
while (($#)); do
    case "$1" in
        --lane) [[ $# -ge 2 ]] || { usage >&2; exit 2; }; lane=$2; shift 2 ;;
        --lane=*) lane=${1#--lane=}; shift ;;
        --np) [[ $# -ge 2 ]] || { usage >&2; exit 2; }; np=$2; shift 2 ;;
        --np=*) np=${1#--np=}; shift ;;
        -h|--help) usage; exit 0 ;;
        --) shift; extra+=("$@"); break ;;
        *) extra+=("$1"); shift ;;
    esac
done
[[ $np =~ ^[1-9][0-9]*$ ]] || lane_die "--np needs a positive integer, got '$np'"

lane_setup "$lane" # sets PY, LAUNCHER, PYMPI; exports OMP_NUM_THREADS=1
cd "$REPO_ROOT"
[[ -f demos/cantilever.py ]] || lane_die "demos/cantilever.py does not exist in $REPO_ROOT"
mkdir -p out

args=(demos/cantilever.py --h 3 1.5 1 0.75 0.5
      --json out/cantilever.json "${extra[@]}")
if ((np > 1)); then
    set -x
    "${LAUNCHER[@]}" -n "$np" "$PY" "${PYMPI[@]}" "${args[@]}"
else
    set -x
    "$PY" "${args[@]}"
fi
