#!/usr/bin/env bash
# The test suite on a fresh machine: Debian's espeak-ng/sox (synthesised test speech) and PortAudio
# when we may install them, then .venv with the test, audio and bench extras, then pytest.
# Extra arguments go to pytest (e.g. `-m slow` for the long runs).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
  if ! command -v espeak-ng >/dev/null 2>&1 || ! command -v sox >/dev/null 2>&1 \
     || ! ldconfig -p | grep -q libportaudio; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq espeak-ng sox libportaudio2 >/dev/null
  fi
else
  echo "note: not root or no apt-get: tests that need espeak-ng/sox skip unless they are installed" >&2
fi
bash "$root/scripts/setup_venv.sh" "test,audio,bench"
cd "$root"
exec "$root/.venv/bin/python" -m pytest "$@"
