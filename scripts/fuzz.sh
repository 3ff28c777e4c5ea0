#!/usr/bin/env bash
# Coverage-guided fuzzing of every dataset reader (docs/reliability.md).
#
#   scripts/fuzz.sh SECONDS [TARGET...]
#
# Runs each fuzz target of fuzz/ (default: v1 alta merl rgl zemax astm mueller any) for SECONDS, one after
# the other, single process (no -jobs/-workers), from a fixed libFuzzer -seed, and prints
# per target the inputs executed, the coverage (libFuzzer's cov: edges and ft: features)
# and the crashes. Exits non-zero if any target crashed; the reproducer stays in
# fuzz/artifacts/TARGET/ (replay it with `cargo fuzz run TARGET FILE`; keep it in
# fuzz/regressions/TARGET/ once fixed, where tests/fuzz_readers.rs replays it in CI).
#
# Tool: cargo-fuzz (libFuzzer) on the stable toolchain: RUSTC_BOOTSTRAP=1 lets stable
# rustc take the -Z flags cargo-fuzz passes. Sanitizer: AddressSanitizer by default
# (FUZZ_SANITIZER=none to turn it off); debug assertions and overflow checks on (-a), so
# an integer overflow is a crash too. Other settings: FUZZ_SEED (libFuzzer -seed,
# default 1), FUZZ_NICE (niceness, default 10). Installs cargo-fuzz when it is missing.
#
# The growing corpus is fuzz/corpus/TARGET/ (not committed); the committed seeds are
# fuzz/seeds/TARGET/ (python3 fuzz/make_seeds.py writes them). Logs: fuzz/logs/.
set -uo pipefail
cd "$(dirname "$0")/.."

if [ $# -lt 1 ] || ! [[ "$1" =~ ^[0-9]+$ ]]; then
    echo "usage: scripts/fuzz.sh SECONDS [TARGET...]" >&2
    exit 2
fi
secs=$1
shift
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(v1 alta merl rgl zemax astm mueller any)
fi
seed=${FUZZ_SEED:-1}
sanitizer=${FUZZ_SANITIZER:-address}
nice_level=${FUZZ_NICE:-10}
export RUSTC_BOOTSTRAP=1

# cargo-fuzz is installed when missing (the version the record runs used), as
# scripts/test.sh installs what the tests need.
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "== installing cargo-fuzz 0.13.2 (cargo install --locked) =="
    cargo install --locked --version 0.13.2 cargo-fuzz || {
        echo "cargo-fuzz could not be installed: cargo install cargo-fuzz" >&2
        exit 2
    }
fi

# One build of every target (release, debug assertions, the sanitizer).
build=(-O -a -s "$sanitizer")
nice -n "$nice_level" cargo fuzz build "${build[@]}" || exit 2

max_len() {
    case "$1" in
        rgl | any) echo 16384 ;;
        *) echo 8192 ;;
    esac
}

mkdir -p fuzz/logs
summary=()
total=0
crashed=0
for t in "${targets[@]}"; do
    mkdir -p "fuzz/corpus/$t" "fuzz/artifacts/$t"
    dirs=("fuzz/corpus/$t" "fuzz/seeds/$t")
    if [ -d "fuzz/regressions/$t" ]; then
        dirs+=("fuzz/regressions/$t")
    fi
    before=$(find "fuzz/artifacts/$t" -type f | wc -l)
    log="fuzz/logs/$t.log"
    echo "== $t: ${secs}s, -seed=$seed, corpus ${dirs[*]} =="
    nice -n "$nice_level" cargo fuzz run "${build[@]}" "$t" "${dirs[@]}" -- \
        -seed="$seed" -max_total_time="$secs" -max_len="$(max_len "$t")" \
        -timeout=20 -rss_limit_mb=4096 -print_final_stats=1 >"$log" 2>&1
    rc=$?
    after=$(find "fuzz/artifacts/$t" -type f | wc -l)
    runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
    # The last status line: "#N DONE cov: E ft: F corp: U/S ...", or the last "#N ..." one.
    status=$(grep -E '^#[0-9]+[[:space:]]' "$log" | tail -1)
    cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$status")
    ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$status")
    corp=$(sed -n 's/.* corp: \([0-9]*\/[0-9]*[a-zA-Z]*\).*/\1/p' <<<"$status")
    crashes=$((after - before))
    if [ "$rc" -ne 0 ] && [ "$crashes" -eq 0 ]; then
        crashes="? (exit $rc)"
    fi
    if [ "$rc" -ne 0 ] || [ "$after" -gt "$before" ]; then
        crashed=1
        grep -E 'panicked at|ERROR: |SUMMARY: |Test unit written' "$log" | head -5
    fi
    total=$((total + ${runs:-0}))
    summary+=("$(printf '%-5s inputs %10s  exec/s %6s  cov %5s  ft %6s  corpus %-12s crashes %s' \
        "$t" "${runs:-?}" "${rate:-?}" "${cov:-?}" "${ft:-?}" "${corp:-?}" "$crashes")")
done

echo
echo "== fuzz summary (${secs}s per target, -seed=$seed, sanitizer $sanitizer) =="
printf '%s\n' "${summary[@]}"
echo "total inputs: $total"
if [ "$crashed" -ne 0 ]; then
    echo "CRASHES: reproducers in fuzz/artifacts/ (logs in fuzz/logs/)"
    exit 1
fi
