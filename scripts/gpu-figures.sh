#!/usr/bin/env bash
# The figures of docs/performance.md on this machine's GPU (or lavapipe), in one command:
# the adapter, `bsdfit bench --scale` (throughput and peak memory from 1e3 to 1e7
# samples, CPU and GPU in one run), and the dense fit — a full MERL-resolution table of
# fa(eon) with 2 % noise, 16 restarts — on both backends (wall time, peak resident
# memory, loss, and whether the two reach the same optimum). Prints the report and
# writes it as markdown.
#
#   bash scripts/gpu-figures.sh [REPORT.md]          (default: gpu-figures.md)
#
# Needs a Vulkan driver (NVIDIA's, or Mesa's lavapipe) and either a Rust toolchain or a
# prebuilt binary: BSDFIT=path/to/bsdfit bash scripts/gpu-figures.sh. SCALE_SIZES
# overrides the sizes of bench --scale (e.g. SCALE_SIZES=1e3,1e4,1e5 for a quick run).
set -euo pipefail
cd "$(dirname "$0")/.."
REPORT=${1:-gpu-figures.md}
if [ -z "${BSDFIT:-}" ]; then
    cargo build --release --quiet
    BSDFIT=target/release/bsdfit
fi
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

# Wall seconds and peak resident memory (MiB) of a command: GNU time where there is one,
# else Python's rusage of its children.
measure() {
    local out=$1
    shift
    if [ -x /usr/bin/time ]; then
        /usr/bin/time -o "$out" -f "%e %M" "$@"
        awk '{ printf "%s %.0f\n", $1, $2 / 1024 }' "$out" >"$out.tmp" && mv "$out.tmp" "$out"
    else
        python3 - "$out" "$@" <<'EOF'
import resource, subprocess, sys, time
t = time.time()
code = subprocess.run(sys.argv[2:]).returncode
rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
open(sys.argv[1], "w").write(f"{time.time() - t:.2f} {rss:.0f}\n")
sys.exit(code)
EOF
    fi
}

echo "== the machine"
CPU=$(lscpu 2>/dev/null | sed -n 's/^Model name: *//p' | head -1)
CORES=$(nproc)
GPU=$(nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>/dev/null || echo "no nvidia-smi")
echo "CPU: $CPU ($CORES cores); nvidia-smi: $GPU"

echo "== dense data: a full MERL-resolution table of fa(eon), 2 % noise"
"$BSDFIT" synth --model 'fa(eon)' \
    --params 'base.rho=0.3:0.4:0.5,base.r=0.3,lobe.alpha=0.15,lobe.eta=1.5,lobe.ks=0.4' \
    --geometry merl --noise 0.02,0.0001 --out "$WORK/dense.binary"

for backend in cpu gpu; do
    echo "== the dense fit, 16 restarts, --backend $backend"
    measure "$WORK/time-$backend" "$BSDFIT" fit "$WORK/dense.binary" --model 'fa(eon)' \
        --assume-uncertainty 0.02,0.0001 --max-samples 0 --backend "$backend" \
        --json "$WORK/fit-$backend.json" 2> >(tee "$WORK/log-$backend" >&2)
done
ADAPTER=$(sed -n 's/^using gpu (\(.*\))$/\1/p' "$WORK/log-gpu" | head -1)

echo "== bench --scale"
"$BSDFIT" bench --scale ${SCALE_SIZES:+--scale-sizes "$SCALE_SIZES"} \
    --json "$WORK/scale.json" | tee "$WORK/scale.txt"

python3 - "$WORK" "$REPORT" "$CPU" "$CORES" "$GPU" "$ADAPTER" <<'EOF'
import json, sys
work, report, cpu, cores, gpu, adapter = sys.argv[1:7]
fits = {b: json.load(open(f"{work}/fit-{b}.json")) for b in ("cpu", "gpu")}
times = {b: open(f"{work}/time-{b}").read().split() for b in ("cpu", "gpu")}
loss = {b: fits[b]["best"]["loss"] for b in fits}
rel = abs(loss["gpu"] - loss["cpu"]) / abs(loss["cpu"])
ratio = float(times["cpu"][0]) / float(times["gpu"][0])
lines = [
    "# bsdfit figures",
    "",
    f"- CPU: {cpu} ({cores} cores); nvidia-smi: {gpu}",
    f"- GPU engine on: {adapter}",
    "",
    "## The dense fit",
    "",
    "`bsdfit fit dense.binary --model 'fa(eon)' --assume-uncertainty 0.02,0.0001 --max-samples 0`,",
    f"16 restarts, {fits['cpu']['samples']} samples (a full MERL-resolution table of fa(eon), 2 % noise):",
    "",
    "| backend | wall s | peak MiB | loss (χ²) | χ²_red | evaluations |",
    "|---|---|---|---|---|---|",
]
for b in ("cpu", "gpu"):
    f = fits[b]
    lines.append(
        f"| {b} | {times[b][0]} | {times[b][1]} | {loss[b]:.9e} | {f['best']['chi2_red']:.4f} | {f['evaluations']} |"
    )
lines += [
    "",
    f"CPU time / GPU time: **{ratio:.2f}×**; losses differ by {rel:.1e} relative.",
    "",
    "## bench --scale",
    "",
    "```",
    open(f"{work}/scale.txt").read().rstrip(),
    "```",
    "",
]
text = "\n".join(lines)
open(report, "w").write(text)
print(text)
print(f"wrote {report}")
EOF
