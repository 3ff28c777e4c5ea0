//! Helpers shared by the integration tests: seeded randomness, directions, quadrature.
#![allow(dead_code)]

pub mod cli;
pub mod optical;
pub mod truths;

use bsdfit::bsdf::Model;
use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

/// A data set of `rows` in a random order (as measurement files list them), numbered as
/// lines 1, 2, … of a file `<name>`.
pub fn shuffled_dataset(
    kind: bsdfit::data::Kind,
    mut rows: Vec<bsdfit::data::RawRow>,
    rng: &mut ChaCha8Rng,
    name: &str,
) -> bsdfit::data::Dataset {
    use rand::seq::SliceRandom;
    rows.shuffle(rng);
    let rows: Vec<(usize, bsdfit::data::RawRow)> = rows
        .into_iter()
        .enumerate()
        .map(|(i, r)| (i + 1, r))
        .collect();
    let file = format!("<{name}>");
    bsdfit::data::Dataset::from_rows(kind, name, &rows, &file, &Default::default())
        .expect("valid data")
}

/// Whether this run is CI (`CI=true`), where the README's test command has installed
/// everything a test needs from the machine (lavapipe, Mitsuba, Slurm).
pub fn in_ci() -> bool {
    // One rule with the Python tests' conftest.py: `true`, `1` or `yes`, any case.
    std::env::var("CI")
        .is_ok_and(|v| matches!(v.trim().to_ascii_lowercase().as_str(), "true" | "1" | "yes"))
}

/// Something a test needs from the machine is missing: under CI that fails the test (a
/// skip there would hide the check); elsewhere the reason is printed and the caller skips.
pub fn missing(what: &str) {
    assert!(
        !in_ci(),
        "{what}: CI=true, where scripts/test.sh installs it, so its absence is a failure"
    );
    eprintln!("skipped: {what}");
}

/// The `--backend` of a command-line test that claims GPU coverage: `gpu` where a Vulkan
/// adapter opens (lavapipe in CI, where its absence fails), else `simd`, saying so.
pub fn gpu_backend_flag() -> &'static str {
    match bsdfit::engine::gpu::GpuBackend::new() {
        Ok(_) => "gpu",
        Err(e) => {
            missing(&format!("no Vulkan adapter for the GPU engine ({e})"));
            eprintln!("running on the SIMD CPU engine instead: this is not GPU coverage");
            "simd"
        }
    }
}

/// The engine of the tests that claim GPU coverage without needing it to be correct: the
/// GPU engine (lavapipe in CI). Without a Vulkan adapter that fails under CI; elsewhere
/// the test runs on the CPU reference, saying so, rather than passing as GPU coverage.
pub fn gpu_engine() -> Box<dyn bsdfit::engine::Backend> {
    match bsdfit::engine::gpu::GpuBackend::new() {
        Ok(g) => {
            eprintln!("using {}", bsdfit::engine::Backend::name(&g));
            Box::new(g)
        }
        Err(e) => {
            missing(&format!("no Vulkan adapter for the GPU engine ({e})"));
            eprintln!("running on the CPU reference instead: this is not GPU coverage");
            Box::new(bsdfit::engine::cpu::CpuBackend::new())
        }
    }
}

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Unit direction from polar angle θ and azimuth φ (radians), upper hemisphere.
pub fn dir(theta: f64, phi: f64) -> DVec3 {
    DVec3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    )
}

/// Unit direction from μ = cos θ and φ.
pub fn dir_mu(mu: f64, phi: f64) -> DVec3 {
    let s = (1.0 - mu * mu).max(0.0).sqrt();
    DVec3::new(s * phi.cos(), s * phi.sin(), mu)
}

/// A random upper-hemisphere direction; one draw in four is grazing (μ in [1e-3, 2e-2]).
pub fn random_upper(r: &mut ChaCha8Rng) -> DVec3 {
    let mu = if r.random::<f64>() < 0.25 {
        1e-3 + r.random::<f64>() * 2e-2
    } else {
        1e-3 + r.random::<f64>() * (1.0 - 1e-3)
    };
    dir_mu(mu, r.random::<f64>() * 2.0 * PI)
}

/// Mirror direction of ω about the normal: (θ, φ + 180°).
pub fn mirror(w: DVec3) -> DVec3 {
    DVec3::new(-w.x, -w.y, w.z)
}

