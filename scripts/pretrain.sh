#!/usr/bin/env bash
# The main job on a fresh machine: install into .venv, then batched DDPG pretraining on the built-in
# default config (configs/pretrain.yaml). Extra arguments go to `protamer pretrain`.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/setup_venv.sh" ""
cd "$root"
exec "$root/.venv/bin/protamer" pretrain "$@"
