//! Channels evaluated together ([`Model::eval_channels`], the CPU backend's path) against
//! the per-channel evaluation ([`Model::eval`]), for every model the registry derives.
//!
//! The channel path computes what the channels of one direction share once and the rest
//! per channel with the same operations in the same order, so the two must agree **bit
//! for bit**; NaN or ±∞ never passes. Then the CPU evaluator, which groups a data set's
//! samples by direction, against values, losses and normal equations formed sample by
//! sample from `Model::eval` on data whose rows are shuffled (channel-major, repeated
//! measurements, directions on two planes).

mod common;

use bsdfit::bsdf::{every_spec, Model};
use bsdfit::data::{Dataset, Kind, RawRow};
use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::{normal_equations_of_values, Backend, Problem};
use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

/// Every spec of both kinds (catalogue, per-plane variants, models outside the
/// catalogue) and a few nestings beyond one suffix.
fn all_specs() -> Vec<(Kind, String)> {
    let mut v: Vec<(Kind, String)> = Vec::new();
    for kind in [Kind::Brdf, Kind::Btdf] {
        v.extend(every_spec(kind).into_iter().map(|s| (kind, s)));
    }
    v.push((Kind::Brdf, "rmg(ggx)+retro".into()));
    v.push((Kind::Brdf, "fa(vmf)+mrm82+falloff".into()));
    v.push((Kind::Brdf, "dmg(ggx)+mrm+falloff".into()));
    v.push((Kind::Btdf, "btdf(gtr)+scale+diffuse".into()));
    v
}

/// A direction with cos θ = μ and azimuth φ.
fn dir_mu(mu: f64, phi: f64) -> DVec3 {
    let s = (1.0 - mu * mu).max(0.0).sqrt();
    DVec3::new(s * phi.cos(), s * phi.sin(), mu)
}

/// (ωi, ωo) pairs: mostly the kind's own hemispheres (one in four near grazing), some on
/// the normal, at the mirror and retro directions, and some on the wrong side (where
/// the models return 0).
fn directions(kind: Kind, rng: &mut ChaCha8Rng, n: usize) -> Vec<(DVec3, DVec3)> {
    let mu = |rng: &mut ChaCha8Rng| {
        if rng.random::<f64>() < 0.25 {
            1e-3 + rng.random::<f64>() * 2e-2
        } else {
            1e-3 + rng.random::<f64>() * (1.0 - 1e-3)
        }
    };
    let below = |w: DVec3| DVec3::new(w.x, w.y, -w.z);
    let mut v = Vec::new();
    for k in 0..n {
        let wi = dir_mu(mu(rng), rng.random_range(0.0..2.0 * PI));
        let wo = match k % 8 {
            0 => DVec3::Z,
            1 => DVec3::new(-wi.x, -wi.y, wi.z), // mirror
            2 => wi,                             // retro
            _ => dir_mu(mu(rng), rng.random_range(0.0..2.0 * PI)),
        };
        let wo = if kind == Kind::Btdf { below(wo) } else { wo };
        v.push(if k % 11 == 5 {
            (wi, below(wo)) // the other hemisphere
        } else if k % 13 == 7 {
            (below(wi), wo) // from below
        } else {
            (wi, wo)
        });
    }
    v
}

/// Random parameter vectors in the bounds, with each value at a bound one time in ten.
fn random_params(model: &Model, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let u: Vec<f64> = (0..model.dim)
        .map(|_| match rng.random_range(0..20) {
            0 => 0.0,
            1 => 1.0,
            _ => rng.random::<f64>(),
        })
        .collect();
    model.from_unit(&u)
}

fn same(a: f64, b: f64) -> bool {
    a.is_finite() && a.to_bits() == b.to_bits()
}

