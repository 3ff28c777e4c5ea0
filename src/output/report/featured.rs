//! Which fits the report features for a data set: the weighting comparison, the top
//! models (BRDF) or NDF families (BTDF), and the suffix comparison (BTDF).

use super::inputs::DataInfo;
use crate::data::Kind;
use crate::output::results::{self, Row};
use std::collections::{BTreeMap, BTreeSet};

/// Featured fits of one data set.
#[derive(Default)]
pub(super) struct Featured<'a> {
    /// The best model's fits under uniform and uncertainty weights (same loss, optimizer).
    pub(super) weights: Option<(&'a Row, &'a Row)>,
    /// Models compared side by side / overlaid.
    pub(super) models: Vec<&'a Row>,
    /// BTDF: plain, +scale, +absorb of the best family.
    pub(super) suffixes: Vec<&'a Row>,
}

/// A spec without its suffixes (`btdf(tr)+scale` → `btdf(tr)`): the model family, read
/// from the spec's syntax rather than guessed from its text.
fn ndf_family(model: &str) -> String {
    match crate::bsdf::spec::Ast::parse(model) {
        Ok(mut ast) => {
            while let crate::bsdf::spec::Ast::Suffix { inner, .. } = ast {
                ast = *inner;
            }
            crate::bsdf::spec::render_spec(&ast)
        }
        Err(_) => model.to_string(),
    }
}

pub(super) fn featured<'a>(rk: &results::Ranking<'a>, kind: Kind) -> Featured<'a> {
    let mut f = Featured::default();
    let rows = |m: &str| {
        rk.models
            .iter()
            .find(|x| x.0 == m)
            .map(|x| x.1.iter().flatten().copied().collect::<Vec<&Row>>())
            .unwrap_or_default()
    };
    // Primary column: the first uniform one (columns sort uniform first within a loss,
    // and chi2 last).
    let Some(primary) = rk
        .columns
        .iter()
        .find(|c| c.1 == "uniform")
        .or(rk.columns.first())
        .cloned()
    else {
        return f;
    };
    let in_col = |r: &&Row, c: &(String, String, String)| {
        r.loss == c.0 && r.weights == c.1 && r.optimizer == c.2
    };
    // Best model that has both a uniform and a weighted fit with the same loss/optimizer.
    'outer: for (m, _, _) in &rk.models {
        let rs = rows(m);
        for u in rs.iter().filter(|r| r.weights == "uniform") {
            if let Some(w) = rs
                .iter()
                .find(|r| r.weights != "uniform" && r.loss == u.loss && r.optimizer == u.optimizer)
            {
                f.weights = Some((u, w));
                break 'outer;
            }
        }
    }
    let prim: Vec<&Row> = rk
        .models
        .iter()
        .filter_map(|(m, _, _)| rows(m).into_iter().find(|r| in_col(r, &primary)))
        .collect();
    match kind {
        Kind::Brdf => f.models = prim.iter().take(2).copied().collect(),
        Kind::Btdf => {
            let mut fams = BTreeSet::new();
            for r in &prim {
                if fams.insert(ndf_family(&r.model)) {
                    f.models.push(r);
                }
            }
            f.models.truncate(4);
            if let Some(best) = prim.first() {
                let fam = ndf_family(&best.model);
                // The family alone, then with each suffix the catalogue gives it.
                let suffixes = crate::bsdf::registry::catalogue_suffixes(Kind::Btdf);
                let specs = std::iter::once(fam.clone())
                    .chain(suffixes.iter().map(|s| format!("{fam}+{s}")));
                for m in specs {
                    if let Some(r) = prim.iter().find(|r| r.model == m) {
                        f.suffixes.push(r);
                    }
                }
                if f.suffixes.len() < 2 {
                    f.suffixes.clear();
                }
            }
        }
    }
    f
}

impl<'a> Featured<'a> {
    /// The featured fits the page shows renders of: for a BRDF, the weighting pair, then
    /// the top models; none for a BTDF.
    pub(super) fn to_render(&self, kind: Kind) -> Vec<&'a Row> {
        if kind != Kind::Brdf {
            return Vec::new();
        }
        let mut rows: Vec<&'a Row> = self.weights.map(|(u, w)| vec![u, w]).unwrap_or_default();
        rows.extend(self.models.iter().copied());
        rows
    }
}

/// Sampling geometry (paper Fig. 1): for each BRDF material with more than one data set,
/// the top models of its baseline (its richest data set) as fitted to each of its data
/// sets with the same loss, weights and optimizer, all to be rendered against the same
/// baseline.
pub(super) fn sampling_sets<'a>(
    baseline_of: &BTreeMap<String, String>,
    datas: &BTreeMap<String, DataInfo>,
    feats: &BTreeMap<String, Featured<'a>>,
    cur: &[&'a Row],
) -> Vec<(String, Vec<&'a Row>)> {
    let mut sampling: Vec<(String, Vec<&Row>)> = Vec::new();
    for (material, base) in baseline_of {
        let members: Vec<&String> = datas
            .values()
            .filter(|d| d.data.as_ref().is_some_and(|x| &x.material == material))
            .map(|d| &d.name)
            .collect();
        if members.len() < 2 {
            continue;
        }
        let Some(f) = feats.get(base) else { continue };
        let mut list = Vec::new();
        for top in f.models.iter() {
            for m in &members {
                if let Some(r) = cur.iter().find(|r| {
                    &&r.data == m
                        && r.model == top.model
                        && r.loss == top.loss
                        && r.weights == top.weights
                        && r.optimizer == top.optimizer
                }) {
                    list.push(*r);
                }
            }
        }
        sampling.push((material.clone(), list));
    }
    sampling
}
