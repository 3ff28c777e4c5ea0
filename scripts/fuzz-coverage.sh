#!/usr/bin/env bash
# Line and region coverage of the readers reached by the fuzz corpora (docs/reliability.md).
#
#   scripts/fuzz-coverage.sh [TARGET...]
#
# For each target (default: all seven, v1 alta merl rgl zemax astm any), `cargo fuzz coverage` replays its
# corpus (fuzz/corpus/TARGET, grown by scripts/fuzz.sh, with fuzz/seeds/TARGET and
# fuzz/regressions/TARGET) through a coverage-instrumented build, then llvm-cov prints
# the coverage of the files under src/data/ that the target reads through. Needs
# cargo-fuzz and the llvm-tools rustup component (rustup component add llvm-tools);
# RUSTC_BOOTSTRAP=1 lets stable rustc take cargo-fuzz's -Z flags. Profiles go to
# fuzz/coverage/ (not committed).
set -euo pipefail
cd "$(dirname "$0")/.."

targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(v1 alta merl rgl zemax astm any)
fi
export RUSTC_BOOTSTRAP=1
host=$(rustc -vV | sed -n 's/^host: //p')
llvm="$(rustc --print sysroot)/lib/rustlib/$host/bin"
if [ ! -x "$llvm/llvm-cov" ]; then
    echo "llvm-cov not found: rustup component add llvm-tools" >&2
    exit 2
fi

# The files each target is meant to cover.
files() {
    case "$1" in
        v1) echo "src/data/readers/v1.rs" ;;
        alta) echo "src/data/readers/alta/" ;;
        merl) echo "src/data/readers/merl.rs" ;;
        rgl) echo "src/data/readers/rgl.rs src/data/readers/tensor.rs" ;;
        zemax) echo "src/data/readers/zemax/" ;;
        astm) echo "src/data/readers/astm/" ;;
        any) echo "src/data/readers/mod.rs src/data/readers/text.rs" ;;
    esac
}

rows=()
for t in "${targets[@]}"; do
    dirs=()
    for d in "fuzz/corpus/$t" "fuzz/seeds/$t" "fuzz/regressions/$t"; do
        if [ -d "$d" ]; then
            dirs+=("../$d")
        fi
    done
    echo "== $t: cargo fuzz coverage (${#dirs[@]} corpus folders) =="
    (cd fuzz && nice -n "${FUZZ_NICE:-10}" cargo fuzz coverage "$t" "${dirs[@]}" >/dev/null 2>&1)
    bin="fuzz/target/$host/coverage/$host/release/$t"
    report=$("$llvm/llvm-cov" report "$bin" -instr-profile="fuzz/coverage/$t/coverage.profdata" 2>/dev/null)
    for f in $(files "$t") src/data/builder.rs src/data/channels.rs; do
        # Columns: regions, missed, cover, functions, missed, executed, lines, missed, cover.
        while read -r name regions _ rcover _ _ _ lines lmissed lcover _; do
            rows+=("$(printf '%-5s %-36s lines %5s of %5s (%7s)  regions %7s' \
                "$t" "src/${name#*/src/}" "$((lines - lmissed))" "$lines" "$lcover" "$rcover")")
        done < <(awk -v p="${PWD#/}/$f" 'index($1, p) > 0' <<<"$report")
    done
done
echo
echo "== reader coverage of the fuzz corpora =="
printf '%s\n' "${rows[@]}"
