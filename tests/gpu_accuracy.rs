//! f32 accuracy of the GPU engine where plain f32 arithmetic is known to fail, each case
//! against the f64 CPU reference:
//! - the per-candidate cost sum (compensated on the device, shaders/engine/kernel.wgsl);
//! - the logarithmic BTDF losses in their tails, where ln(1 + a·y) loses every digit of
//!   a·y ≲ 1e-4 unless written as log1p (shaders/engine/loss.wgsl).
//!
//! Runs on whatever Vulkan adapter exists (lavapipe in CI); a missing adapter fails.

use bsdfit::bsdf::Model;
use bsdfit::data::{Dataset, Kind, RawRow, ReadOptions};
use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::wgsl::Shape;
use bsdfit::engine::{Backend, Problem};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn gpu(shape: Shape) -> GpuBackend {
    GpuBackend::new()
        .unwrap_or_else(|e| panic!("no GPU adapter: {e}. These tests need Vulkan (CI installs mesa-vulkan-drivers for lavapipe)."))
        .with_shape(shape)
}

fn row(i: usize, rng: &mut ChaCha8Rng, value: f64, uncertainty: f64) -> (usize, RawRow) {
    (
        i + 1,
        RawRow {
            theta_i: rng.random_range(0.0..80.0),
            phi_i: rng.random_range(0.0..360.0),
            theta_o: rng.random_range(0.0..80.0),
            phi_o: rng.random_range(0.0..360.0),
            wavelength_nm: 550.0,
            value,
            uncertainty,
        },
    )
}

