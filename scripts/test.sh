#!/usr/bin/env bash
# Every test on a fresh machine, in one command (CI runs exactly this, as .ci/run).
# Installs Debian's Chromium for the HTML playback test when it is missing (apt-get, as root or with sudo),
# makes a new virtual environment (packages left on the machine cannot hide a missing step), installs the
# package with its test extras, then runs ruff, the layers contract and pytest. Extra arguments go to pytest,
# e.g. `bash scripts/test.sh -m "not slow"` for the quick suite.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! command -v chromium >/dev/null 2>&1; then
  sudo=""
  if [ "$(id -u)" != 0 ]; then
    command -v sudo >/dev/null 2>&1 || { echo "scripts/test.sh: the playback test needs Debian's chromium; install it as root: apt-get install chromium" >&2; exit 1; }
    sudo="sudo"
  fi
  echo "installing Debian's chromium (apt-get) for the HTML playback test" >&2
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
fi

venv="$(mktemp -d)/venv"
trap 'rm -rf "$(dirname "$venv")"' EXIT
python3 -m venv "$venv"
source "$venv/bin/activate"
python -m pip install --quiet --upgrade pip
python -m pip install --quiet -e ".[test]"
python -m pip list 2>/dev/null | grep -E -i '^(drake|numpy|matplotlib|scipy|pytest|pytest-xdist|playwright|import-linter|ruff) '

ruff format --check .
ruff check .
lint-imports
# Two or more worker processes (pytest-xdist), a test file each at a time: a file's shared fixtures stay in one.
python -m pytest -q -n auto --dist loadfile "$@"
