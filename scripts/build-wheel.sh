#!/usr/bin/env bash
# Builds the Python package as one abi3 wheel (any CPython from 3.9 on) into
# target/wheels/: the native module, the Python API and the `bsdfit` command (which runs
# the command line through the native module). Needs a Rust toolchain and pip; pip fetches
# maturin, the build backend. PYTHON names the interpreter whose pip builds (default
# python3); MATURIN_PEP517_ARGS passes maturin options (the tests build with
# `--profile ci`, the profile of their own build). Usage: scripts/build-wheel.sh
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
rm -f target/wheels/bsdfit-*.whl
"$PY" -m pip wheel --quiet --no-deps ./python -w target/wheels
ls target/wheels/bsdfit-*-abi3-*.whl