#[test]
fn channels_together_equal_channels_one_by_one_bit_for_bit() {
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let mut compared = 0usize;
    for (kind, spec) in all_specs() {
        for channels in [1usize, 3, 5] {
            // Two planes, so that per-plane parameters differ between the groups' views.
            let model = Model::parse_for(&spec, channels, &[0.0, 90.0]).unwrap();
            let planes = model.axes.len();
            for _ in 0..6 {
                let flat = random_params(&model, &mut rng);
                let stride = model.scalar_count();
                let mut views = Vec::new();
                Model::views_into(&flat, &model.slot_table(), &mut views);
                // The views are the per-group scalar views.
                for g in 0..model.groups() {
                    let mut v = Vec::new();
                    model.scalars_into(&flat, g, &mut v);
                    assert_eq!(&views[g * stride..(g + 1) * stride], &v[..], "{spec}");
                }
                let dirs = directions(kind, &mut rng, 40);
                for plane in 0..planes {
                    let c = channels as u32;
                    let base = plane as u32 * c;
                    let all: Vec<u32> = (base..base + c).collect();
                    // Repeated and out-of-order channels, as a data file may list them.
                    let mixed = vec![base + c - 1, base, base + c - 1];
                    for groups in [&all, &mixed] {
                        // All directions in one block, and one direction per call.
                        let n = groups.len();
                        let mut block = vec![f64::NAN; dirs.len() * n];
                        model.eval_channels(&views, groups, &dirs, &mut block);
                        for (d, &(wi, wo)) in dirs.iter().enumerate() {
                            let mut single = vec![f64::NAN; n];
                            model.eval_channels(&views, groups, &[(wi, wo)], &mut single);
                            for (i, &g) in groups.iter().enumerate() {
                                let want = model.eval(&flat, g as usize, wi, wo);
                                for (how, got) in
                                    [("block", block[d * n + i]), ("single", single[i])]
                                {
                                    assert!(
                                        same(got, want),
                                        "{spec} ({channels} ch) group {g} at wi {wi} wo {wo} ({how}): \
                                         together {got:e}, one by one {want:e}; params {flat:?}"
                                    );
                                }
                                compared += 1;
                            }
                        }
                    }
                }
            }
        }
    }
    assert!(compared > 100_000, "only {compared} values compared");
}

/// Nodes without rgb parameters below them are evaluated once for all channels: the
/// flag that decides it must be set exactly for those subtrees.
#[test]
fn uniform_subtrees_are_those_without_rgb_parameters() {
    let m = Model::parse("lambert+mrm+falloff", 3).unwrap();
    let flags: Vec<(&str, bool)> = m
        .nodes()
        .iter()
        .map(|n| (n.bsdf.name(), n.uniform))
        .collect();
    assert_eq!(
        flags,
        [("mrm", false), ("lambert", false), ("falloff", true)]
    );
    let m = Model::parse("btdf(gg)+scale", 1).unwrap();
    assert!(
        m.nodes().iter().all(|n| n.uniform),
        "BTDF parameters are all shared"
    );
}

/// Directions × channels rows on two planes, shuffled (so neither direction-major nor
/// channel-major), with every tenth row measured twice.
fn shuffled_dataset(kind: Kind, seed: u64) -> Dataset {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let wl = [450.0, 550.0, 650.0];
    let mut rows = Vec::new();
    for d in 0..60 {
        let ti: f64 = rng.random_range(0.0..80.0);
        let to: f64 = rng.random_range(1.0..80.0);
        let phi_o = if d % 2 == 0 { 0.0 } else { 90.0 };
        for (c, &w) in wl.iter().enumerate() {
            let value: f64 = rng.random_range(0.01..2.0);
            let row = RawRow {
                theta_i: ti,
                phi_i: 0.0,
                theta_o: to,
                phi_o,
                wavelength_nm: w,
                value,
                uncertainty: value * rng.random_range(0.005..0.05),
            };
            rows.push(row);
            if (d * 3 + c) % 10 == 0 {
                let again = RawRow {
                    value: value * 1.01,
                    ..row
                };
                rows.push(again);
            }
        }
    }
    common::shuffled_dataset(kind, rows, &mut rng, "shuffled")
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    a.is_finite() && b.is_finite() && (a - b).abs() <= rel * a.abs().max(b.abs()) + 1e-300
}

