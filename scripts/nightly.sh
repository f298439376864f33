#!/usr/bin/env bash
# The nightly regression in one command (what .github/workflows/nightly.yml runs), for anyone without
# GitHub:   bash scripts/nightly.sh [--scale small] [--workers 2] [extra `bench regress` flags]
# Sets up, runs the fast suite and the nightly tests, then `bench regress` on every table that has a
# stored reference at the scale; the report (tables, regress_*.md / .json) goes to results/runs/nightly/.
# Exits non-zero on any failure or regression.
set -euo pipefail
cd "$(dirname "$0")/.."
SCALE=small
WORKERS=2
ARGS=()
while [ $# -gt 0 ]; do
    case "$1" in
        --scale) SCALE="$2"; shift 2 ;;
        --workers) WORKERS="$2"; shift 2 ;;
        *) ARGS+=("$1"); shift ;;
    esac
done
OUT="${NIGHTLY_OUT:-results/runs/nightly}"

bash scripts/setup.sh
.venv/bin/python -m pytest -q
.venv/bin/python -m pytest -q -m nightly
TABLES=$(ls results/reference/"$SCALE"/*.json 2>/dev/null | xargs -r -n1 basename | sed 's/\.json$//' | tr '\n' ' ')
if [ -z "$TABLES" ]; then
    echo "[nightly] no stored references in results/reference/$SCALE/: nothing to compare" >&2
    exit 1
fi
# shellcheck disable=SC2086
.venv/bin/bench regress --table $TABLES --scale "$SCALE" --workers "$WORKERS" --out "$OUT" --quiet "${ARGS[@]}"
.venv/bin/bench report --scale "$SCALE" --out "$OUT" --table $TABLES >/dev/null
echo "[nightly] passed; report: $OUT/$SCALE/"
