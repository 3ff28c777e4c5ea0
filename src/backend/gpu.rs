//! Placeholder for the GPU engine (being implemented).
use super::{Backend, Evaluator, Problem};

pub struct GpuBackend;

impl GpuBackend {
    pub fn new() -> anyhow::Result<Self> {
        anyhow::bail!("the GPU engine is not built yet")
    }
}

impl Backend for GpuBackend {
    fn name(&self) -> String {
        "gpu".into()
    }
    fn id(&self) -> &'static str {
        "gpu"
    }
    fn prepare<'a>(&'a self, _problem: Problem<'a>) -> anyhow::Result<Box<dyn Evaluator + 'a>> {
        anyhow::bail!("the GPU engine is not built yet")
    }
}
