//! Composition of one WGSL module per (model tree, loss shape): WGSL has no function
//! pointers, so the host writes `eval_model` for the tree, calling each node's function
//! (from its `shaders/<model>.wgsl`) with its offset into the scalar view.

use crate::bsdf::{Model, Node};
use crate::engine::loss::Term;

pub const COMMON: &str = include_str!("../../shaders/bsdf/common.wgsl");
pub const LOSS: &str = include_str!("../../shaders/engine/loss.wgsl");
pub const KERNEL: &str = include_str!("../../shaders/engine/kernel.wgsl");
pub const NORMAL: &str = include_str!("../../shaders/engine/normal.wgsl");
pub const LANES_PLAIN: &str = include_str!("../../shaders/engine/lanes_plain.wgsl");
pub const LANES_SUBGROUP: &str = include_str!("../../shaders/engine/lanes_subgroup.wgsl");

/// How threads map to work (shaders/engine/lanes_*.wgsl): workgroups of `lanes`
/// candidate lanes × `slices` record slices, and whether a subgroup loads records once
/// per tile and passes them round (lanes_subgroup.wgsl; needs the device's subgroup
/// feature); and what the kernels may assume of the batch's data (`mu_tables`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Shape {
    pub lanes: u32,
    pub slices: u32,
    pub subgroup_tiles: bool,
    /// Models compute per candidate, before the record loop, what depends on the polar
    /// cosine μ alone, at every μ of the candidate's problem (its μ table, kernel.wgsl),
    /// and look it up per record: micrograin's G1(μ)/μ, whose Λ series is a loop, VMF's
    /// cross sections σ(±μ), whose Legendre series is one, and GG transmission's G1(μ)/μ,
    /// 16 texel fetches of its Λ table each. A loop inside the record
    /// loop cost lavapipe far more than its trips: `rmg(ggx)` ran at 1.2e8 evaluations/s
    /// with its series behind a memo, 2.1–2.4e8 with the table; `vmf` 1.6e8 → 2.7e8
    /// (`bsdfit bench`, bundled W80&G40 data). Set per batch ([`Shape::for_batch`]): only
    /// where every problem has a table (at most `MU_TABLE_LEN` distinct cosines; none
    /// for, say, a MERL subsample) and one thread walks all of a candidate's records
    /// (`slices` = 1), since each slice's thread would fill the tables again. Without it
    /// the models compute those factors per record; the fallback is compiled
    /// out where the tables are used, its mere presence in the record loop costing as
    /// much as the loop itself.
    pub mu_tables: bool,
}

impl Shape {
    /// SIMD CPU devices (lavapipe) without subgroups: one thread walks all samples of its
    /// candidate, loading each.
    pub const CPU_DEVICE: Shape = Shape {
        lanes: 64,
        slices: 1,
        subgroup_tiles: false,
        mu_tables: true,
    };
    /// SIMD CPU devices with subgroups (lavapipe has them): records loaded once per
    /// subgroup tile.
    pub const CPU_DEVICE_TILED: Shape = Shape {
        lanes: 64,
        slices: 1,
        subgroup_tiles: true,
        mu_tables: true,
    };
    /// GPUs: 32 candidates × 8 slices, reduced in workgroup memory.
    pub const GPU_DEVICE: Shape = Shape {
        lanes: 32,
        slices: 8,
        subgroup_tiles: false,
        mu_tables: false,
    };

    /// Every shape the engine uses (tests run each code path on any device; subgroup
    /// tiles fall back to the plain walk where the device has no subgroups).
    pub const ALL: [Shape; 3] = [
        Shape::CPU_DEVICE,
        Shape::CPU_DEVICE_TILED,
        Shape::GPU_DEVICE,
    ];

    /// Candidates per workgroup.
    pub fn candidates_per_workgroup(&self) -> u32 {
        self.lanes
    }

    /// This shape with `mu_tables` set to `yes`.
    pub fn with_mu_tables(self, yes: bool) -> Shape {
        Shape {
            mu_tables: yes,
            ..self
        }
    }

    /// This thread mapping for a batch whose problems all have μ tables or not:
    /// `mu_tables` where they do and one thread walks a candidate's records.
    pub fn for_batch(self, every_problem_has_a_mu_table: bool) -> Shape {
        self.with_mu_tables(self.slices == 1 && every_problem_has_a_mu_table)
    }
}