/// Eight large χ² terms (z = 1000, term 1e6 each, the first eight samples so that each of
/// the 8 sample slices of the GPU shape starts with one) followed by 19,992 small ones
/// (|z| ∈ [0.15, 0.17], terms ≈ 0.026, together ≈ 510). In a plain f32 running sum every
/// small term is below half an ulp of the 1e6 or 8e6 already summed (0.031, 0.5) and
/// vanishes: the cost comes out 8e6 instead of 8e6 + 510, 6.4e-5 relative. A compensated
/// (Neumaier) sum carries them; what remains is the rounding of each term, random in
/// sign, so the bound is a few f32 unit roundoffs of the cost times √N:
/// |gpu − cpu| ≤ 4 · u32 · √N · cpu (3.4e-5 relative at N = 20,000, u32 = 2^-24).
/// Both kernel shapes: one thread per candidate walking all samples, and 8 sample slices
/// per candidate reduced in workgroup memory.
#[test]
fn cost_sums_keep_small_terms_after_a_large_one() {
    const N: usize = 20_000;
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let rho = 0.5;
    let f = rho / std::f64::consts::PI;
    let u = 0.01 * f;
    let rows: Vec<(usize, RawRow)> = (0..N)
        .map(|i| {
            let z = if i < 8 {
                -1000.0
            } else {
                let m: f64 = rng.random_range(0.15..0.17);
                if rng.random::<bool>() {
                    m
                } else {
                    -m
                }
            };
            // y = f − z u, so (y′ − y)/u = z at ρ = 0.5
            row(i, &mut rng, f - z * u, u)
        })
        .collect();
    let data = Dataset::from_rows(
        Kind::Brdf,
        "one outlier",
        &rows,
        "<sum>",
        &ReadOptions::default(),
    )
    .expect("valid data");
    let model = Model::parse("lambert", 1).unwrap();
    let params = [rho, 0.4999, 0.5001];
    let problem = Problem {
        model: &model,
        data: &data,
        loss: Loss::new(Metric::Chi2, Weights::Uniform),
    };
    let cpu = CpuBackend::new()
        .prepare(problem)
        .unwrap()
        .costs(&params)
        .unwrap();
    let bound_rel = 4.0 * (f32::EPSILON as f64 / 2.0) * (N as f64).sqrt();
    let mut failures = Vec::new();
    for shape in [Shape::CPU_DEVICE, Shape::GPU_DEVICE] {
        let g = gpu(shape).prepare(problem).unwrap().costs(&params).unwrap();
        for (n, (c, g)) in cpu.iter().zip(&g).enumerate() {
            let rel = (g - c).abs() / c;
            eprintln!("{shape:?} candidate {n}: cpu {c:.6} gpu {g:.6} relative error {rel:.2e} (bound {bound_rel:.1e})");
            if !(rel <= bound_rel) {
                failures.push(format!(
                    "{shape:?} candidate {n}: cpu {c} gpu {g} relative error {rel:.2e}"
                ));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "cost sums beyond {bound_rel:.1e} relative:\n{}",
        failures.join("\n")
    );
}

/// Model values of `spec` at `params` on every sample of `data`, by the CPU reference.
fn cpu_values(model: &Model, data: &Dataset, params: &[f64]) -> Vec<f64> {
    let problem = Problem {
        model,
        data,
        loss: Loss::new(Metric::Chi2, Weights::Uniform),
    };
    CpuBackend::new()
        .prepare(problem)
        .unwrap()
        .values(params)
        .unwrap()
}

/// `logf` and `logcosf` in the tails, where a·y ~ 1e-6: a diffuser's transmission scaled
/// down to S = 5e-6 (values 1e-9 … 4e-5 sr⁻¹) measured with 2 % noise. There
/// ln(1 + a y) in f32 rounds 1 + a y to a multiple of 2^-23 = 1.2e-7, up to 6 % of a y,
/// while the residuals g(y′) − g(y) are 2 % of it: the plain form was off by 0.28 to 31×
/// relative in the cost, and Goldberg's ln(u)·x/(u − 1) still by 0.23 to 12× (lavapipe's
/// log near 1 is only accurate to ~2^-21 absolute, as Vulkan allows); the atanh series of
/// `log1p_f32` (shaders/engine/loss.wgsl) keeps the relative accuracy of a y. The cost of
/// each candidate (the true parameters, then 7 perturbed ones) must agree within
/// REL = 2e-4 relative: the residuals are ~2 % of g, so the f32 model values' own
/// relative error (≲ 2e-6) is amplified ~50× in each residual and doubled by the square.
#[test]
fn log_losses_keep_their_digits_in_the_tails() {
    const REL: f64 = 2e-4;
    let model = Model::parse("btdf(tr)+scale", 1).unwrap();
    let truth = model
        .params_from_assignments("scale=5e-6,alpha=0.4,eta=1.5")
        .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    // Geometry first (values filled in from the model below).
    let geometry: Vec<(usize, RawRow)> = (0..1000).map(|i| row(i, &mut rng, 1.0, 0.1)).collect();
    let probe = Dataset::from_rows(
        Kind::Btdf,
        "tails",
        &geometry,
        "<tails>",
        &ReadOptions::default(),
    )
    .expect("valid geometry");
    let f = cpu_values(&model, &probe, &truth);
    let rows: Vec<(usize, RawRow)> = geometry
        .iter()
        .zip(&f)
        .filter(|(_, &v)| v > 1e-9)
        .map(|((i, r), &v)| {
            let noise: f64 = rng.random_range(-1.0..1.0);
            let value = v * (1.0 + 0.02 * noise);
            (
                *i,
                RawRow {
                    value,
                    uncertainty: 0.02 * value,
                    ..r.clone()
                },
            )
        })
        .collect();
    assert!(rows.len() > 300, "{} samples in the tails", rows.len());
    let data = Dataset::from_rows(
        Kind::Btdf,
        "tails",
        &rows,
        "<tails>",
        &ReadOptions::default(),
    )
    .expect("valid data");
    let ymax = data.samples.iter().fold(0.0f64, |m, s| m.max(s.value));
    assert!(
        ymax < 1e-4,
        "the data must stay in the log1p regime: max {ymax}"
    );
    let mut params = truth.clone();
    for _ in 0..7 {
        params.extend(truth.iter().map(|v| v * rng.random_range(0.9..1.1)));
    }
    let mut failures = Vec::new();
    for shape in [Shape::CPU_DEVICE, Shape::GPU_DEVICE] {
        let g = gpu(shape);
        for metric in [Metric::Logf, Metric::Logcosf] {
            for weights in [Weights::Uniform, Weights::Invunc] {
                let problem = Problem {
                    model: &model,
                    data: &data,
                    loss: Loss::new(metric, weights),
                };
                let c = CpuBackend::new()
                    .prepare(problem)
                    .unwrap()
                    .costs(&params)
                    .unwrap();
                let gc = g.prepare(problem).unwrap().costs(&params).unwrap();
                let worst =
                    c.iter()
                        .zip(&gc)
                        .map(|(c, g)| (g - c).abs() / c)
                        .fold(
                            0.0f64,
                            |m, e| if e.is_nan() { f64::INFINITY } else { m.max(e) },
                        );
                eprintln!("{shape:?} {metric}/{weights}: worst relative cost error {worst:.2e}");
                if !(worst <= REL) {
                    failures.push(format!(
                        "{shape:?} {metric}/{weights}: {worst:.2e} (cpu {c:?}, gpu {gc:?})"
                    ));
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "log-loss costs beyond {REL:e} relative:\n{}",
        failures.join("\n")
    );
}
