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

/// Held by each test while it uses the GPU: on an NVIDIA H200 (driver 580.159.04) this
/// binary's tests, each opening its own wgpu instance and device, crashed the process
/// (SIGSEGV) in 4 of 5 runs when three ran at once, with or without XDG_RUNTIME_DIR set;
/// one at a time they passed every run. (bsdfit itself opens one device per process.)
fn one_device_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static GPU: std::sync::Mutex<()> = std::sync::Mutex::new(());
    GPU.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

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
/// per candidate reduced in workgroup memory. On an NVIDIA H200 (driver 580) this test
/// failed (3.7e-5) until the compensation's intermediates went behind a barrier the
/// driver's compiler cannot reassociate through (kernel.wgsl, `opaque`): lavapipe never
/// reassociated, so only a real GPU shows it.
#[test]
fn cost_sums_keep_small_terms_after_a_large_one() {
    let _gpu = one_device_at_a_time();
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
    for shape in Shape::ALL {
        let g = gpu(shape).prepare(problem).unwrap().costs(&params).unwrap();
        for (n, (c, g)) in cpu.iter().zip(&g).enumerate() {
            let rel = (g - c).abs() / c;
            eprintln!("{shape:?} candidate {n}: cpu {c:.6} gpu {g:.6} relative error {rel:.2e} (bound {bound_rel:.1e})");
            if rel.is_nan() || rel > bound_rel {
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
    let _gpu = one_device_at_a_time();
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
                    ..*r
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
    for shape in Shape::ALL {
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
                if worst.is_nan() || worst > REL {
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

/// Smith Λ of the β = 1 generalized Gaussian at a = β tanθ (ν = 1/a) by adaptive Simpson
/// quadrature, independent of the crate's fixed-panel integral that builds the table:
/// Λ = a ∫_ν^∞ 2 (√(r² − ν²) − ν acos(ν/r)) c e^(−r^(2p)) r dr, c = p/(π Γ(1/p)) (Heitz
/// 2014, Eq. 72, azimuth integrated; the formula itself is checked against the projected-
/// area identity in tests/btdf_physics.rs), integrated in t = ln r up to where r^(2p)
/// exceeds ν^(2p) by 80 (the rest is below e^-80 of the integrand at ν).
fn gg_lambda_adaptive(p: f64, a: f64) -> f64 {
    let nu = 1.0 / a;
    let c = p / (std::f64::consts::PI * bsdfit::math::special::ln_gamma(1.0 / p).exp());
    let f = |t: f64| {
        let r = t.exp();
        if r <= nu {
            return 0.0;
        }
        let sq = ((r - nu) * (r + nu)).sqrt();
        2.0 * (sq - nu * sq.atan2(nu)) * c * (-(r.powf(2.0 * p))).exp() * r * r
    };
    #[allow(clippy::too_many_arguments)]
    fn simpson(
        f: &dyn Fn(f64) -> f64,
        a: f64,
        b: f64,
        fa: f64,
        fm: f64,
        fb: f64,
        whole: f64,
        tol: f64,
        depth: u32,
    ) -> f64 {
        let m = 0.5 * (a + b);
        let (lm, rm) = (0.5 * (a + m), 0.5 * (m + b));
        let (flm, frm) = (f(lm), f(rm));
        let left = (m - a) / 6.0 * (fa + 4.0 * flm + fm);
        let right = (b - m) / 6.0 * (fm + 4.0 * frm + fb);
        let delta = left + right - whole;
        if depth == 0 || delta.abs() <= 15.0 * tol {
            return left + right + delta / 15.0;
        }
        simpson(f, a, m, fa, flm, fm, left, 0.5 * tol, depth - 1)
            + simpson(f, m, b, fm, frm, fb, right, 0.5 * tol, depth - 1)
    }
    let (lo, hi) = (nu.ln(), ((nu.powf(2.0 * p) + 80.0).powf(0.5 / p)).ln());
    // A first estimate on 64 panels sets the absolute tolerance (1e-12 of the integral).
    let n = 64;
    let h = (hi - lo) / n as f64;
    let mut total = 0.0;
    let mut panels = Vec::new();
    for k in 0..n {
        let (x0, x1) = (lo + k as f64 * h, lo + (k + 1) as f64 * h);
        let (f0, fm, f1) = (f(x0), f(0.5 * (x0 + x1)), f(x1));
        let s = h / 6.0 * (f0 + 4.0 * fm + f1);
        total += s;
        panels.push((x0, x1, f0, fm, f1, s));
    }
    let tol = 1e-12 * total.abs() / n as f64;
    let j: f64 = panels
        .iter()
        .map(|&(x0, x1, f0, fm, f1, s)| simpson(&f, x0, x1, f0, fm, f1, s, tol, 40))
        .sum();
    a * j
}

/// Evaluates G1(ω) = G1/μ · μ of the WGSL GG twin (shaders/bsdf/microfacet.wgsl, with the
/// engine's f32 LUT bound) at points (sinθ, μ, β, p) on the device.
fn gpu_gg_g1(points: &[[f32; 4]]) -> Vec<f32> {
    use wgpu::util::DeviceExt;
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
    }
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
        backends: wgpu::Backends::VULKAN,
        ..wgpu::InstanceDescriptor::new_without_display_handle()
    });
    let adapter =
        pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
            .expect("a Vulkan adapter (CI installs mesa-vulkan-drivers for lavapipe)");
    let (device, queue) =
        pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default()))
            .expect("a device");
    let source = format!(
        "var<private> P: array<f32, 8>;\n\
         @group(0) @binding(0) var<storage, read> LUT: array<f32>;\nfn lut(k: u32) -> f32 {{ return LUT[k]; }}\n\
         @group(0) @binding(1) var<storage, read> pts: array<vec4<f32>>;\n\
         @group(0) @binding(2) var<storage, read_write> g1: array<f32>;\n{}\n{}\n{}\n\
         @compute @workgroup_size(64) fn main(@builtin(global_invocation_id) id: vec3<u32>) {{\n\
         if (id.x >= arrayLength(&pts)) {{ return; }}\n\
         let q = pts[id.x];\n\
         g1[id.x] = gg_g1_over_mu(vec3<f32>(q.x, 0.0, q.y), gg_new(q.z, q.w)) * q.y;\n}}\n",
        bsdfit::engine::wgsl::COMMON,
        bsdfit::engine::wgsl::all_accessors(),
        bsdfit::bsdf::microfacet::MICROFACET_WGSL.1,
    );
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("gg g1 probe"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("gg g1 probe"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let lut = bsdfit::bsdf::microfacet::gg_lambda_table().to_f32();
    let storage = |label, bytes: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytes,
            usage,
        })
    };
    let lut_buf = storage(
        "lut",
        bytemuck::cast_slice(&lut),
        wgpu::BufferUsages::STORAGE,
    );
    let pts_buf = storage(
        "pts",
        bytemuck::cast_slice(points),
        wgpu::BufferUsages::STORAGE,
    );
    let bytes = (points.len() * 4) as u64;
    let out = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("g1"),
        size: bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("staging"),
        size: bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: lut_buf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: pts_buf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: out.as_entire_binding(),
            },
        ],
    });
    let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups((points.len() as u32).div_ceil(64), 1, 1);
    }
    enc.copy_buffer_to_buffer(&out, 0, &staging, 0, bytes);
    queue.submit(Some(enc.finish()));
    let slice = staging.slice(..);
    slice.map_async(wgpu::MapMode::Read, |r| r.expect("map the read-back"));
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
    let view = slice.get_mapped_range().expect("mapped");
    bytemuck::cast_slice::<u8, f32>(&view).to_vec()
}

