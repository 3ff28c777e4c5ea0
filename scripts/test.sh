#!/usr/bin/env bash
# The project's test command (README): installs what the tests need on a fresh Debian
# machine — Mesa's lavapipe software Vulkan device, so the GPU tests really run without a
# GPU — then checks formatting and lints and runs every test.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1; then
    echo "== installing mesa-vulkan-drivers (lavapipe) =="
    SUDO=""
    if [ "$(id -u)" != 0 ]; then SUDO=sudo; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq mesa-vulkan-drivers >/dev/null
fi

echo "== cargo fmt --check =="
cargo fmt --check
echo "== cargo clippy =="
cargo clippy --all-targets --quiet -- -D warnings
echo "== cargo test =="
cargo test --all-targets
