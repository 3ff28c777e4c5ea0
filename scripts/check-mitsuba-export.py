#!/usr/bin/env python3
"""Check `bsdfit export --format mitsuba` against bsdfit's own evaluation, in Mitsuba 3.

For every model with an exact Mitsuba counterpart (docs/export.md) and a few parameter
sets, this script synthesizes data with `bsdfit synth`, fits it (`bsdfit fit --backend cpu
--json`), exports the fit (`bsdfit export --format mitsuba`), evaluates the fit at many
direction pairs with `bsdfit eval --at` (the f64 CPU reference), loads the XML with
`mi.load_string` in the `scalar_rgb` variant and evaluates `bsdf.eval` at the same
directions. Mitsuba's `eval` returns f·cos θo (the foreshortening of the outgoing
direction), so its values are divided by cos θo before the comparison.

Prints the largest relative error per case and overall; exits 1 when it exceeds --bound,
2 when Mitsuba cannot be imported. The default bound, 1e-4, is float32 arithmetic: Mitsuba's
scalar_rgb variant rounds directions and parameters to float32 (unit roundoff 6e-8), which
a sharp lobe amplifies by its slope (at α = 0.03 near grazing, ~1e-5 measured); a formula
that differs (another Fresnel term, masking, or a missing cosine) is off by 1e-2 or more.

Usage: python3 scripts/check-mitsuba-export.py [--bsdfit PATH] [--bound REL] [--keep DIR]
"""

import argparse
import math
import os
import random
import subprocess
import sys
import tempfile

# (name, synth model, synth params, wavelengths, geometry)
CASES = [
    ("lambert, 1 channel", "lambert", "rho=0.42", "550", "hemi"),
    ("lambert, 3 channels", "lambert", "rho=0.2:0.5:0.8", "450,550,650", "hemi"),
    ("ggx, 3 channels", "ggx", "ks=0.3:0.5:0.7,alpha=0.15,eta=1.6", "450,550,650",
     "specular+offplane"),
    ("ggx, sharp (alpha 0.03)", "ggx", "ks=0.8,alpha=0.03,eta=1.45", "550", "specular+offplane"),
    ("ggx, rough, high index", "ggx", "ks=0.6,alpha=0.5,eta=2.8", "550", "hemi+specular"),
]


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{r.stdout}\n{r.stderr}")
    return r


def find_bsdfit(given):
    if given:
        return given
    if os.environ.get("BSDFIT"):
        return os.environ["BSDFIT"]
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    target = os.environ.get("CARGO_TARGET_DIR", os.path.join(root, "target"))
    for profile in ("release", "debug"):
        p = os.path.join(target, profile, "bsdfit")
        if os.path.exists(p):
            return p
    sys.exit("no bsdfit binary: build it (cargo build --release) or pass --bsdfit PATH")


def direction(theta_deg, phi_deg):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return (math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))


def directions(n, seed):
    """(θi, θo, φo) in degrees, φi = 0: half uniform over the two hemispheres (cosθ from
    0.02 to 1), half within 10° of the mirror direction, where the GGX lobes peak."""
    rng = random.Random(seed)
    out = []
    for k in range(n):
        ti = math.degrees(math.acos(rng.uniform(0.02, 1.0)))
        if k % 2 == 0:
            to = math.degrees(math.acos(rng.uniform(0.02, 1.0)))
            po = rng.uniform(0.0, 360.0)
        else:
            to = min(max(ti + rng.uniform(-10.0, 10.0), 0.5), 88.0)
            po = 180.0 + rng.uniform(-10.0, 10.0)
        out.append((ti, to, po))
    return out


def read_v1(path):
    rows = []
    header = None
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            if header is None:
                header = line.split(",")
                continue
            rows.append(dict(zip(header, map(float, line.split(",")))))
    return rows


