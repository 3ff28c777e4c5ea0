"""`bsdfit export --format rgl` checked in a real renderer: Mitsuba 3's `measured` plugin
loads the exported .bsdf file of every BRDF model of the catalogue, and its evaluation at
2,000 random direction pairs agrees with bsdfit's own (median relative error under 2 %
where the BRDF exceeds 1 % of its maximum); a sphere rendered with it is finite and not
black. Skipped, saying why, where Mitsuba cannot be imported (the README's test command
installs it into the test environment when PyPI has a wheel for the machine).
"""

import math
import subprocess
import zlib
from pathlib import Path

import numpy as np
import pytest

import bsdfit
from test_bsdfit import DATA, cli_command

mi = pytest.importorskip("mitsuba", reason="Mitsuba 3 is not installed (pip install mitsuba)")

MEDIAN_BOUND = 0.02
N_DIRECTIONS = 2000


def export(fit, tmp_path, name, *extra):
    src = tmp_path / f"{name}.json"
    fit.to_json(src)
    out = tmp_path / f"{name}.bsdf"
    done = subprocess.run(cli_command() + ["export", str(src), "--format", "rgl", "--out", str(out), *extra],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return out


def random_directions(n, seed):
    """Directions over the hemisphere, uniform in cos θ (no grazing extremes)."""
    rng = np.random.default_rng(seed)
    ti = np.degrees(np.arccos(rng.uniform(0.05, 1.0, n)))
    to = np.degrees(np.arccos(rng.uniform(0.05, 1.0, n)))
    return ti, rng.uniform(0, 360, n), to, rng.uniform(0, 360, n)


def unit(theta, phi):
    t, p = math.radians(theta), math.radians(phi)
    return mi.Vector3f(math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))


def mitsuba_brdf(path, ti, pi, to, po, channel):
    """Mitsuba's f (its eval is f·cos θo) of one RGB channel."""
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    ctx = mi.BSDFContext()
    out = np.empty(len(ti))
    for k in range(len(ti)):
        si = mi.SurfaceInteraction3f()
        si.wi = unit(ti[k], pi[k])
        out[k] = bsdf.eval(ctx, si, unit(to[k], po[k]))[channel] / math.cos(math.radians(to[k]))
    return out


def median_error(ref, got):
    sel = ref > 0.01 * ref.max()
    assert sel.sum() > 100, "too few directions above 1 % of the maximum"
    assert np.all(np.isfinite(got[sel])), "Mitsuba returned a non-finite value"
    return float(np.median(np.abs(got[sel] - ref[sel]) / ref[sel]))


@pytest.fixture(scope="module")
def variant():
    mi.set_variant("scalar_rgb")
    return "scalar_rgb"


@pytest.fixture(scope="module")
def brick():
    return bsdfit.Dataset.read(DATA / "red-brick.csv")


BRDF_SPECS = [m.spec for m in bsdfit.models() if m.kind == "brdf"]


@pytest.mark.parametrize("spec", BRDF_SPECS)
def test_every_brdf_model_renders_as_bsdfit_evaluates_it(spec, brick, variant, tmp_path):
    fit = bsdfit.fit(brick, spec, seed=1, restarts=4, backend="cpu")
    path = export(fit, tmp_path, "model")
    ti, pi, to, po = random_directions(N_DIRECTIONS, seed=zlib.crc32(spec.encode()) % 1000)
    # R is the fit's longest wavelength (red-brick: 650 nm).
    ref, _ = fit.eval(ti, pi, to, po, wavelength_nm=max(fit.channels))
    got = mitsuba_brdf(path, ti, pi, to, po, channel=0)
    err = median_error(ref, got)
    print(f"{spec}: median relative error {err:.2e}")
    assert err < MEDIAN_BOUND, (spec, err)


