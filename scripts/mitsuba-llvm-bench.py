#!/usr/bin/env python3
"""Raw BSDF evaluation throughput: Mitsuba 3 (LLVM JIT, `llvm_ad_rgb`) against `bsdfit bench`.

What is measured, on the same machine in one run:

* Mitsuba: `bsdf.eval(ctx, si, wo)` of two BSDFs over N random direction pairs
  (default 2,000,000; si.wi and wo uniform on the upper hemisphere, local frame,
  shading frame = identity / n = (0,0,1)), RGB output:
    - `roughconductor` (ggx, alpha 0.2, eta 1.5, k 0, specular_reflectance 0.5),
      the counterpart of bsdfit's `ggx`;
    - `roughplastic` (ggx, alpha 0.2, int_ior 1.5, diffuse_reflectance 0.5,
      nonlinear false), the counterpart of bsdfit's `fa(lambert)`.
  One warm-up evaluation compiles the kernel; then evaluations are repeated, each
  forced with dr.eval(result) + dr.sync_thread(), until --seconds have passed.
  Rate = reps x N x 3 / seconds. The kernel history is checked to confirm that every
  rep really launches a kernel, and the mean of the result is printed once.
* bsdfit: `bsdfit bench --models 'ggx,fa(lambert)' --data FILE --backend auto`,
  whose evals/s count one model at one (sample, channel) pair, i.e. also channel
  values per second. Its backends: cpu (f64 reference), simd, and gpu where a
  Vulkan adapter exists (llvmpipe counts). bsdfit's figure includes the loss term
  and the reduction per parameter candidate; Mitsuba's is one parameter set, the
  results written to memory; it computes the geometric terms once per direction pair
  for all three channels. Mitsuba's eval includes the cos(theta_o) factor.

Both sides therefore report RGB channel values per second.

Requirements: the venv with mitsuba/drjit/numpy, and a shared libLLVM for Dr.Jit's
LLVM backend: Debian `apt-get install -y libllvm19`. (Dr.Jit accepts LLVM >= 15, but
with libllvm15 Mitsuba's BSDF kernels abort: "LLVM ERROR: Cannot select: fmaximum".)
The library is $DRJIT_LIBLLVM_PATH if set, else the newest found by globbing
/usr/lib/x86_64-linux-gnu/libLLVM*.so* and /usr/lib/llvm-*/lib/libLLVM*.so*.

Run (from the repository root, after `cargo build --release`, with a Python that has
`pip install mitsuba numpy`):
    python3 scripts/mitsuba-llvm-bench.py --seconds 3 [--threads T]
        [--data FILE] [--bin PATH] [--n N] [--json out.json]
"""

import argparse
import glob
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
MIN_LLVM = 15  # Dr.Jit's minimum (opaque pointers)
GOOD_LLVM = 19  # tested with Mitsuba 3.9.1 / Dr.Jit 1.5.0
BSDFS = {
    "roughconductor": ("ggx", {"type": "roughconductor", "distribution": "ggx", "alpha": 0.2,
                               "eta": 1.5, "k": 0.0, "specular_reflectance": 0.5}),
    "roughplastic": ("fa(lambert)", {"type": "roughplastic", "distribution": "ggx", "alpha": 0.2,
                                     "int_ior": 1.5, "diffuse_reflectance": 0.5,
                                     "nonlinear": False}),
}


def llvm_version(path):
    m = re.search(r"llvm-(\d+)/|libLLVM-(\d+)|libLLVM\.so\.(\d+)", path)
    return int(next(g for g in m.groups() if g)) if m else None


