//! Criterion benchmark: one Levenberg–Marquardt step's normal equations (JᵀJ, Jᵀr, Σr²
//! of R restarts, each a point and its P forward-difference neighbours) over a realistic
//! dataset, CPU reference vs GPU engine, as model-sample evaluations per second. This is
//! what a sweep's LM fits spend their evaluations on; `throughput` measures the `costs`
//! kernel of a compass poll instead. On a CPU device (lavapipe) the GPU engine reads the
//! model values back and forms the sums on the host, so cheap models can run slower here
//! than on the CPU reference, while costly ones run faster (README, Throughput).

use bsdfit::bsdf::Model;
use bsdfit::data::Kind;
use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::{Backend, Problem};
use bsdfit::workflows::bench::bench_dataset;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

/// Restarts per step: one fit's 8, and a sweep stage's 7 fits × 8.
const RESTARTS: [usize; 2] = [8, 56];
/// The forward-difference step in the unit box (the search's, 2⁻¹⁰).
const STEP: f64 = 9.765625e-4;

fn lm_step(c: &mut Criterion) {
    let gpu = GpuBackend::new()
        .map_err(|e| eprintln!("GPU not measured: {e}"))
        .ok();
    let cpu = CpuBackend::new();
    let mut backends: Vec<(&str, &dyn Backend)> = vec![("cpu", &cpu)];
    if let Some(g) = gpu.as_ref() {
        backends.push(("gpu", g));
    }
    for spec in ["lambert", "ggx", "vmf", "rmg(ggx)", "dmg(vmf)"] {
        let Ok(data) = bench_dataset(spec, Kind::Brdf) else {
            continue;
        };
        let model = Model::parse(spec, data.channel_count()).expect("catalogue spec");
        let problem = Problem {
            model: &model,
            data: &data,
            loss: Loss::new(Metric::Rmse, Weights::Uniform),
        };
        for restarts in RESTARTS {
            let (mut params, mut steps) = (Vec::new(), Vec::new());
            for start in bsdfit::optim::random_starts(model.dim, restarts, 3) {
                params.extend(model.from_unit(&start));
                for j in 0..model.dim {
                    let h = if start[j] + STEP <= 1.0 { STEP } else { -STEP };
                    let mut moved = start.clone();
                    moved[j] += h;
                    params.extend(model.from_unit(&moved));
                    steps.push(h);
                }
            }
            let owners = vec![0; restarts];
            let mut group = c.benchmark_group(format!("{spec} x{restarts}"));
            group.throughput(Throughput::Elements(
                (restarts * (model.dim + 1) * data.len()) as u64,
            ));
            group.sample_size(10);
            for (name, backend) in &backends {
                let mut eval = backend.prepare(problem).expect("prepare");
                group.bench_function(*name, |b| {
                    b.iter(|| {
                        eval.normal_equations_of(&owners, &params, &steps)
                            .expect("normal equations")
                    })
                });
            }
            group.finish();
        }
    }
}

criterion_group!(benches, lm_step);
criterion_main!(benches);
