#!/usr/bin/env bash
# shellcheck shell=bash
# .ci/lane.sh -- library sourced by .ci/test.sh, .ci/demo.sh and .ci/run.
#
# A "lane" is one way of getting DOLFINx into a Python environment:
#
#   lane a (default)  Debian 12 packages (python3-dolfinx & co, OpenMPI),
#                     interpreter /usr/bin/python3, venv .venv-a created with
#                     --system-site-packages, launcher OpenMPI's mpirun.
#   lane b            DOLFINx 0.11 from the PyPI wheel dolfinx-solver-real
#                     (needs Python >= 3.12), venv .venv-b without system site
#                     packages, launcher the venv's own MPICH mpiexec.
#
# The two MPI stacks must never be mixed: OpenMPI's mpirun only with lane a,
# the venv's MPICH mpiexec only with lane b.
#
# Public entry point:  lane_setup a|b
#   Ensures the lane (Debian packages for a, venv for both) and sets
#     PY        absolute path of the lane venv's python
#     LAUNCHER  bash array: MPI launcher plus fixed options; append -n N ...
#     PYMPI     bash array: interpreter options for MPI runs ("-m mpi4py")
#   Re-running when nothing is missing only runs a quick import check.
#
# Knobs (environment):
#   LANE_B_PYTHON  interpreter to use for lane b (default: auto-detected)
#   FAKE_NONROOT=1 pretend not to be root (to exercise the sudo message)

# Guard against being sourced twice.
if [[ -n "${_CI_LANE_SH:-}" ]]; then return 0; fi
_CI_LANE_SH=1

CI_DIR="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO_ROOT="$(cd "$CI_DIR/.." && pwd)"

# Debian packages lane a needs. openmpi-bin (mpirun.openmpi) is already pulled
# in by python3-mpi4py via mpi-default-bin; it is listed because we call it.
LANE_A_DEBS=(python3-dolfinx python3-petsc4py python3-mpi4py python3-scipy
             python3-pytest python3-venv libopenblas0 openmpi-bin python3-matplotlib
             python3-tqdm python3-h5py python3-numba python3-pytest-xdist python3-sphinx
             python3-myst-parser)
# Lane a must use Debian's interpreter: the python3 first on PATH may be a
# pyenv one that cannot see the Debian DOLFINx.
LANE_A_PYTHON=/usr/bin/python3
# What pip installs into each venv before `pip install -e .`.
LANE_A_PIP=(ruff)
# h5py < 3.16: 3.16.0 is built against HDF5 2.0 but runs on the HDF5 1.14 the DOLFINx wheel has
# already loaded ("Not a datatype" on import; measured 2026-11-30); 3.15.1 works.
LANE_B_PIP=(dolfinx-solver-real scipy pytest pytest-xdist ruff matplotlib tqdm "h5py<3.16" numba)

lane_log() { echo "[lane] $*" >&2; }
lane_die() {
    echo "[lane] ERROR: $*" >&2
    exit 1
}

# True when we may run apt-get ourselves. FAKE_NONROOT=1 forces "no".
_lane_is_root() { [[ "${FAKE_NONROOT:-0}" != 1 && "$(id -u)" -eq 0 ]]; }

