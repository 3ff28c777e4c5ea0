//! Composition of one WGSL module per (model tree, loss shape): WGSL has no function
//! pointers, so the host writes `eval_model` for the tree, calling each node's function
//! (from its `shaders/<model>.wgsl`) with its offset into the scalar view.

use crate::bsdf::{Model, Node};
use crate::engine::loss::{Finish, Term};

pub const COMMON: &str = include_str!("../../shaders/bsdf/common.wgsl");
pub const LOSS: &str = include_str!("../../shaders/engine/loss.wgsl");
pub const KERNEL: &str = include_str!("../../shaders/engine/kernel.wgsl");
pub const NORMAL: &str = include_str!("../../shaders/engine/normal.wgsl");
pub const LANES_PLAIN: &str = include_str!("../../shaders/engine/lanes_plain.wgsl");
pub const LANES_SUBGROUP: &str = include_str!("../../shaders/engine/lanes_subgroup.wgsl");

/// How threads map to work (shaders/engine/lanes_*.wgsl): workgroups of `lanes`
/// candidate lanes × `slices` sample slices, `per_thread` candidates per thread, and
/// whether a subgroup loads samples once per tile and passes them round
/// (lanes_subgroup.wgsl; needs the device's subgroup feature).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Shape {
    pub lanes: u32,
    pub slices: u32,
    pub per_thread: u32,
    pub subgroup_tiles: bool,
}

impl Shape {
    /// SIMD CPU devices (lavapipe) without subgroups: one thread walks all samples of its
    /// candidate, loading each.
    pub const CPU_DEVICE: Shape = Shape {
        lanes: 64,
        slices: 1,
        per_thread: 1,
        subgroup_tiles: false,
    };
    /// SIMD CPU devices with subgroups (lavapipe has them): samples loaded once per
    /// subgroup tile. One candidate per thread: more run faster (4: ggx 1.1e8 → 2.1e8
    /// evals/s on lavapipe, 16: 2.9e8) but lavapipe then takes 13× longer to compile the
    /// pipelines (the parity test of every model: 11 s → 142 s), and they multiply the
    /// loop iterations of a thread, which llvmpipe caps (kernel.wgsl, `loops_completed`).
    pub const CPU_DEVICE_TILED: Shape = Shape {
        lanes: 64,
        slices: 1,
        per_thread: 1,
        subgroup_tiles: true,
    };
    /// Where a CPU device cut a one-slice kernel's loops short (a data set too large for
    /// one thread per candidate; llvmpipe's loop limit, kernel.wgsl `loops_completed`):
    /// 8 candidates × 32 sample slices, reduced in workgroup memory.
    pub const LONG_DATA: Shape = Shape {
        lanes: 8,
        slices: 32,
        per_thread: 1,
        subgroup_tiles: false,
    };
    /// GPUs: 32 candidates × 8 slices, reduced in workgroup memory.
    pub const GPU_DEVICE: Shape = Shape {
        lanes: 32,
        slices: 8,
        per_thread: 1,
        subgroup_tiles: false,
    };

    /// Every shape the engine uses (tests run each code path on any device; subgroup
    /// tiles fall back to the plain walk where the device has no subgroups).
    pub const ALL: [Shape; 4] = [
        Shape::CPU_DEVICE,
        Shape::CPU_DEVICE_TILED,
        Shape::GPU_DEVICE,
        Shape::LONG_DATA,
    ];

    /// Candidates per workgroup.
    pub fn candidates_per_workgroup(&self) -> u32 {
        self.lanes * self.per_thread
    }
}

fn term_code(t: Term) -> u32 {
    match t {
        Term::AbsRatio => 0,
        Term::Square => 1,
        Term::LogSquare => 2,
    }
}

fn finish_code(f: Finish) -> u32 {
    match f {
        Finish::Mean => 0,
        Finish::SqrtMean => 1,
        Finish::Sum => 2,
    }
}

/// The generated `eval_model`: children first (post-order), then each combinator.
pub fn eval_model_source(model: &Model) -> String {
    fn emit(node: &Node, body: &mut String, counter: &mut usize) -> String {
        let args: Vec<String> = node
            .children
            .iter()
            .map(|c| emit(c, body, counter))
            .collect();
        let name = format!("v{}", *counter);
        *counter += 1;
        let w = node.bsdf.wgsl();
        let mut call = format!("{}(b + {}u, wi, wo", w.function, node.offset);
        for a in &args {
            call += ", ";
            call += a;
        }
        call += ")";
        body.push_str(&format!("    let {name} = {call};\n"));
        name
    }
    let mut body = String::new();
    let mut counter = 0;
    let root = emit(&model.root, &mut body, &mut counter);
    format!(
        "// Generated for `{}`: b is the channel's base index into P.\nfn eval_model(wi: vec3<f32>, wo: vec3<f32>, b: u32) -> f32 {{\n{body}    return {root};\n}}\n",
        model.spec
    )
}