def check_case(bsdfit, work, mi, case, n_dirs, seed):
    name, model, params, wls, geometry = case
    tag = name.replace(" ", "_").replace(",", "").replace("(", "").replace(")", "")
    data = os.path.join(work, f"{tag}.csv")
    fit = os.path.join(work, f"{tag}.json")
    xml = os.path.join(work, f"{tag}.xml")
    at = os.path.join(work, f"{tag}-at.csv")
    pred = os.path.join(work, f"{tag}-eval.csv")
    run([bsdfit, "synth", "--model", model, "--params", params, "--wavelengths", wls,
         "--geometry", geometry, "--seed", "7", "--out", data])
    run([bsdfit, "fit", data, "--model", model, "--backend", "cpu", "--restarts", "4",
         "--json", fit])
    run([bsdfit, "export", fit, "--format", "mitsuba", "--out", xml])
    wavelengths = [float(w) for w in wls.split(",")]
    dirs = directions(n_dirs, seed)
    with open(at, "w") as f:
        f.write("# bsdfit dataset v1\n# kind: brdf\n")
        f.write("theta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty\n")
        for ti, to, po in dirs:
            for w in wavelengths:
                f.write(f"{ti!r},0,{to!r},{po!r},{w},1,1\n")
    run([bsdfit, "eval", fit, "--at", at, "--out", pred])
    rows = read_v1(pred)
    assert len(rows) == len(dirs) * len(wavelengths), (len(rows), len(dirs))
    with open(xml) as f:
        bsdf = mi.load_string(f.read())
    ctx = mi.BSDFContext()
    # R, G, B: one channel for all three, else the longest wavelength is R (docs/export.md).
    order = sorted(range(len(wavelengths)), key=lambda c: -wavelengths[c])
    rgb_of = [0, 0, 0] if len(wavelengths) == 1 else order
    worst = (0.0, None)
    for k, (ti, to, po) in enumerate(dirs):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*direction(ti, 0.0))
        wo = direction(to, po)
        value = bsdf.eval(ctx, si, mi.Vector3f(*wo))
        for c in range(3):
            ref = rows[k * len(wavelengths) + rgb_of[c]]["value"]
            got = float(value[c]) / wo[2]
            rel = abs(got - ref) / abs(ref)
            if rel > worst[0]:
                worst = (rel, (ti, to, po, "RGB"[c], ref, got))
    return worst


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bsdfit", help="the bsdfit binary (default: $BSDFIT, else target/{release,debug}/bsdfit)")
    ap.add_argument("--bound", type=float, default=1e-4, help="largest relative error accepted")
    ap.add_argument("--directions", type=int, default=2000, help="direction pairs per case")
    ap.add_argument("--keep", help="write the files here and keep them")
    a = ap.parse_args()
    try:
        import mitsuba as mi
    except ImportError as e:
        print(f"mitsuba is not importable ({e}); pip install mitsuba", file=sys.stderr)
        return 2
    mi.set_variant("scalar_rgb")
    bsdfit = find_bsdfit(a.bsdfit)
    with tempfile.TemporaryDirectory() as tmp:
        work = a.keep or tmp
        os.makedirs(work, exist_ok=True)
        overall = 0.0
        for i, case in enumerate(CASES):
            rel, where = check_case(bsdfit, work, mi, case, a.directions, seed=11 + i)
            overall = max(overall, rel)
            detail = ""
            if where:
                ti, to, po, c, ref, got = where
                detail = (f" (θi = {ti:.2f}°, θo = {to:.2f}°, φo = {po:.2f}°, {c}: "
                          f"bsdfit {ref:.9g}, Mitsuba {got:.9g})")
            print(f"{case[0]:28s} {a.directions} direction pairs × 3: "
                  f"max relative error {rel:.2e}{detail}")
        print(f"mitsuba {mi.__version__} scalar_rgb: max relative error {overall:.2e} "
              f"(bound {a.bound:.0e})")
        if overall > a.bound:
            print("FAILED: over the bound", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
