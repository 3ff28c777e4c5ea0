//! Criterion benchmark: one compass poll batch (restarts × (2P + 1) candidates) over a
//! realistic dataset, CPU reference, SIMD engine and GPU engine, reported as model-sample evaluations
//! per second (criterion's element throughput). `bsdfit bench` measures the same thing
//! for the whole catalogue.

use bsdfit::bsdf::Model;
use bsdfit::data::Kind;
use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::simd::SimdBackend;
use bsdfit::engine::{Backend, Problem};
use bsdfit::workflows::bench::bench_dataset;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

const RESTARTS: usize = 64;

fn throughput(c: &mut Criterion) {
    let gpu = GpuBackend::new()
        .map_err(|e| eprintln!("GPU not measured: {e}"))
        .ok();
    let mut backends: Vec<(&str, &dyn Backend)> = vec![];
    let cpu = CpuBackend::new();
    backends.push(("cpu", &cpu));
    let simd = SimdBackend::new();
    backends.push(("simd", &simd));
    if let Some(g) = gpu.as_ref() {
        backends.push(("gpu", g));
    }
    for (kind, spec) in [
        (Kind::Brdf, "lambert"),
        (Kind::Brdf, "ggx"),
        (Kind::Brdf, "fa(eon)"),
        (Kind::Brdf, "rmg(eon)"),
        (Kind::Btdf, "btdf(gg)+scale"),
    ] {
        let Ok(data) = bench_dataset(spec, kind) else {
            continue;
        };
        let model = Model::parse(spec, data.channel_count()).expect("catalogue spec");
        let candidates = RESTARTS * (2 * model.dim + 1);
        let starts = bsdfit::optim::random_starts(model.dim, candidates, 3);
        let params: Vec<f64> = starts.iter().flat_map(|u| model.from_unit(u)).collect();
        let metric = if kind == Kind::Brdf {
            Metric::Rmse
        } else {
            Metric::F
        };
        let problem = Problem {
            model: &model,
            data: &data,
            loss: Loss::new(metric, Weights::Uniform),
        };
        let mut group = c.benchmark_group(spec);
        group.throughput(Throughput::Elements((candidates * data.len()) as u64));
        group.sample_size(10);
        for (name, backend) in &backends {
            let mut eval = backend.prepare(problem).expect("prepare");
            group.bench_function(*name, |b| b.iter(|| eval.costs(&params).expect("costs")));
        }
        group.finish();
    }
}

criterion_group!(benches, throughput);
criterion_main!(benches);