def find_libllvm():
    """Path of a libLLVM: $DRJIT_LIBLLVM_PATH, else the newest one (>= 15) installed."""
    path = os.environ.get("DRJIT_LIBLLVM_PATH")
    if not path:
        found = {}
        for pat in ("/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/llvm-*/lib/libLLVM*.so*"):
            for p in sorted(glob.glob(pat)):
                v = llvm_version(p)
                if v is not None and os.path.isfile(p):
                    found.setdefault(v, p)
        ok = [v for v in found if v >= MIN_LLVM]
        if not ok:
            old = f" (found only LLVM {sorted(found)}, too old for Dr.Jit)" if found else ""
            sys.exit(f"no libLLVM >= {MIN_LLVM} found{old}: install one, e.g. "
                     f"`apt-get install -y libllvm{GOOD_LLVM}` (see `apt-cache search libllvm`), "
                     "or set DRJIT_LIBLLVM_PATH to the .so")
        path = found[max(ok)]
    v = llvm_version(path)
    if v is not None and v < GOOD_LLVM:
        print(f"warning: LLVM {v}: with libllvm15, Mitsuba's kernels abort in x86 instruction "
              f"selection ('Cannot select: fmaximum'); install libllvm{GOOD_LLVM} if this fails",
              file=sys.stderr)
    return path


def cpu_info():
    info = {"model_name": "?", "cpus": os.cpu_count()}
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        kv = dict(l.split(":", 1) for l in out.splitlines() if ":" in l)
        kv = {k.strip(): v.strip() for k, v in kv.items()}
        info["model_name"] = kv.get("Model name", "?")
        for key, name in (("CPU(s)", "cpus"), ("Thread(s) per core", "threads_per_core"),
                          ("Core(s) per socket", "cores_per_socket"), ("Socket(s)", "sockets")):
            if key in kv:
                info[name] = int(kv[key])
    except (OSError, subprocess.CalledProcessError, ValueError):
        pass
    return info


def mitsuba_bench(n, seconds, threads, seed=1):
    """Channel values/s of each Mitsuba BSDF in BSDFS (variant llvm_ad_rgb)."""
    import numpy as np
    import drjit as dr
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    if threads:
        dr.set_thread_count(threads)
    rng = np.random.default_rng(seed)

    def hemi():  # uniform on the upper hemisphere, cos(theta) in (1e-3, 1]
        z = rng.uniform(1e-3, 1.0, n)
        phi = rng.uniform(0.0, 2 * np.pi, n)
        r = np.sqrt(1.0 - z * z)
        return mi.Vector3f(mi.Float(r * np.cos(phi)), mi.Float(r * np.sin(phi)), mi.Float(z))

    si = dr.zeros(mi.SurfaceInteraction3f)
    si.n = mi.Normal3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.wi = hemi()
    wo = hemi()
    dr.eval(si.wi, wo)
    dr.sync_thread()
    ctx = mi.BSDFContext()
    rows = []
    for name, (counterpart, desc) in BSDFS.items():
        bsdf = mi.load_dict(desc)

        def run():
            res = bsdf.eval(ctx, si, wo)
            dr.eval(res)
            dr.sync_thread()
            return res

        mean = np.asarray(run()).mean(axis=1)  # warm-up (JIT compile); Color3f -> (3, n)
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history_clear()
        run()
        kernels = [k for k in dr.kernel_history()
                   if k.get("type") == dr.KernelType.JIT and k.get("size") == n]
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        if not kernels:
            sys.exit(f"Mitsuba {name}: no kernel of {n} lanes launched per eval; timing void")
        reps, t0 = 0, time.perf_counter()
        while reps == 0 or time.perf_counter() - t0 < seconds:
            run()
            reps += 1
        secs = time.perf_counter() - t0
        print(f"Mitsuba {name}: {reps} reps x {n} in {secs:.2f} s, {len(kernels)} kernel(s)/rep, "
              f"mean RGB = {np.array2string(mean, precision=4)}")
        if not np.all(np.isfinite(mean)) or not np.any(mean > 0):
            sys.exit(f"Mitsuba {name}: trivial or non-finite result, mean {mean}")
        rows.append({"evaluator": "mitsuba llvm_ad_rgb", "model": name, "counterpart": counterpart,
                     "n": n, "reps": reps, "seconds": secs, "threads": dr.thread_count(),
                     "mean_rgb": [float(v) for v in mean],
                     "channel_values_per_s": reps * n * 3 / secs})
    return rows


