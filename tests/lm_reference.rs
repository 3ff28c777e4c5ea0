//! Our batched Levenberg–Marquardt against an independent implementation, the
//! `levenberg-marquardt` crate (a MINPACK port), on the same problems and starts.
//! Both must reach the same minimum: cost within 1e-6 relative (+1e-12 absolute) and
//! parameters within 1e-4 in the unit box.

mod common;

use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::Backend;
use bsdfit::engine::Problem;
use bsdfit::inference::fit::UnitBox;
use bsdfit::optim::lm::{minimize, LmOptions};
use bsdfit::optim::{BatchObjective, BatchResiduals};
use common::synth_geometry;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use std::cell::RefCell;

/// The reference crate's view of a residual function (Jacobian by central differences).
struct Reference<'a> {
    x: DVector<f64>,
    f: &'a dyn Fn(&[f64]) -> Vec<f64>,
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Reference<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;
    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
    }
    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }
    fn residuals(&self) -> Option<DVector<f64>> {
        Some(DVector::from_vec((self.f)(self.x.as_slice())))
    }
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let p = self.x.len();
        let k = (self.f)(self.x.as_slice()).len();
        let mut j = DMatrix::zeros(k, p);
        for c in 0..p {
            let h = 1e-7;
            let mut up = self.x.clone();
            let mut dn = self.x.clone();
            up[c] += h;
            dn[c] -= h;
            let (ru, rd) = ((self.f)(up.as_slice()), (self.f)(dn.as_slice()));
            for r in 0..k {
                j[(r, c)] = (ru[r] - rd[r]) / (2.0 * h);
            }
        }
        Some(j)
    }
}

/// Residuals of a closure, batched for our LM.
struct Batched<'a> {
    dim: usize,
    k: usize,
    f: &'a dyn Fn(&[f64]) -> Vec<f64>,
}

impl BatchObjective for Batched<'_> {
    fn dim(&self) -> usize {
        self.dim
    }
    fn costs(&mut self, pts: &[f64]) -> anyhow::Result<Vec<f64>> {
        Ok(pts
            .chunks(self.dim)
            .map(|x| (self.f)(x).iter().map(|r| r * r).sum())
            .collect())
    }
}

impl BatchResiduals for Batched<'_> {
    fn residuals(&mut self, pts: &[f64]) -> anyhow::Result<Vec<f64>> {
        Ok(pts.chunks(self.dim).flat_map(|x| (self.f)(x)).collect())
    }
    fn residual_count(&self) -> usize {
        self.k
    }
}

fn compare(name: &str, dim: usize, start: &[f64], f: &dyn Fn(&[f64]) -> Vec<f64>) {
    let k = f(start).len();
    let mut ours = Batched { dim, k, f };
    let opts = LmOptions {
        fd_step: 1e-7,
        ..Default::default()
    };
    let out = minimize(&mut ours, &[start.to_vec()], &opts, &|_, s| s, &mut |_| {}).unwrap();
    let (reference, report) = LevenbergMarquardt::new().minimize(Reference {
        x: DVector::from_column_slice(start),
        f,
    });
    let ref_cost: f64 = f(reference.x.as_slice()).iter().map(|r| r * r).sum();
    eprintln!(
        "{name}: ours {:.6e} at {:?}; reference {ref_cost:.6e} at {:?} ({:?})",
        out[0].cost,
        out[0].x,
        reference.x.as_slice(),
        report.termination
    );
    assert!(out[0].cost.is_finite() && ref_cost.is_finite());
    assert!(
        (out[0].cost - ref_cost).abs() <= 1e-6 * ref_cost + 1e-12,
        "{name}: cost {} vs reference {ref_cost}",
        out[0].cost
    );
    for (a, b) in out[0].x.iter().zip(reference.x.iter()) {
        assert!(
            (a - b).abs() < 1e-4,
            "{name}: parameters {:?} vs reference {:?}",
            out[0].x,
            reference.x.as_slice()
        );
    }
}

#[test]
fn rosenbrock_in_the_unit_box() {
    // x = 4u − 2 maps the box to [−2, 2]²; the minimum (1, 1) sits at u = (0.75, 0.75).
    let f = |u: &[f64]| {
        let (x, y) = (4.0 * u[0] - 2.0, 4.0 * u[1] - 2.0);
        vec![10.0 * (y - x * x), 1.0 - x]
    };
    compare("rosenbrock", 2, &[0.3, 0.8], &f);
}

#[test]
fn exponential_decay_with_offset() {
    let t: Vec<f64> = (0..30).map(|i| i as f64 * 0.1).collect();
    let y: Vec<f64> = t
        .iter()
        .map(|t| 0.8 * (-1.7 * t).exp() + 0.1 + 0.002 * (7.0 * t).sin())
        .collect();
    let f = move |u: &[f64]| {
        t.iter()
            .zip(&y)
            .map(|(t, y)| u[0] * (-3.0 * u[1] * t).exp() + u[2] - y)
            .collect::<Vec<f64>>()
    };
    compare("decay", 3, &[0.5, 0.5, 0.5], &f);
}