/// Parameter accessors generated from a node's declarations: `fn <prefix>_<name>(o: u32)
/// -> f32` returns the parameter `name` of the node whose scalar view starts at `o`, with
/// `<prefix>` the node's WGSL function name without `_eval` and dots in role-prefixed
/// names written as `_` (`fa_lobe_alpha`). The WGSL twins read their parameters only
/// through these, so Rust and WGSL cannot disagree on the order.
pub fn accessors_source(node: &Node) -> String {
    let w = node.bsdf.wgsl();
    let prefix = w.function.strip_suffix("_eval").unwrap_or(&w.function);
    let mut src = String::new();
    for (k, p) in node.bsdf.params().iter().enumerate() {
        src += &format!(
            "fn {prefix}_{}(o: u32) -> f32 {{ return P[o + {k}u]; }}\n",
            p.name.replace('.', "_")
        );
    }
    src
}

/// The accessors of every node function of the catalogue (a shader file may define several,
/// e.g. every `btdf(·)` variant, and is included whole): generated once from the
/// declarations of every spec the registry derives.
pub fn all_accessors() -> &'static str {
    static ALL: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    ALL.get_or_init(|| {
        let mut done: Vec<String> = Vec::new();
        let mut src =
            String::from("\n// ---- parameter accessors (generated from the declarations)\n");
        for kind in [crate::data::Kind::Brdf, crate::data::Kind::Btdf] {
            for spec in crate::bsdf::every_spec(kind) {
                let Ok(model) = Model::parse(&spec, 1) else {
                    continue;
                };
                for node in model.nodes() {
                    let function = node.bsdf.wgsl().function;
                    if !done.contains(&function) {
                        src += &accessors_source(node);
                        done.push(function);
                    }
                }
            }
        }
        src
    })
}

/// How many numbers the `normal` pass (shaders/engine/normal.wgsl) writes per group of
/// P + 1 candidates: the upper triangle of JᵀJ, Jᵀr and Σr².
pub fn normal_entries(p: usize) -> usize {
    p * (p + 1) / 2 + p + 1
}

/// Threads along the rows of one `normal` workgroup (one row of the (P + 1)² Gram matrix
/// of the residual factors each): enough for every row, in multiples of 8 (a SIMD width
/// of CPU devices), at most the shape's lanes, so that a workgroup of lanes × slices
/// threads stays within WebGPU's 256 invocations.
pub fn normal_lanes(p: usize, shape: Shape) -> u32 {
    ((p + 1).next_multiple_of(8) as u32).min(shape.lanes)
}

/// The full module for a model and a loss shape.
pub fn compose(model: &Model, term: Term, finish: Finish, shape: Shape) -> String {
    let s = model.scalar_count();
    // C counts scalar-view groups: channels, times planes under `+peraxis`.
    let c = model.groups();
    let p = model.dim;
    let mut src = format!(
        "// bsdfit kernel module for `{}`, {} channel(s)\nconst S: u32 = {s}u;\nconst C: u32 = {c}u;\nconst CL: u32 = {}u;\nconst SL: u32 = {}u;\nconst CPT: u32 = {}u;\nconst TERM: u32 = {}u;\nconst FINISH: u32 = {}u;\nconst PD: u32 = {p}u;\nconst NJJ: u32 = {}u;\nconst NE: u32 = {}u;\nconst EL: u32 = {}u;\nconst NB: u32 = {}u;\nvar<private> P: array<f32, {}>;\n\n",
        model.spec,
        c,
        shape.lanes,
        shape.slices,
        shape.per_thread,
        term_code(term),
        finish_code(finish),
        p * (p + 1) / 2,
        normal_entries(p),
        normal_lanes(p, shape),
        (p + 1).div_ceil(normal_lanes(p, shape) as usize),
        (s * c * shape.per_thread as usize).max(1)
    );
    src += COMMON;
    src += all_accessors();
    let mut included: Vec<&str> = Vec::new();
    for node in model.nodes() {
        for (name, text) in node.bsdf.wgsl().sources {
            if !included.contains(&name) {
                included.push(name);
                src += &format!("\n// ---- shaders/{name}.wgsl\n");
                src += text;
            }
        }
    }
    src += "\n";
    src += &eval_model_source(model);
    src += "\n";
    src += LOSS;
    src += "\n";
    src += KERNEL;
    src += "\n";
    src += if shape.subgroup_tiles {
        LANES_SUBGROUP
    } else {
        LANES_PLAIN
    };
    src += "\n";
    src += NORMAL;
    src
}

/// Parse and validate a module with naga (no device needed).
pub fn validate(source: &str) -> Result<naga::Module, String> {
    let module = naga::front::wgsl::parse_str(source).map_err(|e| e.emit_to_string(source))?;
    let mut v = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        // Subgroup operations appear only in modules for devices that have them.
        naga::valid::Capabilities::SUBGROUP,
    );
    v.validate(&module).map_err(|e| e.emit_to_string(source))?;
    Ok(module)
}