@pytest.mark.parametrize("spec, fix, peak", [
    ("ggx", {"alpha": 0.03}, "mirror"),
    ("fa(lambert)", {"lobe.alpha": 0.05}, "mirror"),
    # A retroreflective peak sits at m = ωi, mid-table, where the uniform grid of u_m is
    # coarse: ~24 % median error near the peak (docs/export.md). Expected to fail until
    # the export warps the table to the BRDF (an adaptive VNDF).
    pytest.param("lambert+retro", {"alpha_r": 0.08, "kr": 0.5}, "retro",
                 marks=pytest.mark.xfail(strict=True, reason="retro peaks are under-resolved")),
])
def test_sharp_lobes_stay_within_the_bound(spec, fix, peak, brick, variant, tmp_path):
    fit = bsdfit.fit(brick, spec, seed=1, restarts=4, backend="cpu", fix=fix)
    path = export(fit, tmp_path, "sharp")
    ti, pi, to, po = random_directions(N_DIRECTIONS, seed=7)
    # Half the directions near the peak (the mirror or the retro direction ± a few degrees).
    turn = 180 if peak == "mirror" else 0
    to[::2] = np.clip(ti[::2] + np.random.default_rng(3).normal(0, 3, len(ti[::2])), 0, 85)
    po[::2] = (pi[::2] + turn + np.random.default_rng(4).normal(0, 3, len(ti[::2]))) % 360
    ref, _ = fit.eval(ti, pi, to, po, wavelength_nm=max(fit.channels))
    got = mitsuba_brdf(path, ti, pi, to, po, channel=0)
    err = median_error(ref, got)
    print(f"{spec} {fix}: median relative error {err:.2e}")
    assert err < MEDIAN_BOUND, (spec, fix, err)


def test_spectral_variant_carries_the_fit_wavelengths(brick, tmp_path):
    """--spectral writes `spectra` and `wavelengths` (the fit's channels), which Mitsuba's
    spectral variants read; a scalar_spectral eval at a channel's wavelength is the fit."""
    fit = bsdfit.fit(brick, "on", seed=1, restarts=4, backend="cpu")
    path = export(fit, tmp_path, "spectral", "--spectral")
    mi.set_variant("scalar_spectral")
    try:
        bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
        ctx = mi.BSDFContext()
        si = mi.SurfaceInteraction3f()
        si.wi = unit(30.0, 0.0)
        si.wavelengths = mi.Spectrum([450.0, 550.0, 650.0, 650.0])
        value = bsdf.eval(ctx, si, unit(40.0, 0.0))
        ref, _ = fit.eval(30.0, 0.0, 40.0, 0.0, wavelength_nm=np.array([450.0, 550.0, 650.0]))
        got = np.array([value[0], value[1], value[2]]) / math.cos(math.radians(40.0))
        np.testing.assert_allclose(got, ref, rtol=0.02)
    finally:
        mi.set_variant("scalar_rgb")


def test_a_sphere_renders_finite_and_not_black(brick, variant, tmp_path):
    fit = bsdfit.fit(brick, "fa(on)", seed=1, restarts=4, backend="cpu")
    path = export(fit, tmp_path, "sphere")
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {
            "type": "perspective",
            "fov": 30,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": 32, "height": 32},
            "sampler": {"type": "independent", "sample_count": 16},
        },
        "sphere": {"type": "sphere", "bsdf": {"type": "measured", "filename": str(path)}},
        "light": {"type": "point", "position": [2, 2, 4], "intensity": {"type": "rgb", "value": 20.0}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.2}},
    })
    image = np.array(mi.render(scene))
    assert np.all(np.isfinite(image))
    centre = image[12:20, 12:20, :3]
    assert centre.mean() > 0.01, centre.mean()


def write_tensor_file(path, fields):
    """A tensor file by the published layout (what RGL's tools write), from numpy arrays."""
    import struct

    codes = {np.dtype(np.uint8): 1, np.dtype(np.float32): 10}
    arrays = {k: np.ascontiguousarray(v) for k, v in fields.items()}
    header = b"tensor_file\0" + struct.pack("<BBI", 1, 0, len(arrays))
    size = len(header) + sum(2 + len(k) + 2 + 1 + 8 + 8 * v.ndim for k, v in arrays.items())
    offset = (size + 7) // 8 * 8
    body = []
    for k, v in arrays.items():
        header += struct.pack("<H", len(k)) + k.encode() + struct.pack("<HBQ", v.ndim, codes[v.dtype], offset)
        header += struct.pack("<" + "Q" * v.ndim, *v.shape)
        body.append((offset, v.tobytes()))
        offset = (offset + v.nbytes + 7) // 8 * 8
    data = bytearray(header)
    for at, b in body:
        data += b"\0" * (at - len(data)) + b
    Path(path).write_bytes(bytes(data))