/// Oren–Nayar (RGB ρ, σ = 0.6) on the paper's in-plane geometry, 1.5 % noise.
fn oren_nayar_data() -> (bsdfit::bsdf::Model, bsdfit::data::Dataset) {
    let (model, _, data) = synth_geometry(
        "on",
        "rho=0.3:0.5:0.7,sigma=0.6",
        "inplane10",
        &[450.0, 550.0, 650.0],
        (0.015, 1e-4),
        4,
    );
    (model, data)
}

#[test]
fn oren_nayar_brdf_fit() {
    // A real fitting problem: Oren–Nayar on synthetic in-plane data, residuals from the
    // CPU backend through the optimizers' unit box (RMSE loss, uniform weights).
    let (model, data) = oren_nayar_data();
    let loss = Loss::new(Metric::Rmse, Weights::Uniform);
    let cpu = CpuBackend::new();
    let mut eval = cpu
        .prepare(Problem {
            model: &model,
            data: &data,
            loss,
        })
        .unwrap();
    let space = bsdfit::inference::constraints::Constraints::none(&model);
    let obj = RefCell::new(UnitBox {
        model: &model,
        space: &space,
        eval: eval.as_mut(),
        finishers: vec![loss.finisher(&data)],
        start_problem: vec![],
    });
    let f = |u: &[f64]| obj.borrow_mut().residuals(u).unwrap();
    compare("oren-nayar", model.dim, &[0.5, 0.5, 0.5, 0.5], &f);
}

#[test]
fn sums_of_squares_come_from_the_loss_sum() {
    // `sum_squares_of` takes Σr² from the evaluator's loss sum (one number per point)
    // instead of K residuals. It must equal Σ of the squared residual rows, priors
    // included, for every finish of a sum-of-squares loss (Σ, mean, √mean) and the
    // logarithmic term, on both backends. Tolerance: 1e-10 relative on the CPU (f64, a
    // different summation order), 1e-5 on the GPU (f32 costs against f32 values summed
    // in f64). NaN never passes.
    let (model, data) = oren_nayar_data();
    let (btdf_model, _, btdf_data) = synth_geometry(
        "btdf(tr)+scale",
        "scale=0.8,alpha=0.2,eta=1.5",
        "oblique",
        &[633.0],
        (0.02, 1e-4),
        2,
    );
    let spec =
        bsdfit::inference::constraints::ConstraintSpec::parse(&[], &[], &["sigma=0.5:0.1"], false)
            .unwrap();
    let on_prior =
        bsdfit::inference::constraints::Constraints::resolve(&model, &spec, false).unwrap();
    let gpu = bsdfit::engine::gpu::GpuBackend::new().expect("a Vulkan adapter (lavapipe in CI)");
    let cpu = CpuBackend::new();
    let backends: [(&dyn Backend, f64); 2] = [(&cpu, 1e-10), (&gpu, 1e-5)];
    for (backend, tol) in backends {
        let cases = [
            (&model, &data, Metric::Chi2, Some(&on_prior)),
            (&model, &data, Metric::Rmse, None),
            (&model, &data, Metric::Ngan, None),
            (&btdf_model, &btdf_data, Metric::Logcosf, None),
            (&btdf_model, &btdf_data, Metric::F, None),
        ];
        for (m, d, metric, prior) in cases {
            let none = bsdfit::inference::constraints::Constraints::none(m);
            let space = prior.unwrap_or(&none);
            let loss = Loss::new(metric, Weights::Invunc);
            let mut eval = backend
                .prepare(Problem {
                    model: m,
                    data: d,
                    loss,
                })
                .unwrap();
            let mut obj = UnitBox {
                model: m,
                space,
                eval: eval.as_mut(),
                finishers: vec![loss.finisher(d)],
                start_problem: vec![],
            };
            let dim = space.dim();
            let points: Vec<f64> = (0..4)
                .flat_map(|i| (0..dim).map(move |j| 0.2 + 0.15 * ((i + j) % 5) as f64))
                .collect();
            let sums = obj.sum_squares(&points).unwrap();
            let rows = obj.residuals(&points).unwrap();
            let per_point = rows.len() / 4;
            for (i, s) in sums.iter().enumerate() {
                let reference: f64 = rows[i * per_point..(i + 1) * per_point]
                    .iter()
                    .map(|r| r * r)
                    .sum();
                assert!(
                    s.is_finite() && (s - reference).abs() <= tol * reference,
                    "{} {metric:?} on {}: Σr² {s}, from the residuals {reference}",
                    m.spec,
                    backend.id()
                );
            }
        }
    }
}
