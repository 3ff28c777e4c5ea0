"""Read a bundled measurement, fit two models, compare them, and plot the better fit
against the data in the incidence plane (matplotlib is optional: without it, no plot).

    python python/examples/compare_two_models.py [DATA.csv] [PLOT.png]
"""

import sys

import numpy as np

import bsdfit

path = sys.argv[1] if len(sys.argv) > 1 else "data/red-brick.csv"
data = bsdfit.Dataset.read(path, wavelengths=[550])
print(data)

fits = {model: bsdfit.fit(data, model, seed=1) for model in ("lambert", "on")}
for model, fit in fits.items():
    params = ", ".join(f"{k} = {v:.4g} ± {fit.std[k]:.2g}" for k, v in fit.params.items()
                       if np.ndim(v) == 0)
    print(f"{model:8s} χ²_red = {fit.chi2_red:8.3f}  {params}")
best = min(fits.values(), key=lambda f: f.chi2_red)
print(f"better: {best.model}")

# The better model with its propagated uncertainty, at the measured geometries.
values, uncertainties = best.eval(data.theta_i, data.phi_i, data.theta_o, data.phi_o)
pulls = (data.value - values) / data.uncertainty
print(f"largest |pull| = {np.max(np.abs(pulls)):.2f} at θi = {data.theta_i[np.argmax(np.abs(pulls))]:.0f}°")

try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    sys.exit(0)

out = sys.argv[2] if len(sys.argv) > 2 else "compare.png"
fig, ax = plt.subplots(figsize=(6, 4))
for theta_i in np.unique(data.theta_i)[:4]:
    sel = (data.theta_i == theta_i) & (np.abs(data.phi_o - 180.0) < 1e-6)
    # Signed θo: positive on the light's side (φo = φi = 0, backscatter), negative
    # across the normal (φo = 180°, the specular side).
    signed = data.theta_o[sel]
    fwd = (data.theta_i == theta_i) & (np.abs(data.phi_o) < 1e-6)
    x = np.concatenate([-signed, data.theta_o[fwd]])
    y = np.concatenate([data.value[sel], data.value[fwd]])
    u = np.concatenate([data.uncertainty[sel], data.uncertainty[fwd]])
    order = np.argsort(x)
    line = ax.errorbar(x[order], y[order], yerr=u[order], fmt="o", ms=3, label=f"θi = {theta_i:.0f}°")
    grid = np.linspace(-85, 85, 171)
    v, s = best.eval(theta_i, 0.0, np.abs(grid), np.where(grid < 0, 180.0, 0.0))
    ax.plot(grid, v, color=line[0].get_color())
    ax.fill_between(grid, v - s, v + s, color=line[0].get_color(), alpha=0.2)
ax.set_xlabel("θo in the incidence plane (°; > 0 on the light's side)")
ax.set_ylabel("BRDF (sr⁻¹)")
ax.set_title(f"{data.material}: {best.model}, χ²_red = {best.chi2_red:.2f}")
ax.legend()
fig.tight_layout()
fig.savefig(out, dpi=120)
print(f"wrote {out}")
