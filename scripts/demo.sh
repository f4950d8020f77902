#!/usr/bin/env bash
# Installs what is missing, builds sculpt in release and opens its window on the demo scene (the
# thesis's watermelon), solo, with its edits kept in a local store (~/.local/share/sculpt/sessions/demo, or
# --store DIR). With no display at all it says so and pictures the demo scene headless instead.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d /tmp/sculpt-xdg.XXXXXX)}"
chmod 700 "$XDG_RUNTIME_DIR"
if [ -z "${DISPLAY:-}" ] && [ -z "${WAYLAND_DISPLAY:-}" ]; then
  out="$(mktemp -d /tmp/sculpt-demo.XXXXXX)"
  echo "demo: no display (DISPLAY and WAYLAND_DISPLAY are unset), so no window;"
  echo "demo: drawing the demo scene headless with \`sculpt render\` instead"
  cargo run --release --locked -p app --bin sculpt -- render scenes/watermelon.wrl --out "$out"
  echo "demo: the pictures of the demo scene are in $out"
  exit 0
fi
exec cargo run --release --locked -p app --bin sculpt -- demo "$@"
