//! The optimizers' view of an evaluator: unit-box points of the free parameters, their
//! costs, residuals and normal equations (priors included).

use crate::bsdf::Model;
use crate::engine::loss::Finisher;
use crate::engine::Evaluator;
use crate::inference::constraints::Constraints;
use crate::optim::{BatchObjective, BatchResiduals};

/// Adapts an evaluator (physical parameters) to the optimizers' unit box.
/// The optimizers see the free parameters only ([`Constraints`]); priors add residuals.
/// An evaluator holding several problems is shared by all their restarts: `start_problem`
/// says which problem each start (restart) belongs to.
pub struct UnitBox<'m, 'e> {
    pub model: &'m Model,
    pub space: &'m Constraints,
    pub eval: &'m mut (dyn Evaluator + 'e),
    /// How each problem's sums of terms become its loss (term shape, finish, K).
    pub finishers: Vec<Finisher>,
    /// The problem of each start; empty when every start belongs to problem 0.
    pub start_problem: Vec<usize>,
}

impl UnitBox<'_, '_> {
    pub(super) fn to_physical(&self, points: &[f64]) -> Vec<f64> {
        points
            .chunks(self.space.dim())
            .flat_map(|u| self.space.from_unit(u))
            .collect()
    }

    fn problems_of(&self, owners: &[usize]) -> Vec<usize> {
        owners
            .iter()
            .map(|&s| self.start_problem.get(s).copied().unwrap_or(0))
            .collect()
    }

    /// Costs of unit-box points, `problems[i]` the problem of point i.
    pub fn problem_costs(
        &mut self,
        problems: &[usize],
        points: &[f64],
    ) -> anyhow::Result<Vec<f64>> {
        let phys = self.to_physical(points);
        let mut costs = self.eval.costs_of(problems, &phys)?;
        if self.space.prior_rows() > 0 {
            // Priors come with the χ² loss only, whose cost is the plain sum of squares.
            for (c, flat) in costs.iter_mut().zip(phys.chunks(self.model.dim)) {
                *c += self.space.prior_chi2(flat);
            }
        }
        Ok(costs)
    }

    /// Residual rows (data, then priors) of physical points, `problems[i]` the problem of
    /// point i; the rows one after the other, each point's data residuals in its
    /// evaluator's row order. Holds points × samples: for tests and small batches only
    /// (the optimizers use the streamed sums of [`Self::normal_equations_of`]).
    fn problem_residuals(
        &mut self,
        problems: &[usize],
        phys: &[f64],
    ) -> anyhow::Result<Vec<Vec<f64>>> {
        let mut rows: Vec<Vec<f64>> = problems
            .iter()
            .map(|&q| Vec::with_capacity(self.eval.samples_of(q) + self.space.prior_rows()))
            .collect();
        self.eval.value_windows(problems, phys, &mut |w| {
            for part in w.parts {
                let t = &w.rows[part.problem];
                let v = w.values_of(part);
                let row = &mut rows[part.candidate];
                for (i, r) in part.rows.clone().enumerate() {
                    if t.sample[r] != crate::engine::loss::NO_SAMPLE {
                        row.push(t.terms.residual(r, v.at(i)));
                    }
                }
            }
            Ok(())
        })?;
        for (row, flat) in rows.iter_mut().zip(phys.chunks(self.model.dim)) {
            row.extend(self.space.prior_residuals(flat));
        }
        Ok(rows)
    }
}

impl BatchObjective for UnitBox<'_, '_> {
    fn dim(&self) -> usize {
        self.space.dim()
    }
    fn costs(&mut self, points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let n = points.len() / self.space.dim().max(1);
        self.problem_costs(&vec![0; n], points)
    }
    fn costs_of(&mut self, owners: &[usize], points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let problems = self.problems_of(owners);
        self.problem_costs(&problems, points)
    }
}

impl BatchResiduals for UnitBox<'_, '_> {
    fn residuals(&mut self, points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let n = points.len() / self.space.dim().max(1);
        let phys = self.to_physical(points);
        Ok(self.problem_residuals(&vec![0; n], &phys)?.concat())
    }
    fn residual_count(&self) -> usize {
        self.eval.samples_of(0) + self.space.prior_rows()
    }
    fn normal_equations(
        &mut self,
        points: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<crate::optim::NormalEquations>> {
        let n = points.len() / self.space.dim().max(1);
        let every: Vec<usize> = vec![0; n];
        self.normal_equations_of(&every, points, steps)
    }
    /// Reduced by the backend where it evaluates the model, over the free parameters
    /// (the moved points move free parameters only); each prior adds one residual row,
    /// whose share is added here.
    fn normal_equations_of(
        &mut self,
        owners: &[usize],
        points: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<crate::optim::NormalEquations>> {
        let p = self.space.dim();
        let problems = self.problems_of(owners);
        let unit = crate::optim::difference_points(points, steps, p);
        let phys = self.to_physical(&unit);
        let mut normal = self.eval.normal_equations_of(&problems, &phys, steps)?;
        if self.space.prior_rows() > 0 {
            let dim = self.model.dim;
            for ((ne, group), h) in normal
                .iter_mut()
                .zip(phys.chunks(dim * (p + 1)))
                .zip(steps.chunks(p))
            {
                let rows: Vec<Vec<f64>> = group
                    .chunks(dim)
                    .map(|flat| self.space.prior_residuals(flat).collect())
                    .collect();
                ne.add_rows(&rows[0], &rows[1..], h);
            }
        }
        Ok(normal)
    }
    fn sum_squares_of(&mut self, owners: &[usize], points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let problems = self.problems_of(owners);
        let phys = self.to_physical(points);
        let squares = problems
            .iter()
            .all(|&q| self.finishers.get(q).is_some_and(|f| f.is_sum_of_squares()));
        if !squares {
            return Ok(self
                .problem_residuals(&problems, &phys)?
                .iter()
                .map(|r| crate::optim::sanitize(r.iter().map(|v| v * v).sum()))
                .collect());
        }
        // A sum-of-squares loss's terms are the squared residuals, w (g(y′) − g(y))², so
        // the data part of Σr² is the loss's own sum: one number per point from the
        // evaluator (reduced on the device by the GPU engine) instead of K model values
        // read back.
        let costs = self.eval.costs_of(&problems, &phys)?;
        Ok(costs
            .iter()
            .zip(&problems)
            .zip(phys.chunks(self.model.dim))
            .map(|((&c, &q), flat)| {
                let data = self.finishers[q].sum_of(c);
                crate::optim::sanitize(data + self.space.prior_chi2(flat))
            })
            .collect())
    }
    fn sum_squares(&mut self, points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let n = points.len() / self.space.dim().max(1);
        self.sum_squares_of(&vec![0; n], points)
    }
}