def test_bsdfit_reads_a_general_rgl_file_as_mitsuba_evaluates_it(variant, tmp_path):
    """An isotropic material with a non-uniform VNDF warp, jacobian = 1 (values divided by
    the NDF term) and random tables, written here as the RGL tools would: bsdfit's reader gives
    Mitsuba's values at the directions it samples."""
    rng = np.random.default_rng(2)
    n_theta, n = 6, 16

    def smooth(*shape):
        """Positive random values; the rows φ = −π and φ = π (first and last along the
        second-to-last axis) are the same direction, so they hold the same values."""
        t = (1.0 + 0.8 * rng.random(shape)).astype(np.float32)
        t[..., -1, :] = t[..., 0, :]
        return t

    def isotropic(h, w):
        """An NDF or projected-area table of an isotropic material: the same along φ
        (rows), random along θ. (Mitsuba 3.9.1 may turn ωi by 180° about the normal in its
        isotropic path, through a flag it leaves unset: harmless for such tables.)"""
        return np.tile((1.0 + 0.8 * rng.random(w)).astype(np.float32), (h, 1))

    path = tmp_path / "random.bsdf"
    write_tensor_file(path, {
        "description": np.frombuffer(b"random test material", dtype=np.uint8),
        "jacobian": np.array([1], dtype=np.uint8),
        "theta_i": np.linspace(0.0, 1.5, n_theta).astype(np.float32),
        "phi_i": np.array([0.0], dtype=np.float32),
        "ndf": isotropic(n, n),
        "sigma": isotropic(8, 8),
        "vndf": smooth(1, n_theta, n, n),
        "luminance": smooth(1, n_theta, n, n),
        "rgb": smooth(1, n_theta, 3, n, n),
    })
    data = bsdfit.Dataset.read(path, assume_uncertainty=(0.01, 1e-6), sample_geometry="hemi")
    # Not at exactly normal incidence: there Mitsuba 3.9.1's `measured` takes the azimuth
    # of ωi = (0, 0, 1) through a symmetry flag it leaves unset for isotropic files, and
    # the result can turn by 180° from one loaded object to the next.
    red = (data.channel == data.channels.index(650.0)) & (data.theta_i > 0)
    ti, pi, to, po = (getattr(data, c)[red] for c in ("theta_i", "phi_i", "theta_o", "phi_o"))
    assert len(ti) > 250
    got = mitsuba_brdf(path, ti, pi, to, po, channel=0)
    ours = data.value[red]
    rel = np.abs(ours - got) / got
    assert np.all(np.isfinite(got)) and np.all(got > 0)
    # f32 tables and CDFs in Mitsuba, f64 in bsdfit: measured 1e-7 median, 2.5e-4 largest
    # (a direction whose half vector sits on a cell edge of the warp).
    assert np.median(rel) < 1e-5 and np.max(rel) < 2e-3, (np.median(rel), np.max(rel))


def test_round_trip_export_read_refit(brick, tmp_path):
    """Export a fit, read the .bsdf back as data (sampled at a geometry, with an assumed
    uncertainty), refit: the parameters come back within their uncertainties."""
    fit = bsdfit.fit(brick, "fa(lambert)", seed=1, restarts=8, backend="cpu")
    path = export(fit, tmp_path, "round")
    data = bsdfit.Dataset.read(path, assume_uncertainty=(0.01, 1e-5), sample_geometry="hemi+specular")
    assert data.channels == [450.0, 550.0, 650.0]
    again = bsdfit.fit(data, "fa(lambert)", seed=2, restarts=8, backend="cpu")
    assert again.chi2_red < 0.1, again  # the table reproduces the model far below 1 %
    for name, value in fit.params.items():
        np.testing.assert_allclose(again.params[name], value, rtol=0,
                                   atol=4 * np.max(np.atleast_1d(again.std[name])) + 1e-4,
                                   err_msg=name)
