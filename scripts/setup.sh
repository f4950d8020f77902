#!/usr/bin/env bash
# Installs what sculpt needs on a Debian machine with Rust, only what is missing, with no prompt.
# Safe to run again: when everything is present it does nothing and takes well under a second.
set -euo pipefail

# Software Vulkan (llvmpipe) and GL for headless rendering, the X libraries winit loads at run
# time, Xvfb for window tests, FUSE for the fake HID devices of the haptic tests, and ip and
# nft for the network-namespace tests of NAT traversal.
PACKAGES=(
  mesa-vulkan-drivers libvulkan1 libegl1 libegl-mesa0 libgl1-mesa-dri
  libx11-6 libx11-xcb1 libxcursor1 libxi6 libxrandr2 libxkbcommon-x11-0 xvfb xauth
  python3-fusepy libfuse2 fuse3 iproute2 nftables
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  sudo=()
  if [ "$(id -u)" -ne 0 ]; then sudo=(sudo); fi
  export DEBIAN_FRONTEND=noninteractive
  "${sudo[@]}" apt-get update -qq
  "${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if ! command -v cargo >/dev/null; then
  echo "setup: cargo is missing; install Rust from rustup first" >&2
  exit 1
fi
