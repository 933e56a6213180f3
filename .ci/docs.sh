#!/usr/bin/env bash
# .ci/docs.sh [extra sphinx-build args...]
#
# Builds the documentation site (docs/, Sphinx + myst-parser) into docs/_build/html with
# warnings as errors, in lane A (see .ci/lane.sh: Debian's DOLFINx, .venv-a; the Debian
# packages python3-sphinx and python3-myst-parser provide Sphinx):
#   1. docs/generate_results.py       re-renders docs/results/*.md from docs/results/data/*.json
#                                     (it runs no demo; `--run` does, by hand)
#   2. sphinx-build -W --keep-going -E -b html docs docs/_build/html [extra args...]
#      (-E: a fresh environment, so that every page is read again and none of its
#      warnings is skipped as "unchanged")
# from the repository root. docs/conf.py writes the demo pages (docs/demos/*.md) from the
# demos' header comments at the start of the build. Exits non-zero on any warning.
set -euo pipefail

# shellcheck source-path=SCRIPTDIR source=lane.sh
source "$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)/lane.sh"

usage() { sed -n '2,13p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; }

extra=()
while (($#)); do
    case "$1" in
        -h|--help) usage; exit 0 ;;
        *) extra+=("$1"); shift ;;
    esac
done

lane_setup a # sets PY (unused: the build is pinned to .venv-a below); exports OMP_NUM_THREADS=1
cd "$REPO_ROOT"
SPHINX_PY="$REPO_ROOT/.venv-a/bin/python"
"$SPHINX_PY" -c 'import sphinx, myst_parser' 2>/dev/null ||
    lane_die "Sphinx or myst-parser is missing in lane A; install the Debian packages:
    sudo apt-get install -y python3-sphinx python3-myst-parser"

set -x
"$SPHINX_PY" docs/generate_results.py
"$SPHINX_PY" -m sphinx -W --keep-going -E -b html docs docs/_build/html "${extra[@]}"
