#!/usr/bin/env python3
"""Write the fuzz seed corpus (fuzz/seeds/<target>/): small files shaped like real ones.

Reproducible: no randomness, every file from the rules below or cut from the repository's
data/*.csv and tests/fixtures. Run from anywhere: python3 fuzz/make_seeds.py. It empties
and rewrites fuzz/seeds/. Standard library only.

- v1: cuts of data/*.csv (metadata, header, first rows) and hand-shaped variants
  (BTDF with signed angles, CRLF, byte-order mark, columns reordered and quoted, assumed
  uncertainties, zero uncertainties, several planes and wavelengths).
- alta: every parametrization and output kind ALTA defines and the reader converts,
  with #VS 0/1/2, per-output #VS, #SAMPLE / #ALTA HEADER END, no #PARAM_OUT, and the
  repository's fixture.
- merl: a MERL table is 34,992,012 bytes (3 int32 dims 90 x 90 x 180, then 3 x 1,458,000
  doubles), too large for a corpus; the seeds are the header followed by the first N
  cells of each colour block (R run, G run, B run), which the merl target reads both as
  is (a truncated table: the size check) and padded to a full table with every other cell
  unmeasured (see fuzz_targets/merl.rs). Plus other-dims headers and a bare header.
- rgl: tensor files laid out as the RGL database's (description u8, version u32 [2],
  jacobian u8 [1], theta_i, phi_i, ndf, sigma, vndf, luminance, rgb or
  spectra+wavelengths f32), on small tables (a few incidence nodes, 6 x 6 to 8 x 8), with
  and without the version field, jacobian 0 and 1, RGB and spectral, an anisotropic one
  (phi_i with 3 nodes), f64 and u8 tables, and one laid out as bsdfit's exporter writes
  (uniform 2 x 2 ndf, sigma and vndf; no version field).
- zemax: Zemax tabular BSDF files as scatterometers and imaging spheres write them
  (keyword header, tab- or space-separated lists, a TIS line and one row per azimuth per
  table): plane-symmetrical BRDF and BTDF, asymmetrical, Asymmetrical4D with two sample
  rotations, XYZ, CRLF, a wavelength comment, masked (0, NaN) cells, no DataEnd.
- astm: ASTM E1392 text (keyword header ending with VARS, comma-separated rows):
  Cornell-style 31 wavelengths in radians, degrees declared by ANGLE_UNITS and in the
  names, a transmitted (BTDF) file, u_ columns, three angles, R G B, a WAVELENGTH
  keyword, CRLF, NaN cells.
- mueller: NIST Mueller-matrix BRDF tables (a header of SCATMECH's column names, rows of
  signed angles in degrees and the wavelength in micrometres): cuts of the vendored PTFE
  grid and random set, and hand-shaped variants (only the six columns read, the other
  spellings `phii` and `fr11`, columns reordered, CRLF and a byte-order mark, several
  wavelengths, NaN and negative f_r11 cells, an angle past 90 degrees, a short row, a
  header without f_r11).
- any: one of each of the above (the sniffing entry point).
"""

import math
import os
import shutil
import struct

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "fuzz", "seeds")


def write(target, name, data):
    d = os.path.join(OUT, target)
    os.makedirs(d, exist_ok=True)
    if isinstance(data, str):
        data = data.encode("utf-8")
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)
    return data


# --- v1 CSV -------------------------------------------------------------------------

HEADER = "theta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty"


def cut_csv(path, rows):
    """The metadata, the header and the first `rows` data rows of a repository file."""
    out = []
    seen = 0
    with open(path, encoding="utf-8") as f:
        for line in f:
            out.append(line)
            if not line.startswith("#") and "theta_i" not in line and line.strip():
                seen += 1
                if seen >= rows:
                    break
    return "".join(out)


def lambertian(rho, theta_i, theta_o, phi_o):
    return rho / math.pi


