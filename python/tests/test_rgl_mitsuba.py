"""`bsdfit export --format rgl` checked in a real renderer: Mitsuba 3's `measured` plugin
loads the exported .bsdf file of every BRDF model of the catalogue, and its evaluation at
4,000 random direction pairs agrees with bsdfit's own (median relative error under 2 %
where the BRDF exceeds 1 % of its maximum); a sphere rendered with it is finite and not
black; bsdfit reads materials laid out as the RGL database's files as Mitsuba evaluates
them. Skipped, saying why, where Mitsuba cannot be imported, except under CI=true, where
that fails (the README's test command installs Mitsuba into the test environment).
"""

import math
import zlib
from pathlib import Path

import numpy as np
import pytest

import bsdfit
from rgl_helpers import export
from test_bsdfit import DATA

from conftest import in_ci

try:
    import mitsuba as mi
except ImportError:
    # The README's test command installs Mitsuba: under CI (conftest.in_ci, the one rule
    # for every test) its absence is a failure, not a skip that would hide these checks.
    if in_ci():
        raise
    pytest.skip("Mitsuba 3 is not installed (pip install mitsuba)", allow_module_level=True)

MEDIAN_BOUND = 0.02
N_DIRECTIONS = 4000


def random_directions(n, seed):
    """Directions over the hemisphere, uniform in cos θ (no grazing extremes)."""
    rng = np.random.default_rng(seed)
    ti = np.degrees(np.arccos(rng.uniform(0.05, 1.0, n)))
    to = np.degrees(np.arccos(rng.uniform(0.05, 1.0, n)))
    return ti, rng.uniform(0, 360, n), to, rng.uniform(0, 360, n)


def unit(theta, phi):
    t, p = math.radians(theta), math.radians(phi)
    return mi.Vector3f(math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))


def mitsuba_brdf(path, ti, pi, to, po):
    """Mitsuba's f (its eval is f·cos θo) in its three channels (R, G, B in an RGB
    variant), as an array of shape (3, n)."""
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    ctx = mi.BSDFContext()
    out = np.empty((3, len(ti)))
    for k in range(len(ti)):
        si = mi.SurfaceInteraction3f()
        si.wi = unit(ti[k], pi[k])
        value = bsdf.eval(ctx, si, unit(to[k], po[k]))
        out[:, k] = [value[c] / math.cos(math.radians(to[k])) for c in range(3)]
    return out


# R, G, B of an exported RGB file are the fit's longest, middle and shortest wavelengths
# (red-brick: 650, 550, 450 nm).
RGB_NM = (650.0, 550.0, 450.0)


def median_error(ref, got):
    sel = ref > 0.01 * ref.max()
    # At least 50 directions for a meaningful median (the dim B channel of a sharply
    # peaked fit, dmg(ggx) of the brick, has 84 of 4,000 above 1 % of its maximum).
    assert sel.sum() >= 50, "too few directions above 1 % of the maximum"
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
    got = mitsuba_brdf(path, ti, pi, to, po)
    for c, nm in enumerate(RGB_NM):
        ref, _ = fit.eval(ti, pi, to, po, wavelength_nm=nm)
        err = median_error(ref, got[c])
        print(f"{spec} {'RGB'[c]}: median relative error {err:.2e}")
        assert err < MEDIAN_BOUND, (spec, "RGB"[c], err)


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
    got = mitsuba_brdf(path, ti, pi, to, po)
    for c, nm in enumerate(RGB_NM):
        ref, _ = fit.eval(ti, pi, to, po, wavelength_nm=nm)
        err = median_error(ref, got[c])
        print(f"{spec} {fix} {'RGB'[c]}: median relative error {err:.2e}")
        assert err < MEDIAN_BOUND, (spec, fix, "RGB"[c], err)


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
    """A tensor file by the published layout (Mitsuba's `tensor_io` and the RGL tools
    write the same), from numpy arrays, in the order given."""
    import struct

    codes = {np.dtype(t): k + 1 for k, t in enumerate(
        [np.uint8, np.int8, np.uint16, np.int16, np.uint32, np.int32, np.uint64, np.int64,
         np.float16, np.float32, np.float64])}
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


