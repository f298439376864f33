#!/usr/bin/env bash
# Set up the harness on a fresh machine: system library for open3d, a virtualenv in .venv,
# and the project with pinned versions (constraints.txt). Idempotent: a second run is quick.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON="${PYTHON:-python3}"

# 1. open3d's wheel links against libusb-1.0 (a system library pip cannot provide).
if ! ldconfig -p 2>/dev/null | grep -q "libusb-1.0.so.0"; then
    echo "[setup] libusb-1.0 missing (needed by open3d); installing it with apt-get"
    if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
        apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null
    elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null && command -v apt-get >/dev/null 2>&1; then
        sudo apt-get update -qq >/dev/null && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null
    else
        echo "[setup] ERROR: open3d needs the system library libusb-1.0 and this user cannot install it." >&2
        echo "[setup]        Ask an administrator to run:  apt-get install libusb-1.0-0   (Debian/Ubuntu)" >&2
        echo "[setup]        or: dnf install libusb1 (Fedora/RHEL), brew install libusb (macOS); then rerun this script." >&2
        exit 1
    fi
fi

# 2. Virtualenv with the pinned dependencies and the project (editable, with test extras).
if [ ! -x .venv/bin/python ]; then
    echo "[setup] creating .venv"
    "$PYTHON" -m venv .venv
fi
if ! .venv/bin/python -c "import bench, metrics, methods, open3d, torch, kornia" >/dev/null 2>&1 \
   || [ constraints.txt -nt .venv/.setup-done ] || [ pyproject.toml -nt .venv/.setup-done ]; then
    echo "[setup] installing pinned packages (constraints.txt) and the project"
    .venv/bin/python -m pip install -q --disable-pip-version-check -c constraints.txt -e ".[test]"
    touch .venv/.setup-done
fi
.venv/bin/python -c "import open3d, torch; print(f'[setup] ready: torch {torch.__version__}, open3d {open3d.__version__}')"