def v1_rows(kind, geoms, wavelengths, u_rel=0.02, u_abs=1e-4, fmt="{:.6g}"):
    rows = []
    for (ti, pi, to, po) in geoms:
        for k, w in enumerate(wavelengths):
            v = 0.1 + 0.05 * k + 0.3 * math.exp(-((to + ti) / 15.0) ** 2)
            if kind == "btdf":
                v = 0.05 + 2.0 * math.exp(-((to - ti) / 10.0) ** 2)
            u = math.hypot(u_rel * v, u_abs)
            rows.append(",".join(fmt.format(x) for x in (ti, pi, to, po, w, v, u)))
    return rows


def v1_seeds():
    out = {}
    for name, n in [
        ("red-brick.csv", 40),
        ("diffuser-b.csv", 1000),
        ("diffuser-c.csv", 1000),
        ("diffuser-co3.csv", 1000),
        ("w80-g40-full.csv", 60),
        ("black-velvet.csv", 30),
    ]:
        out["data-" + name] = cut_csv(os.path.join(ROOT, "data", name), n)
    inplane = [(ti, 0, to, 0) for ti in (0, 30, 60) for to in range(-80, 81, 20) if to != ti]
    out["brdf-inplane-rgb.csv"] = "\n".join(
        ["# bsdfit dataset v1", "# material: seed", "# kind: brdf", HEADER]
        + v1_rows("brdf", inplane, (450, 550, 650))
    ) + "\n"
    btdf = [(ti, 0, to, po) for ti in (0, 20) for to in (-40, -10, 0, 10, 40) for po in (0, 90)]
    out["btdf-signed-planes.csv"] = "\n".join(
        ["# bsdfit dataset v1", "# kind: btdf", "# thickness_mm: 2", HEADER]
        + v1_rows("btdf", btdf, (550,))
    ) + "\n"
    out["crlf-bom.csv"] = "\ufeff" + "\r\n".join(
        ["# bsdfit dataset v1", "# kind: BRDF", HEADER]
        + v1_rows("brdf", inplane[:8], (550,))
    ) + "\r\n"
    reordered = "uncertainty,value,wavelength_nm,phi_o,theta_o,phi_i,theta_i"
    rows = []
    for r in v1_rows("brdf", inplane[:10], (633,)):
        c = r.split(",")
        rows.append(",".join('"%s"' % x for x in reversed(c)))
    out["reordered-quoted.csv"] = "\n".join(["# kind: brdf", reordered] + rows) + "\n"
    out["assumed-note.csv"] = "\n".join(
        [
            "# bsdfit dataset v1",
            "# kind: brdf",
            "# uncertainty: assumed, not measured: u = sqrt((REL·|value|)² + ABS²) with REL = 0.05, ABS = 0.001 sr⁻¹",
            "# converted_from: x.binary (MERL binary)",
            HEADER,
        ]
        + v1_rows("brdf", inplane[:12], (450, 550, 650), 0.05, 0.001)
    ) + "\n"
    zero = v1_rows("brdf", inplane[:6], (550,))
    zero = [",".join(r.split(",")[:6] + ["0"]) for r in zero]
    out["zero-uncertainty.csv"] = "\n".join(["# kind: brdf", HEADER] + zero) + "\n"
    hemi = [(ti, 0, to, po) for ti in (0, 40) for to in (10, 50, 80) for po in range(0, 360, 90)]
    out["hemisphere-spectral.csv"] = "\n".join(
        ["# bsdfit dataset v1", "# kind: brdf", "# source: seed, out of plane", HEADER]
        + v1_rows("brdf", hemi, (400, 560, 720), fmt="{!r}")
    ) + "\n"
    bad = v1_rows("brdf", inplane[:6], (550,))
    bad[1] = "10,0,95,0,550,0.1,0.01"
    bad[2] = "10;0;20;0;550;0.1;0.01"
    bad[3] = bad[0]
    bad[4] = "10,0,20,0,550,nan,0.01,"
    out["damaged-rows.csv"] = "\n".join(["# kind: brdf", HEADER, "# comment after header"] + bad) + "\n"
    for name, text in out.items():
        write("v1", name, text)
    return out


# --- ALTA text ----------------------------------------------------------------------