# ---------------------------------------------------------------------------
# (a) Debian packages for lane a
# ---------------------------------------------------------------------------
lane_a_ensure_debs() {
    local pkg missing=()
    for pkg in "${LANE_A_DEBS[@]}"; do
        # dpkg-query prints e.g. "install ok installed"; anything else
        # (unknown, config-files, half-installed) counts as missing.
        if [[ "$(dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null || true)" != "install ok installed" ]]; then
            missing+=("$pkg")
        fi
    done
    if ((${#missing[@]} == 0)); then
        return 0
    fi
    lane_log "lane a: missing Debian packages: ${missing[*]}"
    if _lane_is_root; then
        apt-get update ||
            lane_die "lane a: 'apt-get update' failed"
        DEBIAN_FRONTEND=noninteractive apt-get install -y "${LANE_A_DEBS[@]}" ||
            lane_die "lane a: 'apt-get install -y ${LANE_A_DEBS[*]}' failed"
    else
        echo "[lane] lane a needs Debian packages that are not installed: ${missing[*]}" >&2
        echo "[lane] Install them with:" >&2
        echo "    sudo apt-get update && sudo apt-get install -y ${LANE_A_DEBS[*]}" >&2
        exit 1
    fi
}

# ---------------------------------------------------------------------------
# Lane b interpreter discovery
# ---------------------------------------------------------------------------
# Prints the first interpreter that reports Python >= 3.12 and can create a
# venv (has ensurepip). pyenv shims that are not activated just fail the
# check, which is what we want.
lane_b_find_python() {
    local c resolved
    local candidates=()
    [[ -n "${LANE_B_PYTHON:-}" ]] && candidates+=("$LANE_B_PYTHON")
    candidates+=(python3.12 python3.13 python3.14)
    candidates+=("$HOME"/.pyenv/versions/3.1[2-9]*/bin/python3)
    candidates+=(/root/.pyenv/versions/3.1[2-9]*/bin/python3)
    for c in "${candidates[@]}"; do
        resolved="$(command -v "$c" 2>/dev/null)" || continue
        if "$resolved" -c 'import sys, ensurepip, venv; sys.exit(sys.version_info < (3, 12))' \
            >/dev/null 2>&1; then
            echo "$resolved"
            return 0
        fi
    done
    return 1
}

# ---------------------------------------------------------------------------
# (b) venv creation / refresh
# ---------------------------------------------------------------------------
# Content of the stamp file written after a successful install. If
# pyproject.toml or the package list changes, pip runs again.
_lane_stamp() {
    local lane=$1 pkgs
    if [[ $lane == a ]]; then pkgs="${LANE_A_PIP[*]}"; else pkgs="${LANE_B_PIP[*]}"; fi
    printf 'lane=%s\npip=%s\npyproject=%s\n' "$lane" "$pkgs" \
        "$(sha256sum "$REPO_ROOT/pyproject.toml" | cut -d' ' -f1)"
}

# Import check, run from / so the checkout itself is not on sys.path: it
# proves the editable install in the venv points at *this* checkout.
# (dolfinx_meshfree is only located, not imported: see below.)
# Lane b must import dolfinx_solver before dolfinx/petsc4py/mpi4py.
# Prints the reason and returns non-zero when something is missing.
_lane_check() {
    local lane=$1 venv=$2
    local py="$venv/bin/python"
    local out
    [[ -x "$py" ]] || { echo "no interpreter at $py"; return 1; }
    out="$(cd / && "$py" - "$lane" "$REPO_ROOT" 2>&1 <<'PYEOF'
import os
import sys

lane, root = sys.argv[1], sys.argv[2]
if lane == "b":
    import dolfinx_solver  # noqa: F401  -- must come before dolfinx/mpi4py
import dolfinx  # noqa: F401
import matplotlib  # noqa: F401  -- the demos' PNG plots
import mpi4py  # noqa: F401
import petsc4py  # noqa: F401
import pytest  # noqa: F401
import scipy  # noqa: F401

# Locate (not import) our package: an import error in work-in-progress code
# is for pytest to report, not a reason to reinstall the venv.
import importlib.util

spec = importlib.util.find_spec("dolfinx_meshfree")
if spec is None or spec.origin is None:
    sys.exit("dolfinx_meshfree is not installed")
got = os.path.realpath(spec.origin)
want = os.path.realpath(os.path.join(root, "dolfinx_meshfree", "__init__.py"))
if got != want:
    sys.exit(f"dolfinx_meshfree is installed from {got}, not from this checkout ({want})")
PYEOF
    )" || { echo "$out" | tail -n 3; return 1; }
    "$py" -m ruff --version >/dev/null 2>&1 || { echo "ruff is not installed"; return 1; }
}

# Create or refresh the venv of a lane; a no-op (one import check) when the
# venv is complete and its stamp matches.
lane_ensure_venv() {
    local lane=$1
    local venv="$REPO_ROOT/.venv-$lane"
    local py="$venv/bin/python"
    local why base pkgs=()

    if [[ ! -f "$venv/.ci-stamp" ]]; then
        lane_log "lane $lane: $venv not set up yet (no .ci-stamp)"
    elif [[ "$(cat "$venv/.ci-stamp")" != "$(_lane_stamp "$lane")" ]]; then
        lane_log "lane $lane: pyproject.toml or package list changed since last install"
    elif why="$(_lane_check "$lane" "$venv")"; then
        lane_log "lane $lane: $venv is up to date"
        return 0
    else
        lane_log "lane $lane: venv needs work: $why"
    fi

    if [[ $lane == a ]]; then
        base="$LANE_A_PYTHON"
        pkgs=("${LANE_A_PIP[@]}")
        [[ -x "$base" ]] || lane_die "lane a: $base not found (Debian package python3 missing?)"
    else
        pkgs=("${LANE_B_PIP[@]}")
        base="$(lane_b_find_python)" || lane_die "lane b: no Python >= 3.12 with venv/ensurepip found.
  Looked for: \$LANE_B_PYTHON, python3.12/python3.13/python3.14 on PATH,
  $HOME/.pyenv/versions/3.1[2-9]*/bin/python3 and /root/.pyenv/versions/3.1[2-9]*/bin/python3.
  Install one (e.g. 'pyenv install 3.12') or set LANE_B_PYTHON=/path/to/python3.12."
    fi

    # A venv whose interpreter no longer runs (base python removed), or that
    # was created with the wrong options, is rebuilt from scratch.
    if [[ -d "$venv" ]]; then
        if ! "$py" -c 'import sys' >/dev/null 2>&1; then
            lane_log "lane $lane: $venv is broken, recreating"
            rm -rf "$venv"
        elif [[ $lane == a ]] && ! grep -q '^include-system-site-packages = true' "$venv/pyvenv.cfg"; then
            lane_log "lane a: $venv lacks system site packages, recreating"
            rm -rf "$venv"
        elif [[ $lane == b ]] && ! "$py" -c 'import sys; sys.exit(sys.version_info < (3, 12))'; then
            lane_log "lane b: $venv has Python < 3.12, recreating"
            rm -rf "$venv"
        fi
    fi

    if [[ ! -d "$venv" ]]; then
        lane_log "lane $lane: creating $venv with $base ($("$base" --version 2>&1))"
        if [[ $lane == a ]]; then
            "$base" -m venv --system-site-packages "$venv" ||
                lane_die "lane a: '$base -m venv --system-site-packages $venv' failed (python3-venv installed?)"
        else
            "$base" -m venv "$venv" ||
                lane_die "lane b: '$base -m venv $venv' failed"
        fi
    fi

    rm -f "$venv/.ci-stamp"
    lane_log "lane $lane: pip install ${pkgs[*]}"
    "$py" -m pip install --progress-bar off -q "${pkgs[@]}" ||
        lane_die "lane $lane: 'pip install ${pkgs[*]}' failed (see pip output above)"
    lane_log "lane $lane: pip install -e $REPO_ROOT"
    "$py" -m pip install --progress-bar off -q -e "$REPO_ROOT" ||
        lane_die "lane $lane: 'pip install -e $REPO_ROOT' failed (see pip output above)"

    why="$(_lane_check "$lane" "$venv")" ||
        lane_die "lane $lane: venv $venv was installed but does not work: $why"
    _lane_stamp "$lane" >"$venv/.ci-stamp"
    lane_log "lane $lane: $venv ready"
}

# ---------------------------------------------------------------------------
# (c) PY / LAUNCHER / PYMPI for a lane
# ---------------------------------------------------------------------------
lane_setup() {
    local lane=${1:-a}
    case "$lane" in
        a)
            lane_a_ensure_debs
            lane_ensure_venv a
            PY="$REPO_ROOT/.venv-a/bin/python"
            # OpenMPI. Refuses to run as root unless told; --oversubscribe
            # lets -n exceed the core count.
            LANE_MPIRUN=/usr/bin/mpirun.openmpi
            [[ -x $LANE_MPIRUN ]] || LANE_MPIRUN=/usr/bin/mpirun
            LAUNCHER=("$LANE_MPIRUN" --oversubscribe)
            if [[ "$(id -u)" -eq 0 ]]; then LAUNCHER+=(--allow-run-as-root); fi
            ;;
        b)
            lane_ensure_venv b
            PY="$REPO_ROOT/.venv-b/bin/python"
            # MPICH (hydra) from the PyPI mpich wheel inside the venv.
            LAUNCHER=("$REPO_ROOT/.venv-b/bin/mpiexec")
            [[ -x "${LAUNCHER[0]}" ]] ||
                lane_die "lane b: ${LAUNCHER[0]} missing (mpich wheel not installed?)"
            ;;
        *)
            lane_die "unknown lane '$lane' (expected a or b)"
            ;;
    esac
    # `python -m mpi4py` turns an uncaught exception on one rank into
    # MPI_Abort instead of a hang. It imports mpi4py.MPI first, which is
    # exactly the order dolfinx_solver itself enforces, so it is fine for
    # lane b too.
    # shellcheck disable=SC2034  # used by the scripts that source this file
    PYMPI=(-m mpi4py)
    export OMP_NUM_THREADS=1
    export PY
}