#[test]
fn the_cpu_evaluator_matches_sample_by_sample_evaluation() {
    let cases = [
        (Kind::Brdf, "fa(lambert)"),
        (Kind::Brdf, "rmg(eon)+retro"),
        (Kind::Brdf, "fa(vmf)+mrm82"),
        (Kind::Btdf, "btdf(gg)+scale"),
        (Kind::Btdf, "btdf(tr)+scale+peraxis"),
    ];
    for (kind, spec) in cases {
        let a = shuffled_dataset(kind, 1);
        let b = shuffled_dataset(kind, 2);
        let model = Model::for_data(spec, &a).unwrap();
        assert_eq!(model.channels, 3);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = 7;
        let params: Vec<f64> = (0..n)
            .flat_map(|_| random_params(&model, &mut rng))
            .collect();
        let owners: Vec<usize> = (0..n).map(|i| i % 2).collect();
        // Every loss shape: squares (χ², rmse / f), logarithmic squares, SMAPE.
        let metrics: &[Metric] = match kind {
            Kind::Brdf => &[Metric::Chi2, Metric::Smape, Metric::Ngan],
            Kind::Btdf => &[Metric::Chi2, Metric::Logcosf, Metric::F],
        };
        for &metric in metrics {
            let loss = Loss::new(metric, Weights::Uniform);
            let problems = [
                Problem {
                    model: &model,
                    data: &a,
                    loss,
                },
                Problem {
                    model: &model,
                    data: &b,
                    loss,
                },
            ];
            let cpu = CpuBackend::new();
            let mut eval = cpu.prepare_many(&problems).unwrap();
            let values = eval.values_of(&owners, &params).unwrap();
            let costs = eval.costs_of(&owners, &params).unwrap();
            let mut at = 0;
            for (i, flat) in params.chunks(model.dim).enumerate() {
                let data = problems[owners[i]].data;
                let want: Vec<f64> = data
                    .samples
                    .iter()
                    .map(|s| model.eval(flat, model.group_of(s), s.wi(), s.wo()))
                    .collect();
                let got = &values[at..at + data.len()];
                at += data.len();
                for (k, (&g, &w)) in got.iter().zip(&want).enumerate() {
                    assert!(
                        same(g, w),
                        "{spec} {metric}: candidate {i} sample {k}: {g:e} vs {w:e}"
                    );
                }
                // The cost sums the same terms in direction order: equal to rounding.
                let terms = loss.terms(data);
                let c = terms.loss(&want);
                assert!(
                    close(costs[i], c, 1e-12),
                    "{spec} {metric}: cost {} vs {c}",
                    costs[i]
                );
            }
            assert_eq!(at, values.len());
            if !loss.is_sum_of_squares() {
                continue;
            }
            // Normal equations of one group per problem: the point and its P moves.
            let p = model.dim;
            let mut group_params = Vec::new();
            let mut steps = Vec::new();
            for _ in 0..2 {
                let point = random_params(&model, &mut rng);
                let unit = model.to_unit(&point);
                let h: Vec<f64> = (0..p)
                    .map(|j| if unit[j] > 0.5 { -1e-4 } else { 1e-4 })
                    .collect();
                group_params.extend(&point);
                for j in 0..p {
                    let mut u = unit.clone();
                    u[j] += h[j];
                    group_params.extend(model.from_unit(&u));
                }
                steps.extend(&h);
            }
            let ne = eval
                .normal_equations_of(&[0, 1], &group_params, &steps)
                .unwrap();
            let mut reference_values = Vec::new();
            for (g, flat) in group_params.chunks(p).enumerate() {
                let data = problems[g / (p + 1)].data;
                reference_values.extend(
                    data.samples
                        .iter()
                        .map(|s| model.eval(flat, model.group_of(s), s.wi(), s.wo())),
                );
            }
            let ta = loss.terms(&a);
            let tb = loss.terms(&b);
            let want =
                normal_equations_of_values(&reference_values, &[&ta, &tb], &[0, 1], &steps, p);
            for (got, want) in ne.iter().zip(&want) {
                assert!(
                    close(got.ss, want.ss, 1e-12),
                    "{spec} {metric}: Σr² {} vs {}",
                    got.ss,
                    want.ss
                );
                // Sums over rows in another order: compare on the scale of the products.
                for x in 0..p {
                    let sx = want.jtj[x * p + x].sqrt();
                    let tol = 1e-10 * sx * want.ss.sqrt() + 1e-300;
                    assert!(
                        (got.jtr[x] - want.jtr[x]).abs() <= tol,
                        "{spec} {metric}: Jᵀr[{x}] {} vs {}",
                        got.jtr[x],
                        want.jtr[x]
                    );
                    for y in 0..p {
                        let tol = 1e-10 * sx * want.jtj[y * p + y].sqrt() + 1e-300;
                        assert!(
                            (got.jtj[x * p + y] - want.jtj[x * p + y]).abs() <= tol,
                            "{spec} {metric}: JᵀJ[{x},{y}] {} vs {}",
                            got.jtj[x * p + y],
                            want.jtj[x * p + y]
                        );
                    }
                }
            }
        }
    }
}