PARAMS = {
    "ISOTROPIC_TL_TV_PROJ_DPHI": 3,
    "ISOTROPIC_TV_TL_DPHI": 3,
    "RUSIN_TH_TD_PD": 3,
    "RUSIN_TH_PH_TD_PD": 4,
    "SPHERICAL_TL_PL_TV_PV": 4,
    "CARTESIAN": 6,
}
OUTS = {"INV_STERADIAN": 1, "INV_STERADIAN_COSINE_FACTOR": 1, "RGB_COLOR": 3}


def alta_inputs(param, k):
    """Input coordinates of the k-th sample of a parametrization (radians)."""
    tl = 0.1 + 0.25 * (k % 5)
    tv = 0.05 + 0.3 * ((k * 3) % 5)
    dphi = -2.5 + 0.7 * k
    if param == "ISOTROPIC_TL_TV_PROJ_DPHI":
        return [tl, tv * math.cos(dphi), tv * math.sin(dphi)]
    if param == "ISOTROPIC_TV_TL_DPHI":
        return [tv, tl, dphi]
    if param == "RUSIN_TH_TD_PD":
        return [0.05 * k, 0.1 + 0.2 * (k % 6), 0.4 * k]
    if param == "RUSIN_TH_PH_TD_PD":
        return [0.05 * k, 0.3 * k, 0.1 + 0.2 * (k % 6), 0.4 * k]
    if param == "SPHERICAL_TL_PL_TV_PV":
        return [tl, 0.2 * k, tv, 0.2 * k + dphi]
    # CARTESIAN: V then L.
    v = (math.sin(tv) * math.cos(dphi), math.sin(tv) * math.sin(dphi), math.cos(tv))
    l = (math.sin(tl), 0.0, math.cos(tl))
    return list(v) + list(l)


def alta_file(param, out, vs, rows=12, extra=(), order=None, end=None):
    n_in, n_out = PARAMS[param], OUTS[out] if out else 1
    head = {
        "DIM": "#DIM %d %d" % (n_in, n_out),
        "PARAM_IN": "#PARAM_IN " + param,
        "PARAM_OUT": ("#PARAM_OUT " + out) if out else None,
        "VS": ("#VS " + " ".join(str(x) for x in vs)) if vs is not None else None,
    }
    lines = list(extra)
    for key in order or ["DIM", "PARAM_IN", "PARAM_OUT", "VS"]:
        if head[key]:
            lines.append(head[key])
    if end:
        lines.append(end)
    per_out = (vs or [0]) * (n_out if vs is not None and len(vs) == 1 else 1)
    for k in range(rows):
        x = alta_inputs(param, k)
        ys = [0.2 + 0.1 * j + 0.5 * math.exp(-k / 4.0) for j in range(n_out)]
        cols = x + ys
        for j in range(n_out):
            cols += [0.01 * (1 + j)] * (per_out[j] if j < len(per_out) else 0)
        lines.append(" ".join("%.6g" % c for c in cols))
    return "\n".join(lines) + "\n"


def alta_seeds():
    out = {}
    for p in PARAMS:
        out["%s-inv-sr-vs1.dat" % p.lower()] = alta_file(p, "INV_STERADIAN", [1])
    for o in OUTS:
        out["isotropic-%s-vs2.dat" % o.lower()] = alta_file("ISOTROPIC_TL_TV_PROJ_DPHI", o, [2])
    out["rgb-per-output-vs.dat"] = alta_file("SPHERICAL_TL_PL_TV_PV", "RGB_COLOR", [0, 1, 2])
    out["no-vs.dat"] = alta_file("RUSIN_TH_TD_PD", "INV_STERADIAN", None)
    out["cosine-no-param-out.dat"] = alta_file("ISOTROPIC_TV_TL_DPHI", None, [0])
    out["sample-origin-end.dat"] = alta_file(
        "CARTESIAN",
        "INV_STERADIAN_COSINE_FACTOR",
        [1],
        extra=['#SAMPLE "seed material"', "#ORIGIN \"make_seeds.py\"", "#FORMAT text", "# a comment"],
        order=["PARAM_OUT", "VS", "PARAM_IN", "DIM"],
        end="#ALTA HEADER END",
    )
    out["unknown-output.dat"] = alta_file("RUSIN_TH_PH_TD_PD", None, [1]).replace(
        "#VS 1", "#PARAM_OUT UNKNOWN_OUTPUT\n#VS 1"
    )
    with open(os.path.join(ROOT, "tests", "fixtures", "alta_tape_no_param_out.dat"), encoding="utf-8") as f:
        out["fixture-tape-no-param-out.dat"] = f.read()
    for name, text in out.items():
        write("alta", name, text)
    return out


