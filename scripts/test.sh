#!/usr/bin/env bash
# The project's test command (README): installs what the tests need on a fresh Debian
# machine — Mesa's lavapipe software Vulkan device, so the GPU tests really run without a
# GPU — then checks formatting and lints and runs every test, then installs the Python
# module from the repository into a fresh virtual environment, as a user would, and runs
# its tests there, and runs a sharded sweep on a real single-node Slurm cluster.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1; then
    echo "== installing mesa-vulkan-drivers (lavapipe) =="
    SUDO=""
    if [ "$(id -u)" != 0 ]; then SUDO=sudo; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq mesa-vulkan-drivers >/dev/null
fi

# Each phase says when it starts (seconds since the script began), so a slow CI run shows
# where its time went.
phase() { echo "== $1 == (${SECONDS} s)"; }

phase "cargo fmt --check"
cargo fmt --check
phase "cargo clippy"
cargo clippy --workspace --all-targets --quiet -- -D warnings
# The tests, the Python wheel and the Slurm test use the `ci` profile (Cargo.toml: release
# code with debug assertions and overflow checks): the tests' fits and diagnoses run
# faster than at the test profile's opt-level 1. `--workspace` resolves the shared crates'
# features with the Python package's, as the wheel's build does (python/Cargo.toml asks
# for the dev-dependencies' few), so the wheel reuses the compiled library: every cargo
# command here that builds keeps `--profile ci --workspace`.
phase "cargo test (profile ci)"
cargo test --profile ci --workspace --all-targets
phase "SIMD parity capped at AVX2 and at the baseline (SSE2); the run above used the widest"
BSDFIT_SIMD=avx2 cargo test --profile ci --workspace --test simd_parity
BSDFIT_SIMD=baseline cargo test --profile ci --workspace --test simd_parity

phase "Python module: its wheel installed into a fresh venv, then pytest"
VENV=target/python-test-venv
rm -rf "$VENV"
if ! python3 -m venv "$VENV" >/dev/null 2>&1; then
    # Debian's python3 ships venv and pip separately.
    SUDO=""
    if [ "$(id -u)" != 0 ]; then SUDO=sudo; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq python3-venv python3-pip >/dev/null
    rm -rf "$VENV"
    python3 -m venv "$VENV"
fi
"$VENV/bin/pip" install --quiet --upgrade pip
# The package as users get it: one abi3 wheel (scripts/build-wheel.sh), installed here and
# again, by test_wheel.py, into a venv with no Rust toolchain on the PATH.
PYTHON="$VENV/bin/python" MATURIN_PEP517_ARGS="--profile ci" bash scripts/build-wheel.sh
"$VENV/bin/pip" install --quiet target/wheels/bsdfit-*-abi3-*.whl pytest mypy matplotlib
# Mitsuba 3 checks the RGL and Mitsuba exports and the RGL reader in a real renderer.
# Under CI a missing Mitsuba is a failure; elsewhere (a machine PyPI has no wheel for)
# those tests are reported as skipped (-rs prints why).
if ! "$VENV/bin/pip" install --quiet mitsuba; then
    if [ "${CI:-}" = true ]; then echo "error: Mitsuba 3 could not be installed" >&2; exit 1; fi
    echo "note: Mitsuba 3 could not be installed; the Mitsuba checks will be skipped"
fi
# The CLI comparisons use the binary `cargo test` just built.
BSDFIT_CLI="$PWD/target/ci/bsdfit" "$VENV/bin/python" -m pytest -q -rs python/tests

phase "export --format mitsuba checked in Mitsuba 3"
BSDFIT_PYTHON="$PWD/$VENV/bin/python" cargo test --profile ci --workspace --test export -- --ignored mitsuba_export

phase "Slurm: a sharded sweep on a single-node cluster"
bash scripts/test-slurm.sh "$PWD/target/ci/bsdfit"
phase "done"