def database_material(path, spectral, seed, anisotropic=False):
    """An isotropic material laid out as the RGL database's files are: the fields in their
    order and element types (text and the `jacobian` flag as uint8, a uint32 `version`,
    float32 tables), a non-uniform VNDF warp, `jacobian` = 1 (values divided by the NDF
    term) and smooth random tables; RGB (`rgb`) or spectral (`spectra` over 360–1000 nm)."""
    rng = np.random.default_rng(seed)
    n_theta, n = 6, 16
    # An anisotropic file: five incidence azimuths over −180…0° (a half-turn symmetry,
    # as the database's anisotropic files have), tables over the half vector's azimuth
    # in the surface's frame, NDF and projected area varying with azimuth too.
    n_phi = 5 if anisotropic else 1

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

    fields = {
        "description": np.frombuffer(b"random test material", dtype=np.uint8),
        "version": np.array([1, 0], dtype=np.uint32),
        "jacobian": np.array([1], dtype=np.uint8),
        "theta_i": np.linspace(0.0, 1.5, n_theta).astype(np.float32),
        "phi_i": (np.linspace(-math.pi, 0.0, n_phi) if anisotropic else np.array([0.0])).astype(np.float32),
        "ndf": smooth(n, n) if anisotropic else isotropic(n, n),
        "sigma": smooth(8, 8) if anisotropic else isotropic(8, 8),
        "vndf": smooth(n_phi, n_theta, n, n),
        "luminance": smooth(n_phi, n_theta, n, n),
    }
    if spectral:
        wavelengths = np.linspace(360.0, 1000.0, 17).astype(np.float32)
        fields["spectra"] = smooth(n_phi, n_theta, len(wavelengths), n, n)
        fields["wavelengths"] = wavelengths
    else:
        fields["rgb"] = smooth(n_phi, n_theta, 3, n, n)
    write_tensor_file(path, fields)


@pytest.mark.parametrize("spectral", [False, True], ids=["rgb", "spectral"])
def test_bsdfit_reads_a_database_layout_file_as_mitsuba_evaluates_it(spectral, variant, tmp_path):
    """bsdfit's reader gives Mitsuba's values, in every channel, at the directions it
    samples a material written here as the database's files are."""
    path = tmp_path / ("spectral.bsdf" if spectral else "rgb.bsdf")
    database_material(path, spectral, seed=2)
    # Incidence azimuths 0…150° besides 0: the relative azimuth is checked, not only u_θ.
    data = bsdfit.Dataset.read(path, assume_uncertainty=(0.01, 1e-6), sample_geometry="hemi+azimuths")
    assert data.channels == [450.0, 550.0, 650.0]
    assert len(set(np.round(data.phi_i).tolist())) == 6
    # Mirror directions left out: their half vector is the normal, whose azimuth is
    # rounding noise, and random tables differ along u_φ at u_θ = 0 (a real material's
    # hold one value there).
    mirror = (np.abs(data.theta_o - data.theta_i) < 1e-6) & (
        np.abs(np.cos(np.radians(data.phi_o - data.phi_i)) + 1.0) < 1e-9)
    if spectral:
        mi.set_variant("scalar_spectral")
    try:
        for c, nm in enumerate(RGB_NM):
            # Not at exactly normal incidence: there Mitsuba 3.9.1's `measured` takes the
            # azimuth of ωi = (0, 0, 1) through a symmetry flag it leaves unset for
            # isotropic files, and the result can turn by 180° from one loaded object to
            # the next.
            sel = (data.channel == data.channels.index(nm)) & (data.theta_i > 0) & ~mirror
            ti, pi, to, po = (getattr(data, k)[sel] for k in ("theta_i", "phi_i", "theta_o", "phi_o"))
            assert len(ti) > 250
            if spectral:
                got = mitsuba_spectral(path, ti, pi, to, po, nm)
            else:
                got = mitsuba_brdf(path, ti, pi, to, po)[c]
            ours = data.value[sel]
            rel = np.abs(ours - got) / got
            assert np.all(np.isfinite(got)) and np.all(got > 0)
            print(f"{path.name} {nm} nm: median {np.median(rel):.1e}, largest {np.max(rel):.1e}")
            # f32 tables and CDFs in Mitsuba, f64 in bsdfit: measured 1.2e-7 median, 1.4e-6
            # largest (the mirror directions left out, as said above).
            assert np.median(rel) < 1e-5 and np.max(rel) < 1e-4, (nm, np.median(rel), np.max(rel))
    finally:
        mi.set_variant("scalar_rgb")


def test_bsdfit_reads_an_anisotropic_database_layout_file_as_mitsuba_evaluates_it(variant, tmp_path):
    """The anisotropic reader against Mitsuba's `measured` on a file laid out as the
    database's anisotropic materials are (five incidence azimuths over −180…0°, random
    tables varying along every axis), at the directions bsdfit samples it: incidence
    azimuths 0…150° (`azimuths`), folded by the half-turn symmetry into the file's range,
    so the incidence interpolation, the fold and the surface-frame azimuth are all
    checked. Directions whose ωi lies on the fold (φi = 0 or 180°, where Mitsuba 3.9's
    fold leaves φi at +π, outside the file's azimuths), normal incidence, and mirror
    directions (whose half vector is the normal, its azimuth rounding noise) are left
    out."""
    path = tmp_path / "aniso_rgb.bsdf"
    database_material(path, spectral=False, seed=5, anisotropic=True)
    data = bsdfit.Dataset.read(path, assume_uncertainty=(0.01, 1e-6), sample_geometry="azimuths")
    assert data.channels == [450.0, 550.0, 650.0]
    on_fold = np.abs(np.sin(np.radians(data.phi_i))) < 1e-3
    mirror = (np.abs(data.theta_o - data.theta_i) < 1e-6) & (
        np.abs(np.cos(np.radians(data.phi_o - data.phi_i)) + 1.0) < 1e-9)
    azimuths = set(np.round(data.phi_i[~on_fold]).tolist())
    assert len(azimuths) >= 4, azimuths
    for c, nm in enumerate(RGB_NM):
        sel = (data.channel == data.channels.index(nm)) & (data.theta_i > 0) & ~on_fold & ~mirror
        ti, pi, to, po = (getattr(data, k)[sel] for k in ("theta_i", "phi_i", "theta_o", "phi_o"))
        assert len(ti) > 500
        got = mitsuba_brdf(path, ti, pi, to, po)[c]
        ours = data.value[sel]
        assert np.all(np.isfinite(got)) and np.all(got > 0)
        rel = np.abs(ours - got) / got
        print(f"anisotropic {nm} nm: median {np.median(rel):.1e}, largest {np.max(rel):.1e}")
        # As the isotropic file: f32 tables in Mitsuba, f64 in bsdfit (measured 1.3e-7
        # median, 1.1e-6 largest).
        assert np.median(rel) < 1e-5 and np.max(rel) < 1e-4, (nm, np.median(rel), np.max(rel))