# --- MERL binary --------------------------------------------------------------------


def merl_prefix(n, dims=(90, 90, 180), unmeasured_every=0):
    """The header and the first n cells of each colour block (stored values, R G B)."""
    b = struct.pack("<3i", *dims)
    scale = (1.0, 1.15, 1.66)
    for c in range(3):
        for i in range(n):
            td = (i // 180 + 0.5) / 90 * math.pi / 2
            v = 1500.0 * (0.05 + 0.4 * math.exp(-td * 4.0)) / scale[c]
            if unmeasured_every and i % unmeasured_every == 0:
                v = -1.0
            b += struct.pack("<d", v)
    return b


def merl_seeds():
    out = {
        "prefix-30-cells.binary": merl_prefix(30),
        "prefix-200-cells-unmeasured.binary": merl_prefix(200, unmeasured_every=7),
        "header-only.binary": struct.pack("<3i", 90, 90, 180),
        "other-dims-1x1x2.binary": merl_prefix(2, dims=(1, 1, 2)),
        "negative-dims.binary": struct.pack("<3i", -90, 90, 180) + b"\0" * 24,
    }
    for name, data in out.items():
        write("merl", name, data)
    return out


# --- RGL tensor files ---------------------------------------------------------------

DTYPES = {"u8": (1, "B"), "u32": (5, "I"), "f32": (10, "f"), "f64": (11, "d")}


def tensor_file(fields):
    """Bytes of a tensor file: (name, dtype, shape, flat values); data 8-byte aligned."""
    head = b"tensor_file\0" + bytes([1, 0]) + struct.pack("<I", len(fields))
    header_len = len(head) + sum(2 + len(n) + 2 + 1 + 8 + 8 * len(s) for n, _, s, _ in fields)
    offset = (header_len + 7) // 8 * 8
    body = []
    for name, dt, shape, values in fields:
        code, fmt = DTYPES[dt]
        data = struct.pack("<%d%s" % (len(values), fmt), *values)
        head += struct.pack("<H", len(name)) + name.encode() + struct.pack("<HBQ", len(shape), code, offset)
        head += b"".join(struct.pack("<Q", s) for s in shape)
        body.append((offset, data))
        offset = (offset + len(data) + 7) // 8 * 8
    out = bytearray(head)
    for at, data in body:
        out += b"\0" * (at - len(out))
        out += data
    return bytes(out)


def rgl_material(
    nt=3,
    n=6,
    nphi=1,
    spectral=0,
    jacobian=0,
    version=True,
    table_dtype="f32",
    exporter=False,
    description="seed material (make_seeds.py), shaped like an RGL database file",
):
    thetas = [0.5 * math.pi / 2 * k / max(nt - 1, 1) for k in range(nt)]
    phis = [0.0, math.pi][:nphi] if nphi <= 2 else [2 * math.pi * k / nphi - math.pi for k in range(nphi)]
    nc = spectral or 3
    wavelengths = [400.0 + 300.0 * k / max(nc - 1, 1) for k in range(nc)]

    def grid(f, *lead):
        vals = []
        for y in range(n):
            for x in range(n):
                vals.append(f(x / (n - 1), y / (n - 1), *lead))
        return vals

    ndf = grid(lambda u, v: 2.0 * math.exp(-4.0 * u * u) + 0.05)
    sigma = grid(lambda u, v: 1.0 - 0.3 * u * u)
    nv = n
    if exporter:
        # As bsdfit's exporter writes: uniform 2 x 2 ndf, sigma and vndf (identity warp).
        ndf, sigma, nv = [1.0] * 4, [1.0] * 4, 2
    vndf, lum, table = [], [], []
    for _ in range(nphi):
        for t in range(nt):
            vndf += [1.0] * 4 if exporter else grid(lambda u, v: 1.5 * math.exp(-3.0 * u * u) + 0.1)
            lum += grid(lambda u, v: 0.2 + u * (1 - u) + 0.1 * t)
            for c in range(nc):
                table += grid(lambda u, v: (0.1 + 0.02 * c) + 0.8 * math.exp(-6.0 * u * u) * (1 + 0.1 * t))
    if table_dtype == "u8":
        table = [min(255, int(v * 200)) for v in table]
    fields = [("description", "u8", [len(description)], list(description.encode()))]
    if version:
        fields.append(("version", "u32", [2], [1, 0]))
    fields += [
        ("jacobian", "u8", [1], [jacobian]),
        ("theta_i", "f32", [nt], thetas),
        ("phi_i", "f32", [nphi], phis),
        ("ndf", "f32", [nv, nv], ndf),
        ("sigma", "f32", [nv, nv], sigma),
        ("vndf", "f32", [nphi, nt, nv, nv], vndf),
        ("luminance", "f32", [nphi, nt, n, n], lum),
    ]
    if spectral:
        fields.append(("wavelengths", "f32", [nc], wavelengths))
        fields.append(("spectra", table_dtype, [nphi, nt, nc, n, n], table))
    else:
        fields.append(("rgb", table_dtype, [nphi, nt, nc, n, n], table))
    return tensor_file(fields)


def rgl_seeds():
    out = {
        "rgb-with-version.bsdf": rgl_material(),
        "rgb-jacobian.bsdf": rgl_material(jacobian=1, version=False),
        "rgb-no-version.bsdf": rgl_material(version=False, nt=4, n=8),
        "spectral-5.bsdf": rgl_material(spectral=5, version=False, nt=2),
        "spectral-with-version.bsdf": rgl_material(spectral=4, nt=2),
        "isotropic-two-phi.bsdf": rgl_material(nphi=2, version=False, nt=2),
        "anisotropic.bsdf": rgl_material(nphi=3, version=False, nt=2, n=4),
        "table-f64.bsdf": rgl_material(table_dtype="f64", version=False, nt=2),
        "table-u8.bsdf": rgl_material(table_dtype="u8", version=False, nt=2),
        "one-theta.bsdf": rgl_material(nt=1, version=False),
        "exporter-layout.bsdf": rgl_material(exporter=True, version=False, nt=5, n=8),
        "empty-tensor.bsdf": tensor_file([]),
    }
    for name, data in out.items():
        write("rgl", name, data)
    return out


# --- Zemax tabular BSDF -------------------------------------------------------------


def zemax_file(symmetry="PlaneSymmetrical", spectral="Monochrome", kind="BRDF", rotations=(0,),
               aoi=(15, 30, 45), az=(0, 30, 60, 90, 120, 150, 180), rad=(0, 5, 10, 20, 40, 80),
               sep="\t", eol="\n", comments=("#Data Generated by Radiant Imaging's 'Imaging Sphere'",),
               value=None, data_end=True, extra_header=()):
    """A Zemax file: values from `value(section, rot, aoi, az, rad)` (a smooth lobe about
    the specular direction by default), four significant digits as the instruments write."""
    if value is None:
        def value(c, ro, a, z, r):
            return 0.06375 * (1 + 0.1 * c) * math.exp(-(r / 40.0) ** 2) * (1 - a / 200.0)
    j = lambda v: sep.join(("%g" % x) for x in v)
    l = list(comments) + list(extra_header) + [
        "Source  Measured", "Symmetry  " + symmetry, "SpectralContent  " + spectral,
        "ScatterType  " + kind,
        "SampleRotation  %d" % len(rotations), j(rotations),
        "AngleOfIncidence  %d" % len(aoi), j(aoi),
        "ScatterAzimuth %d" % len(az), j(az),
        "ScatterRadial %d" % len(rad), j(rad), ""]
    sections = ["TristimulusX", "TristimulusY", "TristimulusZ"] if spectral == "XYZ" else ["Monochrome"]
    for c, name in enumerate(sections):
        l += [name, "DataBegin"]
        for ro in rotations:
            for a in aoi:
                l.append("TIS %.6f" % (0.134506 - 0.001 * a))
                for z in az:
                    l.append(sep.join(fmt_cell(value(c, ro, a, z, r)) for r in rad))
        if data_end or c < len(sections) - 1:
            l.append("DataEnd")
    return eol.join(l) + eol


def fmt_cell(v):
    return "NaN" if v != v else "%.3E" % v


def zemax_seeds():
    def masked(c, ro, a, z, r):
        if r >= 80:
            return 0.0
        if z == 90 and r == 20:
            return float("nan")
        return 0.05 + 0.01 * math.cos(math.radians(r))

    def btdf(c, ro, a, z, r):
        return 3.689 * math.exp(-(r / 8.0) ** 2) + 0.01

    out = {
        "brown-vinyl-like.bsdf": zemax_file(),
        "btdf-matte.bsdf": zemax_file(kind="BTDF", aoi=(0, 10, 20), az=(0, 30, 60, 90, 180),
                                      rad=(0, 1, 2, 3.5, 5, 6.7, 8, 13.1), sep="    ", value=btdf),
        "asymmetrical.bsdf": zemax_file(symmetry="Asymmetrical", az=tuple(range(0, 360, 45)), aoi=(20,)),
        "asymmetrical4d-two-rotations.bsdf": zemax_file(symmetry="Asymmetrical4D", rotations=(0, 90),
                                                        az=(0, 90, 180, 270), aoi=(0, 40), rad=(0, 10, 30)),
        "xyz.bsdf": zemax_file(spectral="XYZ", aoi=(10, 50), az=(0, 90, 180), rad=(0, 15, 45)),
        "crlf-wavelength.bsdf": zemax_file(eol="\r\n", extra_header=("# wavelength_nm: 632.8",), aoi=(0, 60)),
        "masked-cells.bsdf": zemax_file(value=masked, aoi=(10, 70)),
        "no-data-end.bsdf": zemax_file(data_end=False, aoi=(30,), az=(0, 180), rad=(0, 10)),
        "full-circle-azimuths.bsdf": zemax_file(symmetry="Asymmetrical", az=(0, 90, 180, 270, 360), aoi=(45,)),
    }
    for name, data in out.items():
        write("zemax", name, data)
    return out


# --- ASTM E1392 ---------------------------------------------------------------------


def astm_file(vars_, rows, header=("SOURCE Test lab", "MEAS_DATE 1/2/2003", 'SAMPLE_NAME "white paint"'),
              eol="\n", num_points=True):
    l = list(header)
    if num_points:
        l.append("NUM_POINTS %d" % len(rows))
    l.append("VARS " + ",".join(vars_))
    l += [",".join(("nan" if c != c else "%.6g" % c) for c in r) for r in rows]
    return eol.join(l) + eol


def astm_seeds():
    wl = [400 + 10 * k for k in range(31)]
    geoms = [(ti, 0.0, ts, ps) for ti in (0, 30, 60) for ts in (10, 45) for ps in (-90, 0, 180)]
    rad = lambda g: [math.radians(x) for x in g]
    spectral = [rad(g) + [0.05 + 0.001 * k for k in range(31)] for g in geoms]
    deg_rows = [list(g) + [0.2 + 0.01 * g[2]] for g in geoms]
    btdf_rows = [[g[0], g[1], 180 - g[2], g[3], 2.5 * math.exp(-(g[2] / 20.0) ** 2), 0.05] for g in geoms]
    out = {
        "cornell-spectral-radians.astm": astm_file(["theta_i", "phi_i", "theta_s", "phi_s"] + [str(w) for w in wl], spectral),
        "degrees-keyword.astm": astm_file(["theta_i", "phi_i", "theta_s", "phi_s", "BRDF"], deg_rows,
                                          header=("SAMPLE_NAME grey", "ANGLE_UNITS DEG")),
        "degrees-in-names.astm": astm_file(["theta_i(deg)", "theta_s(deg)", "phi_s(deg)", "550nm"],
                                           [[r[0], r[2], r[3], r[4]] for r in deg_rows], header=("MEAS_NAME short form",)),
        "btdf-uncertainty.astm": astm_file(["theta_i", "phi_i", "theta_s", "phi_s", "633nm", "u_633nm"], btdf_rows,
                                           header=("SAMPLE_NAME diffuser", "ANGLE_UNITS DEG")),
        "rgb.astm": astm_file(["theta_i", "phi_i", "theta_s", "phi_s", "R", "G", "B"],
                              [rad(g) + [0.1, 0.2, 0.3] for g in geoms]),
        "wavelength-keyword-crlf.astm": astm_file(["theta_i", "phi_i", "theta_s", "phi_s", "Integrated BRDF"],
                                                  [rad(g) + [0.3] for g in geoms],
                                                  header=("SAMPLE_NAME x", "WAVELENGTH 0.633 um"), eol="\r\n"),
        "nan-cells.astm": astm_file(["theta_i", "phi_i", "theta_s", "phi_s", "450", "550"],
                                    [rad(g) + [0.1, float("nan") if k % 3 == 0 else 0.2] for k, g in enumerate(geoms)]),
        "no-num-points.astm": astm_file(["theta_i", "phi_i", "theta_s", "phi_s", "BRDF"],
                                        [rad(g) + [0.3] for g in geoms], num_points=False),
    }
    for name, data in out.items():
        write("astm", name, data)
    return out


# --- Real files (tests/fixtures/real/, sources and licences in its README) ------------

REAL = os.path.join(ROOT, "tests", "fixtures", "real")


def real_zemax(name, tables=3):
    """A vendored Zemax file cut to its first `tables` incidences (the fuzzers' 8 KiB
    inputs): the AngleOfIncidence line rewritten to match, the rest as the file has it."""
    with open(os.path.join(REAL, name), newline="") as f:
        lines = f.read().split("\n")
    at = next(k for k, l in enumerate(lines) if l.startswith("AngleOfIncidence"))
    angles = lines[at + 1].split()
    lines[at] = "AngleOfIncidence  %d" % tables
    lines[at + 1] = "\t".join(angles[:tables]) + "\t"
    begin = lines.index("DataBegin")
    tis = [k for k, l in enumerate(lines) if l.startswith("TIS")]
    end = tis[tables] if tables < len(tis) else lines.index("DataEnd")
    return "\n".join(lines[: begin + 1] + lines[tis[0]:end] + ["DataEnd", ""])


def real_astm(name, rows=18):
    """A vendored ASTM file cut to its first `rows` rows, NUM_POINTS rewritten to match."""
    with open(os.path.join(REAL, name), newline="") as f:
        lines = f.read().split("\n")
    at = next(k for k, l in enumerate(lines) if l.startswith("VARS"))
    head = ["NUM_POINTS %d" % rows if l.startswith("NUM_POINTS") else l for l in lines[: at + 1]]
    body = [l for l in lines[at + 1:] if l.strip()][:rows]
    return "\n".join(head + body) + "\n"


def real_mueller(name, rows=30):
    """A vendored NIST Mueller-matrix table cut to its header and first `rows` rows."""
    with open(os.path.join(REAL, name), newline="") as f:
        lines = f.read().split("\n")
    return "\n".join(lines[: rows + 1]) + "\n"


def mueller_row(names, lam, ti, pi, tr, pr, f):
    """One row of a Mueller table in the column order of `names` (the normalised
    elements written as small numbers, as NIST's files have them)."""
    cells = {"lambda": lam, "thetai": ti, "phi": pi, "phii": pi, "thetar": tr, "phir": pr,
             "f_r11": f, "fr11": f}
    return ",".join(fmt_mueller(cells.get(n, 0.0123)) for n in names)


def fmt_mueller(v):
    return v if isinstance(v, str) else "%.6g" % v


def mueller_table(names, rows, eol="\n", bom=False):
    text = eol.join([",".join(names)] + [mueller_row(names, *r) for r in rows]) + eol
    return ("\ufeff" if bom else "") + text


def mueller_seeds():
    full = ["lambda", "thetai", "phi", "thetar", "phir", "f_r11", "f_r12/f_r11",
            "f_r13/f_r11", "f_r14/f_r11", "f_r44/f_r11"]
    six = full[:6]
    grid = [(0.532, -ti, 0, tr, pr, 0.30 + 0.001 * tr)
            for ti in (0.001, 30, 60) for tr, pr in ((10, 0), (40, -45), (70, 180), (85, 90))]
    seeds = {
        "grid-full-columns.csv": mueller_table(full, grid),
        "six-columns.csv": mueller_table(six, grid),
        "other-spellings.csv": mueller_table(["lambda", "thetai", "phii", "thetar", "phir", "fr11"], grid),
        "reordered.csv": mueller_table(["f_r11", "phir", "thetar", "phi", "thetai", "lambda"], grid),
        "crlf-bom.csv": mueller_table(six, grid[:6], eol="\r\n", bom=True),
        "wavelengths.csv": mueller_table(six, [(lam,) + r[1:] for lam in (0.351, 0.633, 1.064) for r in grid[:4]]),
        "masked-cells.csv": mueller_table(six, grid[:4] + [(0.532, -30, 0, 20, 0, "NaN"), (0.532, -30, 0, 25, 0, -0.01)]),
        "angle-past-90.csv": mueller_table(six, grid[:3] + [(0.532, -30, 0, 95, 0, 0.3)]),
        "short-row.csv": mueller_table(six, grid[:3]) + "0.532,-30,0,20\n",
        "no-f_r11.csv": mueller_table(six[:5] + ["f_r12/f_r11"], grid[:3]),
        "real-nist-ptfe-grid.csv": real_mueller("PTFE.data.csv"),
        "real-nist-ptfe-random.csv": real_mueller("PTFE.data.random.csv"),
    }
    for name, data in seeds.items():
        write("mueller", name, data)
    return seeds


def real_seeds():
    zemax = {
        "real-imaging-sphere-brdf.bsdf": real_zemax("zemax_planesymmetric_brdf.bsdf"),
        "real-imaging-sphere-btdf.bsdf": real_zemax("zemax_planesymmetric_btdf.bsdf"),
    }
    astm = {"real-cornell-acryl-blue.astm": real_astm("cornell_acryl_blue.astm")}
    for name, data in zemax.items():
        write("zemax", name, data)
    for name, data in astm.items():
        write("astm", name, data)
    return zemax, astm


def main():
    if os.path.isdir(OUT):
        shutil.rmtree(OUT)
    v1, alta, merl, rgl = v1_seeds(), alta_seeds(), merl_seeds(), rgl_seeds()
    zemax, astm = zemax_seeds(), astm_seeds()
    mueller_seeds()
    real_zemax_seeds, real_astm_seeds = real_seeds()
    for name, data in [
        ("v1-" + "brdf-inplane-rgb.csv", v1["brdf-inplane-rgb.csv"]),
        ("v1-" + "crlf-bom.csv", v1["crlf-bom.csv"]),
        ("alta-sample-origin-end.dat", alta["sample-origin-end.dat"]),
        ("alta-fixture.dat", alta["fixture-tape-no-param-out.dat"]),
        ("merl-prefix-30-cells.binary", merl["prefix-30-cells.binary"]),
        ("rgl-rgb-no-version.bsdf", rgl["rgb-no-version.bsdf"]),
        ("rgl-rgb-with-version.bsdf", rgl["rgb-with-version.bsdf"]),
        ("zemax-brown-vinyl-like.bsdf", zemax["brown-vinyl-like.bsdf"]),
        ("zemax-btdf-matte.bsdf", zemax["btdf-matte.bsdf"]),
        ("astm-cornell-spectral-radians.astm", astm["cornell-spectral-radians.astm"]),
        ("astm-btdf-uncertainty.astm", astm["btdf-uncertainty.astm"]),
        ("zemax-real-imaging-sphere-brdf.bsdf", real_zemax_seeds["real-imaging-sphere-brdf.bsdf"]),
        ("astm-real-cornell-acryl-blue.astm", real_astm_seeds["real-cornell-acryl-blue.astm"]),
        ("mueller-real-nist-ptfe.csv", real_mueller("PTFE.data.csv")),
        ("mueller-real-nist-ptfe-random.csv", real_mueller("PTFE.data.random.csv")),
    ]:
        write("any", name, data)
    total = 0
    for d, _, files in os.walk(OUT):
        for f in files:
            total += os.path.getsize(os.path.join(d, f))
    print("wrote %s (%d bytes)" % (OUT, total))


if __name__ == "__main__":
    main()
