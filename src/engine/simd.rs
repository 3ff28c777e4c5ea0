//! The SIMD CPU engine: the CPU reference's evaluator (directions grouped by channels,
//! blocks, windows, the same streamed reductions in f64) with model values computed in
//! SIMD lanes of eight f32 or four f64 directions ([`crate::math::lanes`]) from the
//! same model source as the reference ([`crate::bsdf::kernel`]).
//!
//! **Precision.** A model runs in f32 lanes (the GPU engine's arithmetic, and its
//! accuracy contract: `tests/simd_parity.rs` holds it to the GPU parity bounds) unless
//! one of its nodes declares that it needs f64 ([`crate::bsdf::Model::lane_kind`]).
//! Losses and normal equations are summed in f64, as on the reference.
//!
//! **Where it is used.** `--backend simd`, and `--backend auto` where no hardware GPU
//! exists (a CPU-only cluster node, or a machine whose only Vulkan device is a
//! software rasterizer such as lavapipe).

use super::cpu::{Arith, CpuEvaluator};
use super::{Backend, Evaluator, Problem};
use crate::bsdf::kernel::LaneKind;
use crate::math::lanes::instruction_set;

/// The SIMD CPU engine.
#[derive(Debug, Default, Clone)]
pub struct SimdBackend {
    /// Lanes for every model, whatever its nodes ask for (tests of the f64 lanes).
    lanes: Option<LaneKind>,
}

impl SimdBackend {
    pub fn new() -> Self {
        SimdBackend { lanes: None }
    }

    /// The engine with every model in the lanes `kind` (f64 lanes give the reference's
    /// values bit for bit: `tests/simd_parity.rs`).
    pub fn with_lanes(kind: LaneKind) -> Self {
        SimdBackend { lanes: Some(kind) }
    }
}

impl Backend for SimdBackend {
    fn name(&self) -> String {
        format!(
            "simd ({} lanes, rayon, {} threads)",
            instruction_set(),
            rayon::current_num_threads()
        )
    }
    fn id(&self) -> &'static str {
        "simd"
    }
    /// f32's: most models run in f32 lanes, and finite differences must step above it.
    fn unit_roundoff(&self) -> f64 {
        f32::EPSILON as f64 / 2.0
    }
    fn prepare_many<'a>(
        &'a self,
        problems: &[Problem<'a>],
    ) -> anyhow::Result<Box<dyn Evaluator + 'a>> {
        let model = problems
            .first()
            .ok_or_else(|| anyhow::anyhow!("no problem to evaluate"))?
            .model;
        let kind: LaneKind = self.lanes.unwrap_or_else(|| model.lane_kind());
        Ok(Box::new(CpuEvaluator::new(problems, Arith::Lanes(kind))?))
    }
}
