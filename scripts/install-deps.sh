#!/usr/bin/env bash
# Installs what mfd needs on a fresh Debian/Ubuntu machine, and nothing that
# is already there. Sourced by demo.sh and test.sh; safe to run by hand.
set -euo pipefail

# Debian packages: a C toolchain and pkg-config for -sys crates.
# Later stages add their own (libaravis-dev, xvfb, mesa-vulkan-drivers, ...).
packages=(build-essential pkg-config)
# Fringe display: lavapipe (Vulkan on the CPU), Xvfb and the X client libraries
# winit loads, screenshots for the window test (xwd, ImageMagick's convert).
packages+=(mesa-vulkan-drivers xvfb libxkbcommon-x11-0 libx11-xcb1 libxcursor1 libxi6 libxrandr2
  imagemagick x11-apps)
# Live acquisition: libaravis 0.8 (feature aravis), libclang for v4l's bindgen (feature v4l).
packages+=(libaravis-dev libusb-1.0-0-dev libclang-dev)
# The report and the comparison: HDF5 for .datx (feature datx), h5py/numpy for its test writer, chromium for the browser test.
packages+=(libhdf5-dev python3-h5py python3-numpy chromium)

missing=()
for p in "${packages[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  sudo_cmd=""
  [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
  $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq "${missing[@]}"
fi

if ! command -v cargo >/dev/null 2>&1; then
  [ -f "$HOME/.cargo/env" ] && . "$HOME/.cargo/env"
fi
if ! command -v cargo >/dev/null 2>&1; then
  echo "error: no Rust toolchain (cargo) on PATH. Install one with rustup (https://rustup.rs)," >&2
  echo "       or your distribution's cargo >= 1.85, then run this script again." >&2
  exit 1
fi
for c in rustfmt clippy; do
  if ! cargo "$( [ $c = rustfmt ] && echo fmt || echo clippy )" --version >/dev/null 2>&1; then
    if command -v rustup >/dev/null 2>&1; then rustup component add "$c"; else
      echo "error: cargo $c missing and no rustup to add it" >&2; exit 1; fi
  fi
done
