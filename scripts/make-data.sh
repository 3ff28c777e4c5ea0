#!/usr/bin/env bash
# Regenerates the bundled data sets in data/ exactly (fixed seeds) with `bsdfit synth`.
# Every file is SYNTHETIC: a catalogue model with documented parameters, measured on a
# goniometer geometry, with metrology-like noise. data/README.md describes each file.
#   u = sqrt((REL·f)² + ABS² + (δ·∂f/∂θi)² + (δ·∂f/∂θo)²),  value = f + u·N(0,1) (clipped ±3)
# with --noise REL,ABS and --angular-unc δ (degrees).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
B=target/release/bsdfit
D=data
mkdir -p "$D"

# --- BRDF (channels 450, 550, 650 nm) -------------------------------------------------
# Near-white diffuse standard (sintered-PTFE-like): almost Lambertian, slight backscatter
# and a weak broad forward sheen.
"$B" synth --model 'fa(eon)' \
  --params 'base.rho=0.975:0.982:0.986,base.r=0.3,lobe.alpha=0.5,lobe.eta=1.35,lobe.ks=0.3' \
  --geometry inplane10 --noise 0.008,0.0002 --angular-unc 0.1 --seed 101 \
  --material 'White diffuse standard (W98)' --out "$D/white-standard.csv"

# Glossy series W80 & G40 / G10.9 / G3.4: 80 % grey diffuse base under a dielectric
# (η 1.5) coat of decreasing gloss (increasing GGX roughness).
GLOSSY='base.rho=0.79:0.80:0.81,base.r=0.2,lobe.eta=1.5,lobe.ks=1'
"$B" synth --model 'fa(eon)' --params "$GLOSSY,lobe.alpha=0.045" \
  --geometry inplane10 --noise 0.01,0.0002 --angular-unc 0.15 --seed 201 \
  --material 'W80&G40' --out "$D/w80-g40-inplane.csv"
"$B" synth --model 'fa(eon)' --params "$GLOSSY,lobe.alpha=0.045" \
  --geometry specular+offplane --noise 0.01,0.0002 --angular-unc 0.15 --seed 202 \
  --material 'W80&G40' --out "$D/w80-g40-full.csv"
"$B" synth --model 'fa(eon)' --params "$GLOSSY,lobe.alpha=0.12" \
  --geometry inplane10 --noise 0.01,0.0002 --angular-unc 0.15 --seed 203 \
  --material 'W80&G10.9' --out "$D/w80-g10.9.csv"
"$B" synth --model 'fa(eon)' --params "$GLOSSY,lobe.alpha=0.3" \
  --geometry inplane10 --noise 0.01,0.0002 --angular-unc 0.15 --seed 204 \
  --material 'W80&G3.4' --out "$D/w80-g3.4.csv"

# Rough red brick: strongly backscattering rough diffuse (VMF) base, red albedo, with a
# weak, very rough forward sheen.
"$B" synth --model 'fa(vmf)' \
  --params 'base.rho=0.10:0.17:0.40,base.r=0.7,lobe.alpha=0.4,lobe.eta=1.6,lobe.ks=0.25' \
  --geometry inplane10 --noise 0.015,0.0003 --angular-unc 0.2 --seed 301 \
  --material 'SmoothRedBrick' --out "$D/red-brick.csv"

# Dark velvet: very dark rough diffuse base plus a retroreflective lobe; the absolute
# floor dominates its uncertainties (relative uncertainty several %).
"$B" synth --model 'eon+retro' \
  --params 'rho=0.016:0.014:0.015,r=0.9,kr=0.004,alpha_r=0.35' \
  --geometry retro --noise 0.02,0.0004 --angular-unc 0.2 --seed 401 \
  --material 'BlackVelvet' --out "$D/black-velvet.csv"

# --- BTDF (633 nm, normal incidence, paper §2.3.1) --------------------------------------
# C: quasi-Lambertian bulk diffuser, 2 mm (CSIC geometry, 0…80° by 10°).
"$B" synth --model 'btdf(tr)+scale' --params 'alpha=0.9,eta=1.5,scale=0.45' \
  --geometry csic --noise 0.015,0.001 --seed 501 \
  --material 'Diffuser C (quasi-Lambertian, 2 mm)' --out "$D/diffuser-c.csv"
# B: angle-dependent diffuser with long tails, 2 mm (PTB geometry, −20…20° by 5°).
"$B" synth --model 'btdf(gtr)+scale' --params 'alpha=0.15,gamma=1.4,eta=1.5,scale=0.85' \
  --geometry ptb5 --noise 0.015,0.001 --angular-unc 0.05 --seed 502 \
  --material 'Diffuser B (long-tailed, 2 mm)' --out "$D/diffuser-b.csv"
# Co3: polycarbonate plate with scattering centres, 3 mm, Gaussian (CSIC geometry).
"$B" synth --model 'btdf(beckmann)+scale' --params 'alpha=0.8,eta=1.58,scale=0.7' \
  --geometry csic --noise 0.015,0.001 --seed 503 \
  --material 'Co3 (Gaussian, polycarbonate 3 mm)' --out "$D/diffuser-co3.csv"
# A: square-shaped scattering, 1.5 mm: flat-topped generalized Gaussian (p = 3), PTB
# 1° steps on the φ = 0° and 90° planes.
"$B" synth --model 'btdf(gg)+scale' --params 'beta=0.35,p=3,eta=1.5,scale=0.9' \
  --geometry ptb1 --noise 0.015,0.001 --angular-unc 0.05 --seed 504 \
  --material 'Diffuser A (square-shaped, 1.5 mm)' --out "$D/diffuser-a.csv"
# D: elliptical Gaussian, 2 mm: one anisotropic Beckmann surface (+aniso: α_u = 0.15
# along φ = 0°, α_v = 0.35 along φ = 90°), measured on the planes of its axes.
"$B" synth --model 'btdf(beckmann)+scale+aniso' --params 'alpha_u=0.15,alpha_v=0.35,phi0=0,eta=1.5,scale=0.9' \
  --geometry ptb1 --noise 0.015,0.001 --angular-unc 0.05 --seed 505 \
  --material 'Diffuser D (elliptical Gaussian, 2 mm)' --out "$D/diffuser-d.csv"