/// A random point of the unit box [0,1]^P.
pub fn random_unit(r: &mut ChaCha8Rng, dim: usize) -> Vec<f64> {
    (0..dim).map(|_| r.random::<f64>()).collect()
}

/// Physical parameter vectors to try: the box corners all-0 and all-1, then `n` random.
pub fn param_sets(model: &Model, n: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut r = rng(seed);
    let mut v = vec![
        model.from_unit(&vec![0.0; model.dim]),
        model.from_unit(&vec![1.0; model.dim]),
    ];
    for _ in 0..n {
        let u = random_unit(&mut r, model.dim);
        v.push(model.from_unit(&u));
    }
    v
}

/// Evaluates a compiled model at one channel without allocating per call.
pub struct Eval<'a> {
    pub model: &'a Model,
    pub view: Vec<f64>,
}

impl<'a> Eval<'a> {
    pub fn new(model: &'a Model, flat: &[f64], ch: usize) -> Self {
        let mut view = Vec::new();
        model.scalars_into(flat, ch, &mut view);
        Eval { model, view }
    }
    pub fn f(&self, wi: DVec3, wo: DVec3) -> f64 {
        self.model.root.eval(&self.view, wi, wo)
    }
}

/// Set a named parameter (all channels) in a flat vector.
pub fn set_param(model: &Model, flat: &mut [f64], name: &str, value: f64) {
    let p = model
        .params
        .iter()
        .find(|p| p.name == name)
        .unwrap_or_else(|| panic!("{}: no parameter {name}", model.spec));
    for k in 0..p.width(model.channels) {
        flat[p.index + k] = value;
    }
}

pub fn get_param(model: &Model, flat: &[f64], name: &str) -> Option<f64> {
    model
        .params
        .iter()
        .find(|p| p.name == name)
        .map(|p| flat[p.index])
}

/// "ρ-type" parameters: per-channel albedo-like scales with bounds [0, 1].
pub fn is_rho_type(p: &bsdfit::bsdf::FlatParam) -> bool {
    p.decl.rgb && p.decl.lo == 0.0 && p.decl.hi == 1.0
}

/// Resolution of [`sphere_integral_with`]: cells grow geometrically by `ratio` from 1e-7 rad
/// off the axis until they reach `max_step`, then stay uniform to π; `nphi` azimuthal cells
/// far from the axis (fewer, at least 24, near it).
#[derive(Clone, Copy, Debug)]
pub struct Grid {
    pub ratio: f64,
    pub max_step: f64,
    pub nphi: usize,
}

/// The default. Error on ∫ μo/π: ≤ 1.2e-5 (θi 0–89°); on EON's white albedo ≈ 1.3e-4 at
/// θi = 89°.
pub const COARSE: Grid = Grid {
    ratio: 1.04,
    max_step: PI / 300.0,
    nphi: 180,
};
/// ≈ 4× the cells of [`COARSE`]. Error on ∫ μo/π: ≤ 1.2e-6; on EON's white albedo ≤ 7e-6.
pub const FINE: Grid = Grid {
    ratio: 1.02,
    max_step: PI / 600.0,
    nphi: 360,
};

fn polar_edges(grid: Grid) -> Vec<f64> {
    let mut e = vec![0.0, 1e-7];
    loop {
        let last = *e.last().unwrap();
        let next = last * grid.ratio;
        if next - last >= grid.max_step {
            break;
        }
        e.push(next);
    }
    let last = *e.last().unwrap();
    let n = ((PI - last) / grid.max_step).ceil() as usize;
    for k in 1..=n {
        e.push(last + (PI - last) * k as f64 / n as f64);
    }
    e
}

/// [`sphere_integral_with`] on the [`COARSE`] grid.
pub fn sphere_integral(axis: DVec3, g: &dyn Fn(DVec3) -> f64) -> f64 {
    sphere_integral_with(COARSE, axis, g)
}

