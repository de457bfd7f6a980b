#!/usr/bin/env bash
# Create the placo peer venv used by the walking benchmark (scripts/bench.d/walking.py).
# placo pins its own pinocchio (3.x), so it cannot share the project's .venv (pin 4.x).
# Idempotent: does nothing when the venv already imports placo.
# Usage: scripts/peers/setup_placo.sh [--help]
set -euo pipefail
if [[ "${1:-}" == "--help" || "${1:-}" == "-h" ]]; then
    sed -n '2,5p' "$0"
    exit 0
fi
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
VENV="$ROOT/.venv-peers/placo"
PLACO_VERSION="${PLACO_VERSION:-0.10.2}"
PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null 2>&1 || PY=python3
if [[ -x "$VENV/bin/python" ]] && "$VENV/bin/python" -c "import placo" >/dev/null 2>&1; then
    echo "placo venv ready: $VENV"
    exit 0
fi
mkdir -p "$ROOT/.venv-peers"
"$PY" -m venv "$VENV"
"$VENV/bin/python" -m pip install --quiet --upgrade pip
"$VENV/bin/python" -m pip install --quiet "placo==$PLACO_VERSION"
"$VENV/bin/python" -c "import placo; print('placo venv ready:', '$VENV', 'placo', placo.__file__)"
