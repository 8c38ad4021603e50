#!/usr/bin/env bash
# Creates .venv (Python >= 3.11) and installs mjx-protamer with the given extras, e.g. "test,audio,bench".
# Sourced by scripts/pretrain.sh and scripts/test.sh; safe to run again (pip skips what is installed).
set -euo pipefail
extras="${1:-}"
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
python="${PYTHON:-python3}"
if ! "$python" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
  echo "mjx-protamer needs Python >= 3.11 (found $("$python" --version 2>&1)); set PYTHON=/path/to/python3.11" >&2
  exit 1
fi
[ -x "$root/.venv/bin/python" ] || "$python" -m venv "$root/.venv"
"$root/.venv/bin/python" -m pip install -q --upgrade pip
spec="$root"
[ -n "$extras" ] && spec="$root[$extras]"
"$root/.venv/bin/python" -m pip install -q -e "$spec"
