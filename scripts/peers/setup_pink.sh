#!/usr/bin/env bash
# Create the pink peer venv used by the IK benchmark (scripts/bench.d/ik.py): pin-pink with the daqp
# QP backend (its fastest here) and the same pinocchio as the project (pin 4.1), so both solvers load
# the very same serialized model. Idempotent: does nothing when the venv already imports pink and daqp.
# Usage: scripts/peers/setup_pink.sh [--help]
set -euo pipefail
if [[ "${1:-}" == "--help" || "${1:-}" == "-h" ]]; then
    sed -n '2,5p' "$0"
    exit 0
fi
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
VENV="$ROOT/.venv-peers/pink"
PINK_VERSION="${PINK_VERSION:-4.4.0}"
DAQP_VERSION="${DAQP_VERSION:-0.11.0}"
PIN_VERSION="${PIN_VERSION:-4.1.0}"
PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null 2>&1 || PY=python3
if [[ -x "$VENV/bin/python" ]] && "$VENV/bin/python" -c "import pink, daqp" >/dev/null 2>&1; then
    echo "pink venv ready: $VENV"
    exit 0
fi
mkdir -p "$ROOT/.venv-peers"
"$PY" -m venv "$VENV"
"$VENV/bin/python" -m pip install --quiet --upgrade pip
"$VENV/bin/python" -m pip install --quiet "pin-pink==$PINK_VERSION" "daqp==$DAQP_VERSION" "pin==$PIN_VERSION"
"$VENV/bin/python" -c "import pink, daqp, pinocchio; print('pink venv ready:', '$VENV', 'pink', pink.__version__, 'pin', pinocchio.__version__)"