fn term_code(t: Term) -> u32 {
    match t {
        Term::AbsRatio => 0,
        Term::Square => 1,
        Term::LogSquare => 2,
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
/// through these, so Rust and WGSL cannot disagree on the order. The first knot of a run
/// (`ndf1` of `ndf1` … `ndf31`) also gets `fn <prefix>_<name>_run(o: u32, j: u32) -> f32`,
/// the run's j-th knot from it: a table of knots is read in a loop.
pub fn accessors_source(node: &Node) -> String {
    let w = node.bsdf.wgsl();
    let prefix = w.function.strip_suffix("_eval").unwrap_or(&w.function);
    let mut src = String::new();
    let params = node.bsdf.params();
    for (k, p) in params.iter().enumerate() {
        let name = p.name.replace('.', "_");
        src += &format!("fn {prefix}_{name}(o: u32) -> f32 {{ return P[o + {k}u]; }}\n");
        let starts_run =
            p.knot && (k == 0 || !params[k - 1].knot || params[k - 1].knot_stem() != p.knot_stem());
        if starts_run {
            src += &format!(
                "fn {prefix}_{name}_run(o: u32, j: u32) -> f32 {{ return P[o + {k}u + j]; }}\n"
            );
        }
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

/// The per-candidate prepare functions of the catalogue ([`crate::bsdf::Bsdf::wgsl_prepare`]):
/// every module declares each one's constant, since a shader file may hold several node
/// functions (every `btdf(·)` variant) and is included whole.
fn all_prepare_functions() -> &'static [&'static str] {
    static ALL: std::sync::OnceLock<Vec<&'static str>> = std::sync::OnceLock::new();
    ALL.get_or_init(|| {
        let mut all: Vec<&'static str> = Vec::new();
        for kind in [crate::data::Kind::Brdf, crate::data::Kind::Btdf] {
            for spec in crate::bsdf::every_spec(kind) {
                let Ok(model) = Model::parse(&spec, 1) else {
                    continue;
                };
                for node in model.nodes() {
                    if let Some(f) = node.bsdf.wgsl_prepare() {
                        if !all.contains(&f) {
                            all.push(f);
                        }
                    }
                }
            }
        }
        all
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

/// Most channels of one direction a sample record holds (`CB` in the kernels): a
/// record's channels are evaluated together, unrolled, so the shader compiler shares what
/// does not depend on the rgb parameters (half vector, D, G, Fresnel…) between them;
/// RGB and monochrome data fit one record per direction, spectral data take several.
pub const MAX_RECORD_CHANNELS: usize = 4;

/// Records per row of the records texture (`RPR` in the kernels); a row is then at most
/// 4,096 texels wide, within every device's limit.
pub const RECORDS_PER_ROW: usize = 1024;

/// Texels (RGBA32F) per record of `slots` channel slots: ωi (and the first group), ωo (and
/// a), then two slots (v, w) per texel.
pub fn record_texels(slots: usize) -> usize {
    2 + slots.div_ceil(2)
}

/// Channels per sample record for `model`: its channel count, at most
/// [`MAX_RECORD_CHANNELS`].
pub fn record_channels(model: &Model) -> usize {
    model.channels.clamp(1, MAX_RECORD_CHANNELS)
}

/// Scalar-view groups the private parameter array holds per candidate (`GP`): every
/// group, and room for a record whose first group is the last one (its channel slots
/// past the model's channels read zeros and are never used).
pub fn padded_groups(model: &Model) -> usize {
    let cb = record_channels(model);
    if fixed_base(model) {
        cb
    } else {
        model.groups() + cb
    }
}

/// Whether every record starts at group 0 (one plane and at most one record per
/// direction): the kernels then index the parameter views with constants only, which lets
/// the compiler keep them in registers and share the channels' common factors.
fn fixed_base(model: &Model) -> bool {
    model.groups() == model.channels && model.channels <= MAX_RECORD_CHANNELS
}

/// The generated, unrolled helpers a module's kernels call per sample record (WGSL has
/// no generics and every loop iteration counts against llvmpipe's loop limit, so the
/// per-channel code is written out here, CB times):
/// - `load_params(c)`: candidate c's flat vector into its views in P, each
///   flat entry loaded once and stored to every view that uses it (a parameter shared by
///   the channels is then one value the compiler can see is shared), its problem into
///   `CANDIDATE_PROBLEM`, then the prepare functions of the model's nodes;
/// - `eval_record(wi, wo, b)`: the model at the record's CB channels (views b, b + S, …);
/// - `record_costs(s, y, obs, a)`: the compensated sum s plus the record's loss terms;
/// - `record_obs(rec)`: the record's channel slots from the records texture;
/// - `store_values(at, y)`: the record's values to `out[at..at + CB]`, 0 in the slots
///   that hold no sample (`values` pass);
/// - under subgroup tiles, `shuffle_obs`: a record's per-channel data passed round a
///   subgroup.
pub fn record_source(model: &Model, shape: Shape) -> String {
    let s = model.scalar_count();
    let cb = record_channels(model);
    let mut src =
        String::from("// ---- generated: per-record helpers (src/engine/wgsl.rs, record_source)\n");
    // load_params: group g's view at P[g·S].
    src += "fn load_params(c: u32) {\n    CANDIDATE_PROBLEM = owners[2u * c];\n    let base = c * dims.dim;\n";
    let mut users: Vec<(usize, Vec<usize>)> = Vec::new();
    for g in 0..model.groups() {
        for j in 0..s {
            let flat = model.slot(j, g);
            match users.iter_mut().find(|(f, _)| *f == flat) {
                Some((_, v)) => v.push(g * s + j),
                None => users.push((flat, vec![g * s + j])),
            }
        }
    }
    for (flat, views) in &users {
        src += &format!("    let v{flat} = params[base + {flat}u];\n");
        for v in views {
            src += &format!("    P[{v}u] = v{flat};\n");
        }
    }
    for (function, offsets) in prepared_nodes(model) {
        if let [offset] = offsets[..] {
            src += &format!("    {function}({offset}u);\n");
        }
    }
    src += "}\n\n";
    let list = |f: &dyn Fn(usize) -> String| (0..cb).map(f).collect::<Vec<_>>().join(", ");
    src += &format!(
        "fn eval_record(wi: vec3<f32>, wo: vec3<f32>, b: u32) -> array<f32, CB> {{\n    return array<f32, CB>({});\n}}\n\n",
        list(&|i| format!("eval_model(wi, wo, b + {}u)", i * s))
    );
    src += "fn record_costs(s: vec2<f32>, y: array<f32, CB>, obs: array<vec2<f32>, CB>, a: f32) -> vec2<f32> {\n    var t = s;\n";
    for i in 0..cb {
        src += &format!("    t = add_term(t, y[{i}], obs[{i}], a);\n");
    }
    src += "    return t;\n}\n\n";
    // An empty slot's value may be anything (a channel past the model's evaluates views
    // of zeros): it is written as 0, so that host reductions see an exact 0 there.
    src += "fn store_values(at: u32, y: array<f32, CB>) {\n";
    for i in 0..cb {
        src += &format!(
            "    out[at + {i}u] = select(0.0, y[{i}], (RECORD_SLOTS & {}u) != 0u);\n",
            1 << i
        );
    }
    src += "}\n";
    let texels = record_texels(cb);
    src += "\nfn record_obs(r: u32) -> array<vec2<f32>, CB> {\n";
    for t in 2..texels {
        src += &format!("    let t{t} = record_texel(r, {t}u);\n");
    }
    src += &format!(
        "    return array<vec2<f32>, CB>({});\n}}\n",
        list(&|i| format!("t{}.{}", 2 + i / 2, if i % 2 == 0 { "xy" } else { "zw" }))
    );
    if shape.subgroup_tiles {
        src += &format!(
            "\nfn shuffle_obs(x: array<vec2<f32>, CB>, j: u32) -> array<vec2<f32>, CB> {{\n    return array<vec2<f32>, CB>({});\n}}\n",
            list(&|i| format!("subgroupShuffle(x[{i}], j)"))
        );
    }
    src
}

/// The nodes with a per-candidate prepare function ([`crate::bsdf::Bsdf::wgsl_prepare`]):
/// each function with the offsets of the nodes that have it, in first-use order. One
/// node: the module calls it per candidate. Several: their values would collide in the
/// function's module-scope variables, so none is called and each node computes its own.
fn prepared_nodes(model: &Model) -> Vec<(&'static str, Vec<usize>)> {
    let mut out: Vec<(&'static str, Vec<usize>)> = Vec::new();
    for node in model.nodes() {
        // A prepare function reads the node's parameters from the first group's view; a
        // node with a parameter of its own per measured plane (`+peraxis` on two planes)
        // has different values in other groups, so it computes per record instead.
        let own = node.offset..node.offset + node.bsdf.params().len();
        if model.params[own].iter().any(|p| p.axes > 1) {
            continue;
        }
        if let Some(f) = node.bsdf.wgsl_prepare() {
            match out.iter_mut().find(|(g, _)| *g == f) {
                Some((_, offsets)) => offsets.push(node.offset),
                None => out.push((f, vec![node.offset])),
            }
        }
    }
    out
}

/// The constants every generated module declares, with what each is; the kernels
/// (shaders/engine/*.wgsl) use them by these names.
const MODULE_CONSTANTS: &[(&str, &str, &str)] = &[
    (
        "S",
        "u32",
        "scalars of one parameter group's view (`Model::scalar_count`)",
    ),
    (
        "G",
        "u32",
        "parameter groups: channels, times planes under `+peraxis`",
    ),
    (
        "CB",
        "u32",
        "channel slots per sample record (`record_channels`)",
    ),
    (
        "TPR",
        "u32",
        "texels per record in the records texture (`record_texels`)",
    ),
    (
        "RPR",
        "u32",
        "records per row of the records texture (`RECORDS_PER_ROW`)",
    ),
    (
        "GP",
        "u32",
        "groups the private parameter array holds (`padded_groups`)",
    ),
    (
        "FIXED_BASE",
        "bool",
        "every record starts at group 0 (`fixed_base`)",
    ),
    (
        "MU_TABLES",
        "bool",
        "models look up their μ-only factors in tables (`Shape::mu_tables`)",
    ),
    (
        "CL",
        "u32",
        "candidate lanes per workgroup (`Shape::lanes`)",
    ),
    ("SL", "u32", "record slices per workgroup (`Shape::slices`)"),
    ("TERM", "u32", "the loss's per-sample term (`term_code`)"),
    ("PD", "u32", "P, the parameters per candidate"),
    ("NJJ", "u32", "entries of JᵀJ's upper triangle, P(P + 1)/2"),
    (
        "NE",
        "u32",
        "numbers the normal pass writes per group of P + 1 candidates (`normal_entries`)",
    ),
    (
        "EL",
        "u32",
        "threads along the rows of one normal workgroup (`normal_lanes`)",
    ),
    (
        "NB",
        "u32",
        "blocks of EL rows covering the P + 1 rows of the Gram matrix",
    ),
];

/// The values of [`MODULE_CONSTANTS`] for `model`, `term` and `shape`, in its order, as
/// (name, WGSL type, WGSL literal).
fn module_constants(
    model: &Model,
    term: Term,
    shape: Shape,
) -> Vec<(&'static str, &'static str, String)> {
    let p = model.dim;
    let u = |v: usize| format!("{v}u");
    let values = [
        u(model.scalar_count()),
        u(model.groups()),
        u(record_channels(model)),
        u(record_texels(record_channels(model))),
        u(RECORDS_PER_ROW),
        u(padded_groups(model)),
        fixed_base(model).to_string(),
        shape.mu_tables.to_string(),
        format!("{}u", shape.lanes),
        format!("{}u", shape.slices),
        format!("{}u", term_code(term)),
        u(p),
        u(p * (p + 1) / 2),
        u(normal_entries(p)),
        format!("{}u", normal_lanes(p, shape)),
        u((p + 1).div_ceil(normal_lanes(p, shape) as usize)),
    ];
    MODULE_CONSTANTS
        .iter()
        .zip(values)
        .map(|(&(name, ty, _), value)| (name, ty, value))
        .collect()
}

/// The full module for a model and a loss shape.
pub fn compose(model: &Model, term: Term, shape: Shape) -> String {
    let s = model.scalar_count();
    let mut src = format!(
        "// bsdfit kernel module for `{}`, {} channel(s)\n",
        model.spec, model.channels
    );
    for (name, ty, value) in module_constants(model, term, shape) {
        src += &format!("const {name}: {ty} = {value};\n");
    }
    src += &format!(
        "var<private> P: array<f32, {}>;\n\n",
        (s * padded_groups(model)).max(1)
    );
    src += &super::gpu::bindings::wgsl_declarations();
    src += COMMON;
    src += all_accessors();
    let prepared = prepared_nodes(model);
    for function in all_prepare_functions() {
        let once = prepared
            .iter()
            .any(|(f, offsets)| f == function && offsets.len() == 1);
        src += &format!("const {}D: bool = {once};\n", function.to_uppercase());
    }
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
    src += &record_source(model, shape);
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
