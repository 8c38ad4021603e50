#!/usr/bin/env bash
# The test suite on a fresh machine: Debian's espeak-ng/sox (synthesised test speech), PortAudio, Mesa's
# offscreen OpenGL (EGL, OSMesa) and chromium (the live page's browser test) when we may install them,
# then .venv with the test, audio, bench and view extras, then pytest.
# Extra arguments go to pytest (e.g. `-m slow` for the long runs).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
  if ! command -v espeak-ng >/dev/null 2>&1 || ! command -v sox >/dev/null 2>&1 \
     || ! ldconfig -p | grep -q libportaudio || ! ldconfig -p | grep -q libEGL_mesa \
     || ! ldconfig -p | grep -q libOSMesa || ! command -v chromium >/dev/null 2>&1; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq espeak-ng sox libportaudio2 \
      libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6 chromium >/dev/null
  fi
else
  echo "note: not root or no apt-get: tests that need espeak-ng/sox, Mesa GL or chromium skip unless installed" >&2
fi
bash "$root/scripts/setup_venv.sh" "test,audio,bench,view"
cd "$root"
exec "$root/.venv/bin/python" -m pytest "$@"