def bsdfit_bench(binary, data, seconds):
    """Rows of `bsdfit bench --json` for ggx and fa(lambert) on every backend of auto."""
    with tempfile.TemporaryDirectory() as tmp:
        if data is None:
            data = Path(tmp) / "synth.csv"
            subprocess.run([str(binary), "synth", "--model", "fa(lambert)", "--geometry", "hemi",
                            "--out", str(data)], check=True, capture_output=True)
        out = Path(tmp) / "bench.json"
        cmd = [str(binary), "bench", "--models", "ggx,fa(lambert)", "--data", str(data),
               "--seconds", str(seconds), "--backend", "auto", "--json", str(out)]
        run = subprocess.run(cmd, capture_output=True, text=True)
        if run.returncode != 0:
            sys.exit(f"{' '.join(cmd)} failed:\n{run.stderr}")
        for line in run.stderr.splitlines():
            if line.startswith(("backend:", "skipping")):
                print(f"bsdfit {line}")
        rows = json.loads(out.read_text())
    return rows["rows"] if isinstance(rows, dict) else rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=3.0, help="minimum timing per measurement")
    ap.add_argument("--threads", type=int, default=0, help="Dr.Jit threads (default: all cores)")
    ap.add_argument("--n", type=int, default=2_000_000, help="Mitsuba direction pairs per eval")
    ap.add_argument("--data", type=Path, help="bsdfit data file (default: synth fa(lambert) hemi)")
    ap.add_argument("--bin", type=Path, default=REPO / "target/release/bsdfit", help="bsdfit binary")
    ap.add_argument("--json", type=Path, help="write all figures here")
    a = ap.parse_args()
    if not a.bin.is_file():
        sys.exit(f"no bsdfit binary at {a.bin}: run `cargo build --release` or give --bin")
    os.environ["DRJIT_LIBLLVM_PATH"] = find_libllvm()  # before drjit is imported
    cpu = cpu_info()
    print(f"CPU: {cpu['model_name']}; {cpu['cpus']} logical CPUs"
          f" ({cpu.get('sockets', '?')} socket(s) x {cpu.get('cores_per_socket', '?')} cores"
          f" x {cpu.get('threads_per_core', '?')} threads)")
    print(f"libLLVM: {os.environ['DRJIT_LIBLLVM_PATH']}")
    mits = mitsuba_bench(a.n, a.seconds, a.threads)
    print(f"Dr.Jit threads: {mits[0]['threads']}")
    rows = bsdfit_bench(a.bin, a.data, a.seconds)
    print(f"bsdfit threads (cpu/simd): {next((r['threads'] for r in rows if r['threads']), '?')}; "
          f"data: {rows[0]['data'] if rows else '?'} ({rows[0]['samples'] if rows else '?'} "
          "(sample, channel) values)")

    print(f"\n{'evaluator':<26} {'model':<16} {'channel values/s':>17}")
    for m in mits:
        print(f"{m['evaluator']:<26} {m['model']:<16} {m['channel_values_per_s']:>17.3e}")
    for r in rows:
        print(f"{'bsdfit ' + r['backend']:<26} {r['model']:<16} {r['evals_per_s']:>17.3e}")
    ratios = {}
    for m in mits:
        simd = next((r for r in rows if r["backend"] == "simd" and r["model"] == m["counterpart"]),
                    None)
        if simd:
            key = f"bsdfit-simd {m['counterpart']} / mitsuba {m['model']}"
            ratios[key] = simd["evals_per_s"] / m["channel_values_per_s"]
            print(f"{key}: {ratios[key]:.2f}x")
    if a.json:
        a.json.write_text(json.dumps({"cpu": cpu, "libllvm": os.environ["DRJIT_LIBLLVM_PATH"],
                                      "mitsuba": mits, "bsdfit": rows, "ratios": ratios},
                                     indent=2) + "\n")
        print(f"wrote {a.json}")


if __name__ == "__main__":
    main()
