//! The GPU engine evaluates the channels of one direction together: it groups samples
//! into records (one per direction, plane and block of up to four channels) and scatters
//! the values back. Measured files are not as tidy as `synth` writes them: rows in any
//! order, a channel missing at some directions, a channel measured twice, more channels
//! than a record holds (spectral data), directions on two planes under `+peraxis`. Each
//! case here is evaluated on every engine shape and compared with the CPU reference.
//!
//! Tolerances (from f32, as tests/gpu_parity.rs states them): model values per sample
//! within REL = 2e-3 relative (FLOOR = 1e-30 sr⁻¹ for values below f32's range), costs
//! within 1e-3 relative. NaN never passes.

mod common;

use bsdfit::bsdf::Model;
use bsdfit::data::{Dataset, Kind, RawRow};
use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::wgsl::Shape;
use bsdfit::engine::{Backend, Problem};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const REL: f64 = 2e-3;
const REL_COST: f64 = 1e-3;
const FLOOR: f64 = 1e-30;

/// `directions` random directions (φo on `planes`, if any), each measured at every
/// wavelength except, at every fourth direction, one; every fifth direction measures one
/// wavelength twice (a different value). Rows shuffled.
fn untidy(kind: Kind, wavelengths: &[f64], planes: &[f64], directions: usize) -> Dataset {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut rows = Vec::new();
    for d in 0..directions {
        let (ti, pi) = (rng.random_range(0.0..80.0), rng.random_range(0.0..360.0));
        let to = rng.random_range(1.0..80.0);
        let po = if planes.is_empty() {
            rng.random_range(0.0..360.0)
        } else {
            planes[d % planes.len()]
        };
        let skipped = (d % 4 == 3).then(|| rng.random_range(0..wavelengths.len()));
        let repeated = (d % 5 == 2).then(|| rng.random_range(0..wavelengths.len()));
        for (c, &wl) in wavelengths.iter().enumerate() {
            let times = if Some(c) == skipped {
                0
            } else if Some(c) == repeated {
                2
            } else {
                1
            };
            for _ in 0..times {
                let value: f64 = rng.random_range(0.02..1.5);
                rows.push(RawRow {
                    theta_i: ti,
                    phi_i: pi,
                    theta_o: to,
                    phi_o: po,
                    wavelength_nm: wl,
                    value,
                    uncertainty: value * rng.random_range(0.01..0.05),
                });
            }
        }
    }
    common::shuffled_dataset(kind, rows, &mut rng, "untidy")
}

fn close(a: f64, b: f64, rel: f64, floor: f64) -> bool {
    a.is_finite() && (a - b).abs() <= rel * b.abs() + floor
}

/// Costs and values of `spec` on `data` at a few random points, on every shape, against
/// the CPU reference.
fn compare(spec: &str, data: &Dataset, metric: Metric, weights: Weights) {
    let model = Model::parse_for(spec, data.channels.len(), &data.axes).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let params: Vec<f64> = (0..5)
        .flat_map(|_| {
            let u: Vec<f64> = (0..model.dim).map(|_| rng.random_range(0.1..0.9)).collect();
            model.from_unit(&u)
        })
        .collect();
    let problem = Problem {
        model: &model,
        data,
        loss: Loss::new(metric, weights),
    };
    let reference = CpuBackend::new();
    let mut cpu = reference.prepare(problem).unwrap();
    let (ref_costs, ref_values) = (cpu.costs(&params).unwrap(), cpu.values(&params).unwrap());
    assert_eq!(ref_values.len(), 5 * data.len());
    for shape in Shape::ALL {
        let gpu = GpuBackend::new()
            .expect("a Vulkan adapter (lavapipe in CI)")
            .with_shape(shape);
        let mut ev = gpu.prepare(problem).unwrap();
        let (costs, values) = (ev.costs(&params).unwrap(), ev.values(&params).unwrap());
        assert_eq!(values.len(), ref_values.len(), "{spec} {shape:?}");
        for (i, (a, b)) in values.iter().zip(&ref_values).enumerate() {
            assert!(
                close(*a, *b, REL, FLOOR),
                "{spec} {shape:?}: value {i} (point {}, sample {}) {a}, reference {b}",
                i / data.len(),
                i % data.len()
            );
        }
        for (a, b) in costs.iter().zip(&ref_costs) {
            assert!(
                close(*a, *b, REL_COST, 0.0),
                "{spec} {metric:?} {shape:?}: cost {a}, reference {b}"
            );
        }
    }
}

#[test]
fn rgb_rows_in_any_order_with_gaps_and_repeats() {
    let data = untidy(Kind::Brdf, &[450.0, 550.0, 650.0], &[], 60);
    assert_eq!(data.channels.len(), 3);
    for spec in ["lambert", "ggx", "fa(on)", "rmg(eon)"] {
        compare(spec, &data, Metric::Smape, Weights::Relunc);
        compare(spec, &data, Metric::Ngan, Weights::Invunc);
    }
}

#[test]
fn spectral_data_spans_several_records_per_direction() {
    // Six channels: two records per direction (four channel slots and two), whose
    // parameter views start at a group that is not a constant.
    let wl = [420.0, 480.0, 540.0, 600.0, 660.0, 720.0];
    let data = untidy(Kind::Brdf, &wl, &[], 40);
    assert_eq!(data.channels.len(), 6);
    for spec in ["lambert", "ggx", "dmg(ggx)"] {
        compare(spec, &data, Metric::Rmse, Weights::Relunc);
    }
}

/// Per-plane roughness on two planes; `btdf(gg)+scale+peraxis` is the case where a node
/// that prepares per candidate what its shared parameters give (GG's shape constants,
/// its G1 at the problem's polar cosines) has per-plane parameters instead, so it must
/// not prepare them from the first plane's values. Once on random angles, once on
/// angles rounded to a 10° grid, where the engine also tabulates the functions of μ.
#[test]
fn per_plane_parameters_on_two_planes() {
    let data = untidy(Kind::Btdf, &[450.0, 550.0, 650.0], &[0.0, 90.0], 60);
    assert_eq!(data.axes.len(), 2, "two measurement planes");
    let mut gridded = data.clone();
    let step = 10f64.to_radians();
    for s in &mut gridded.samples {
        s.theta_i = (s.theta_i / step).round() * step;
        s.theta_o = ((s.theta_o / step).round() * step).max(step);
    }
    for data in [&data, &gridded] {
        for metric in [Metric::F, Metric::Logcosf] {
            compare("btdf(tr)+scale+peraxis", data, metric, Weights::Invunc);
            compare("btdf(gg)+scale+peraxis", data, metric, Weights::Invunc);
            compare("btdf(gg)+absorb", data, metric, Weights::Uniform);
        }
    }
}

#[test]
fn one_channel_alone() {
    let data = untidy(Kind::Brdf, &[550.0], &[], 80);
    compare("ggx", &data, Metric::Low, Weights::Invunc);
}
