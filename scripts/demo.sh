#!/usr/bin/env bash
# Installs what is missing, builds sculpt in release and runs it on the demo scene.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d /tmp/sculpt-xdg.XXXXXX)}"
chmod 700 "$XDG_RUNTIME_DIR"
cargo run --release --locked -p app --bin sculpt -- demo "$@"