/// The GG Smith Λ table (bicubic, src/bsdf/microfacet.rs) against an adaptive quadrature
/// at 1,000 random (β, p, μ): β and p log-uniform over their parameter ranges
/// [0.003, 1] × [0.2, 5], μ = cos θ uniform in [1e-3, 1]. Error: the relative error of
/// G1 = 1/(1 + Λ). CPU (f64 interpolation): below 1e-5 (measured 4.6e-7 on a dense
/// sample). GPU (the WGSL twin on the f32 table): below 1e-5 + 64·u32 (3.8e-6: f32
/// rounding of the table values, of lnΓ in J0 (~1e-6 relative), of r_c's exp and of the
/// stencil sum). The bilinear 33 × 129 table this replaces failed the 1e-5 bound (9.4e-5).
#[test]
fn gg_lambda_table_matches_an_adaptive_quadrature_on_cpu_and_gpu() {
    let _gpu = one_device_at_a_time();
    use bsdfit::bsdf::microfacet::{Gg, Masking};
    const TABLE: f64 = 1e-5;
    let gpu_bound = TABLE + 64.0 * f32::EPSILON as f64 / 2.0;
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let log_uniform = |rng: &mut ChaCha8Rng, lo: f64, hi: f64| {
        (lo.ln() + rng.random::<f64>() * (hi / lo).ln()).exp()
    };
    let mut cases = Vec::new();
    for _ in 0..1000 {
        let beta = log_uniform(&mut rng, 3e-3, 1.0);
        let p = log_uniform(&mut rng, 0.2, 5.0);
        let mu: f64 = rng.random_range(1e-3..1.0);
        cases.push((beta, p, mu));
    }
    let points: Vec<[f32; 4]> = cases
        .iter()
        .map(|&(beta, p, mu)| {
            [
                (1.0 - mu * mu).sqrt() as f32,
                mu as f32,
                beta as f32,
                p as f32,
            ]
        })
        .collect();
    let gpu = gpu_gg_g1(&points);
    let (mut worst_cpu, mut worst_gpu) = ((0.0f64, (0.0, 0.0, 0.0)), (0.0f64, (0.0, 0.0, 0.0)));
    for (&(beta, p, mu), &g) in cases.iter().zip(&gpu) {
        // The GPU's inputs are f32: compare each side at the point it actually evaluates.
        let exact_at = |beta: f64, p: f64, mu: f64| {
            let sin = (1.0 - mu * mu).sqrt();
            1.0 / (1.0 + gg_lambda_adaptive(p, beta * sin / mu))
        };
        let w = glam::DVec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
        let cpu = Gg::new(beta, p).g1_over_mu(w) * mu;
        let e = (cpu - exact_at(beta, p, mu)).abs() / exact_at(beta, p, mu);
        if e.is_nan() || e > worst_cpu.0 {
            worst_cpu = (e, (beta, p, mu));
        }
        let (b32, p32, m32) = (beta as f32 as f64, p as f32 as f64, mu as f32 as f64);
        let exact32 = exact_at(b32, p32, m32);
        let e = (g as f64 - exact32).abs() / exact32;
        if e.is_nan() || e > worst_gpu.0 {
            worst_gpu = (e, (b32, p32, m32));
        }
    }
    eprintln!("GG G1 from the table: worst relative error cpu {:.2e} at (β, p, μ) = {:?}, gpu {:.2e} at {:?}", worst_cpu.0, worst_cpu.1, worst_gpu.0, worst_gpu.1);
    assert!(
        worst_cpu.0 <= TABLE,
        "CPU table G1 off by {:.2e} at (β, p, μ) = {:?}",
        worst_cpu.0,
        worst_cpu.1
    );
    assert!(
        worst_gpu.0 <= gpu_bound,
        "GPU table G1 off by {:.2e} (bound {gpu_bound:.2e}) at (β, p, μ) = {:?}",
        worst_gpu.0,
        worst_gpu.1
    );
}