def mitsuba_spectral(path, ti, pi, to, po, nm):
    """Mitsuba's f at one wavelength, in a spectral variant (all four of its wavelength
    samples set to `nm`)."""
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    ctx = mi.BSDFContext()
    out = np.empty(len(ti))
    for k in range(len(ti)):
        si = mi.SurfaceInteraction3f()
        si.wi = unit(ti[k], pi[k])
        si.wavelengths = mi.Spectrum([nm] * 4)
        out[k] = bsdf.eval(ctx, si, unit(to[k], po[k]))[0] / math.cos(math.radians(to[k]))
    return out


def test_an_anisotropic_fit_renders_as_bsdfit_evaluates_it(variant, tmp_path):
    """A brushed-metal-like fit (`fa(lambert)+aniso`, α_u = 0.15 and α_v = 0.4 along a frame
    turned by 30°) exported as an anisotropic file (incidence azimuths −180…0°, read by
    Mitsuba with its half-turn symmetry), evaluated by Mitsuba's `measured` plugin at
    random directions whose incidence azimuths span the circle."""
    import subprocess

    from test_bsdfit import cli_command

    data = tmp_path / "brushed.csv"
    done = subprocess.run(cli_command() + [
        "synth", "--model", "fa(lambert)+aniso",
        "--params", "lobe.alpha_u=0.15,lobe.alpha_v=0.4,lobe.phi0=30,lobe.eta=1.5,"
                    "lobe.ks=0.6:0.7:0.8,base.rho=0.2:0.35:0.5",
        "--geometry", "specular+hemi", "--noise", "0.02,0.0001", "--seed", "3",
        "--out", str(data)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    fit = bsdfit.fit(bsdfit.Dataset.read(data), "fa(lambert)+aniso", seed=1, restarts=8,
                     backend="cpu")
    path = export(fit, tmp_path, "brushed")
    ti, pi, to, po = random_directions(N_DIRECTIONS, seed=11)
    got = mitsuba_brdf(path, ti, pi, to, po)
    for c, nm in enumerate(RGB_NM):
        ref, _ = fit.eval(ti, pi, to, po, wavelength_nm=nm)
        err = median_error(ref, got[c])
        print(f"fa(lambert)+aniso {'RGB'[c]}: median relative error {err:.2e}")
        assert err < MEDIAN_BOUND, ("RGB"[c], err)
    # The file is anisotropic: the same pair of directions turned by 60° about the normal
    # (off the mirror direction, whose half vector is the normal) changes the value, and
    # Mitsuba follows.
    # (Not at φi = 0 exactly: there Mitsuba 3.9's fold leaves φi = +π, outside the file's
    # azimuths, and it reads the wrong incidence table; 0.001° away it is right.)
    ti, to = np.array([40.0, 40.0]), np.array([30.0, 30.0])
    pi, po = np.array([20.0, 80.0]), np.array([170.0, 230.0])
    ref, _ = fit.eval(ti, pi, to, po, wavelength_nm=RGB_NM[1])
    got = mitsuba_brdf(path, ti, pi, to, po)[1]
    assert abs(ref[0] - ref[1]) > 0.1 * ref.max(), ref
    np.testing.assert_allclose(got, ref, rtol=0.02)
    # Read back by bsdfit itself at incidence azimuths 0…150°: the file's values are the
    # fit's (the same 2 % median bound), and they change with the incidence azimuth.
    back = bsdfit.Dataset.read(path, assume_uncertainty=(0.01, 1e-6), sample_geometry="azimuths")
    assert len(set(np.round(back.phi_i).tolist())) == 6
    for c, nm in enumerate(RGB_NM):
        sel = back.channel == back.channels.index(nm)
        ref, _ = fit.eval(*(getattr(back, k)[sel] for k in ("theta_i", "phi_i", "theta_o", "phi_o")),
                          wavelength_nm=nm)
        err = median_error(ref, back.value[sel])
        print(f"fa(lambert)+aniso read back {'RGB'[c]}: median relative error {err:.2e}")
        assert err < MEDIAN_BOUND, ("RGB"[c], err)