/// ∫ g(ω) dω over the directions with ω.z > 0, in polar coordinates about `axis`, with
/// cells dense near the axis (resolves lobes down to widths ~1e-4 rad centred on it).
/// Cells use their exact solid angle and the midpoint value.
pub fn sphere_integral_with(grid: Grid, axis: DVec3, g: &dyn Fn(DVec3) -> f64) -> f64 {
    let a = axis.normalize();
    let t = if a.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let t = (t - a * a.dot(t)).normalize();
    let b = a.cross(t);
    let edges = polar_edges(grid);
    let mut sum = 0.0;
    for w in edges.windows(2) {
        let (ta, tb) = (w[0], w[1]);
        let tm = 0.5 * (ta + tb);
        let nphi = ((grid.nphi as f64 * (4.0 * tm.sin()).min(1.0)).ceil() as usize).max(24);
        let dphi = 2.0 * PI / nphi as f64;
        let area = (ta.cos() - tb.cos()) * dphi;
        let (st, ct) = tm.sin_cos();
        for k in 0..nphi {
            let ph = (k as f64 + 0.5) * dphi;
            let d = a * ct + (t * ph.cos() + b * ph.sin()) * st;
            if d.z <= 0.0 {
                continue;
            }
            sum += g(d) * area;
        }
    }
    sum
}

/// Path of the built `bsdfit` binary.
pub fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_bsdfit")
}

/// Synthetic data from `spec` with `params` (`name=value,…`, as `bsdfit synth --params`) on
/// `rows` (θi, φi, θo, φo in degrees), one channel per wavelength of `wavelengths`, with
/// noise u = sqrt((rel·f)² + abs²) drawn from `seed`: the synth → fit scaffolding of the
/// recovery, GPU-vs-CPU, LM and diagnose tests. Returns the model (compiled for the rows'
/// measurement planes), the true flat parameters and the data.
pub fn synth_rows(
    spec: &str,
    params: &str,
    rows: &[[f64; 4]],
    wavelengths: &[f64],
    noise: (f64, f64),
    seed: u64,
) -> (Model, Vec<f64>, bsdfit::data::Dataset) {
    let planes = bsdfit::data::measurement_planes(
        rows.iter()
            .map(|r| bsdfit::data::normalise_angles(r[2], r[3])),
    );
    let model = Model::parse_for(spec, wavelengths.len(), &planes)
        .unwrap_or_else(|e| panic!("{spec}: {e}"));
    let truth = model
        .params_from_assignments(params)
        .unwrap_or_else(|e| panic!("{spec}: {e}"));
    let noise = bsdfit::workflows::synth::Noise {
        rel: noise.0,
        abs: noise.1,
    };
    let data = bsdfit::workflows::synth::synthesize(
        &model,
        &truth,
        rows,
        wavelengths,
        noise,
        seed,
        &format!("synthetic {spec}"),
    )
    .unwrap_or_else(|e| panic!("{spec}: {e}"));
    (model, truth, data)
}

/// [`synth_rows`] on a named geometry of `bsdfit models`.
pub fn synth_geometry(
    spec: &str,
    params: &str,
    geometry: &str,
    wavelengths: &[f64],
    noise: (f64, f64),
    seed: u64,
) -> (Model, Vec<f64>, bsdfit::data::Dataset) {
    let (_, rows) = bsdfit::workflows::synth::geometry_expr(geometry)
        .unwrap_or_else(|e| panic!("geometry {geometry}: {e}"));
    synth_rows(spec, params, &rows, wavelengths, noise, seed)
}

/// Rows (θi, φi, θo, φo in degrees) shaped like the measurements of retroreflective tapes
/// (the 3M tapes of Belcour et al. 2014): incidences θi = 15, 30, 60° in the plane φi = 0,
/// outgoing directions over the hemisphere (θo = 2.5…82.5° in 5° steps, φo every 15°), and
/// dense points within 4° of the retro direction (on and off the plane of incidence) and of
/// the mirror direction, where the lobes are narrow.
pub fn tape_rows() -> Vec<[f64; 4]> {
    let mut rows = Vec::new();
    for ti in [15.0, 30.0, 60.0] {
        for k in 0..17 {
            let to = 2.5 + 5.0 * k as f64;
            for j in 0..24 {
                rows.push([ti, 0.0, to, 15.0 * j as f64]);
            }
        }
        for d in [
            -4.0, -3.0, -2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0,
        ] {
            for po in [0.0, 2.0, 358.0, 5.0, 355.0] {
                rows.push([ti, 0.0, ti + d, po]);
            }
            if d != 0.0 {
                rows.push([ti, 0.0, ti + d, 180.0]);
            }
        }
        rows.push([ti, 0.0, ti, 180.0]);
    }
    rows
}
