//! The diagnosis as JSON: docs/output.md's contract and the candidate tables of `--report`.

use super::Diagnosis;
use serde_json::{json, Value};

impl Diagnosis {
    /// docs/output.md: `{start_model, final_model, effects, steps: [{model, effect, chi2_red,
    /// loss, evidence}]}`, and `removed` on a step of the backward elimination.
    pub fn to_json(&self) -> Value {
        json!({
            "start_model": self.start_model,
            "final_model": self.final_model,
            "effects": self.effects.iter().map(|e| e.name()).collect::<Vec<_>>(),
            "steps": self.steps.iter().map(|s| {
                let mut step = json!({
                    "model": s.model,
                    "effect": s.effect.map(|e| e.name()),
                    "chi2_red": num(s.chi2_red),
                    "loss": num(s.loss),
                    "evidence": s.evidence,
                });
                // Only the backward elimination's step has it: the contract's steps are
                // unchanged.
                if !s.removed.is_empty() {
                    step["removed"] = json!(s.removed.iter().map(|e| e.name()).collect::<Vec<_>>());
                }
                step
            }).collect::<Vec<_>>(),
        })
    }

    /// Every candidate of every round (for `--report`).
    pub fn candidates_json(&self) -> Value {
        Value::Array(
            self.steps
                .iter()
                .enumerate()
                .map(|(i, s)| {
                    json!({
                        "after_step": i,
                        "current": s.model,
                        "seconds": s.round_seconds,
                        "candidates": s.candidates.iter().map(|c| json!({
                            "model": c.candidate.spec,
                            "effect": c.candidate.effect.name(),
                            "nested": c.candidate.nested,
                            "chi2_red": c.fit.as_ref().map(|f| num(f.chi2_red)),
                            "extra_params": c.dp,
                            "delta_chi2": num(c.delta_chi2),
                            "F": c.f.map(num),
                            "p": c.p.map(num),
                            "p_nominal_F": c.p_nominal.map(num),
                            "p_test": c.p_test.to_json(),
                            "p_test_description": c.p_test.describe(),
                            "irregular_null": c.irregular,
                            "level": num(c.level),
                            "delta_bic": num(c.delta_bic),
                            "delta_bic_scaled": num(c.delta_bic_scaled),
                            "significant": c.significant,
                            "identifiable": c.identifiable,
                            "on_bound": c.on_bound,
                            "removal_in_flagged_regions": c.removal_flagged.map(num),
                            "removal_outside": c.removal_outside.map(num),
                            "removal_by_region": c.removal.iter().map(|(w, r)| json!({"region": w, "removed": num(*r)})).collect::<Vec<_>>(),
                            "frame_test": c.frame_test.as_ref().map(|m| m.to_json()),
                            "too_wide": c.too_wide,
                            "adoptable": c.adoptable(),
                            "verdict": c.verdict,
                        })).collect::<Vec<_>>(),
                    })
                })
                .collect(),
        )
    }
}

fn num(v: f64) -> Value {
    serde_json::Number::from_f64(v)
        .map(Value::Number)
        .unwrap_or(Value::Null)
}
