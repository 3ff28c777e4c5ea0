//! The model catalogue: one file per model, each the twin of a WGSL file in
//! `shaders/bsdf/`, its declarations ([`decl`]), the spec parser ([`spec`]), the registry
//! ([`registry`], one line per model) and the compiled [`Model`] the backends evaluate.
//!
//! A model is a tree of [`Bsdf`] nodes. Each node declares its own parameters once
//! ([`ParamDecl`]); combinators (`dmg(B)`, `fa(B)`, `M+retro`, BTDF suffixes) receive
//! the values of their children. Compiling a tree for C channels lays out one flat
//! parameter vector (an rgb parameter takes C entries) and, per channel, a scalar view
//! that the node functions read — the same layout on the CPU and the GPU.

use crate::data::Kind;
use crate::math::lanes::{F32x16, F32x8, F64x4};
pub use channels::{each_direction, Channels, Children, Dir, MAX_CHILDREN};
pub use decl::{
    Builder, Entry, GgxPlace, InCatalogue, LobePart, MitsubaBsdf, MitsubaField, ParamDecl, Role,
    Scale, Tabulated,
};
use glam::DVec3;
pub use registry::{
    base_arg, bases_of, build, catalogue, catalogue_for, every_spec, no_arg, spec_kind,
};
pub use spec::{render_spec, Ast};
use std::fmt;
use std::sync::Arc;

/// The data-driven form `+ndf` puts in place of `btdf(tr)`'s lobe (no entry of its own).
pub mod btdf_ndf;
mod channels;
pub mod decl;
pub mod effect;
pub mod kernel;
pub mod microfacet;
pub mod micrograin;
/// The form `+ndf` and `+fresnel` together put in place of a GGX lobe (no entry of its own).
pub mod ndf_fresnel;
pub mod registry;
pub mod spec;
pub mod stretched;
#[cfg(test)]
pub(crate) mod test_support;

/// Declares each model file as a module and lists the registry entries it declares.
macro_rules! models {
    ($($module:ident => [$($entry:ident),+]),* $(,)?) => {
        $(pub mod $module;)*
        /// Every model, in the order the catalogue lists them.
        pub const REGISTRY: &[&Entry] = &[$($(&$module::$entry),+),*];
    };
}

// The registry: one line per model file. Adding a model is its Rust file, its WGSL twin
// in shaders/bsdf/, and one line here; everything else is derived from its declarations.
models! {
    lambert => [ENTRY],
    on => [ENTRY],
    eon => [ENTRY],
    vmf => [ENTRY],
    ggx => [ENTRY],
    dmg => [ENTRY],
    rmg => [ENTRY],
    fa => [ENTRY],
    retro => [ENTRY],
    coat => [ENTRY],
    mrm => [ENTRY, F82_ENTRY],
    falloff => [ENTRY],
    btdf => [ENTRY, SCALE_ENTRY, ABSORB_ENTRY, DIFFUSE_ENTRY],
    peraxis => [ENTRY],
    aniso => [ENTRY],
    ndf => [ENTRY],
    fresnel => [ENTRY],
    body => [ENTRY],
}
/// WGSL side of a node: the source files it needs and the function to call.
#[derive(Clone, Debug)]
pub struct WgslFn {
    /// Shader sources (beyond `common.wgsl`) this node needs, included once each.
    pub sources: Vec<(&'static str, &'static str)>,
    /// Function name; called as `name(offset, wi, wo, child0, child1, …)`.
    pub function: String,
}

impl WgslFn {
    /// A node whose twin is one file `shaders/bsdf/<name>.wgsl` defining `<name>_eval`.
    pub fn single(name: &'static str, source: &'static str) -> WgslFn {
        WgslFn {
            sources: vec![(name, source)],
            function: format!("{name}_eval"),
        }
    }
}

/// One node of a model tree: a BSDF or a combinator of its children.
pub trait Bsdf: Send + Sync + fmt::Debug {
    /// The node's registry entry: its declared name, kind and role.
    fn entry(&self) -> &'static Entry;
    /// The spec name (`lambert`, `dmg`, `retro`, …).
    fn name(&self) -> &'static str {
        self.entry().name
    }
    /// The declared kind; a suffix that applies to either kind overrides this.
    fn kind(&self) -> Kind {
        self.entry().kind.unwrap_or(Kind::Brdf)
    }
    /// The node's own parameters, in the order `eval` reads them.
    fn params(&self) -> Vec<ParamDecl>;
    /// Roles of the children (`"base"` → parameters prefixed `base.`; `""` → unprefixed).
    fn child_roles(&self) -> &'static [&'static str] {
        &[]
    }
    /// Evaluate with this node's parameters `p` (already resolved for one channel) and the
    /// values of its children, in `child_roles` order.
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, children: &[f64]) -> f64;
    /// [`Self::eval`] for n channels (`p`, n = `p.len()`) at a block of directions
    /// `dirs` that all have these channels: `out[d · n + i]` receives direction d,
    /// channel i, and `children` holds the children's values the same way. The channels
    /// share every non-rgb parameter ([`Channels`]), so a node overrides this to compute
    /// once per direction what depends only on them and on the directions (half vector,
    /// D, G, Fresnel factors), as BBM evaluates the RGB channels of a direction in one
    /// call; one call per block of directions also pays the dynamic dispatch once for
    /// all of them. An override ([`each_direction`] is its loop) must give exactly what
    /// `eval` gives per channel (same operations in the same order; `tests/channels.rs`
    /// compares them bit for bit for every model the registry derives). The default
    /// calls `eval` per direction and channel.
    fn eval_channels(&self, p: Channels, dirs: &[Dir], children: Children, out: &mut [f64]) {
        let n = p.len();
        let nc = children.values.len().checked_div(out.len()).unwrap_or(0);
        let mut child = [0.0f64; MAX_CHILDREN];
        each_direction(dirs, n, out, |d, wi, wo, out| {
            for (i, o) in out.iter_mut().enumerate() {
                for (k, c) in child[..nc].iter_mut().enumerate() {
                    *c = children.at(k, d)[i];
                }
                *o = self.eval(p.view(i), wi, wo, &child[..nc]);
            }
        });
    }
    /// [`Self::eval_channels`] at lane-directions of eight f32 lanes (the SIMD engine).
    /// `kernel::kernel_methods!` derives it from a [`kernel::Kernel`];
    /// the default evaluates each lane with `eval_channels`.
    fn eval_f32x8(
        &self,
        p: Channels,
        dirs: &[kernel::LaneDir<F32x8>],
        children: kernel::LaneChildren<F32x8>,
        out: &mut [F32x8],
    ) {
        kernel::by_reference(self, p, dirs, children, out)
    }
    /// The same in sixteen f32 lanes.
    fn eval_f32x16(
        &self,
        p: Channels,
        dirs: &[kernel::LaneDir<F32x16>],
        children: kernel::LaneChildren<F32x16>,
        out: &mut [F32x16],
    ) {
        kernel::by_reference(self, p, dirs, children, out)
    }
    /// The same in four f64 lanes.
    fn eval_f64x4(
        &self,
        p: Channels,
        dirs: &[kernel::LaneDir<F64x4>],
        children: kernel::LaneChildren<F64x4>,
        out: &mut [F64x4],
    ) {
        kernel::by_reference(self, p, dirs, children, out)
    }
    /// The lanes the node's kernel runs in; `None` for a node without one (the SIMD
    /// engine then evaluates it lane by lane through the f64 reference).
    fn lanes(&self) -> Option<kernel::LaneKind> {
        None
    }
    /// The node's anisotropic form (two roughnesses and a tangent azimuth in place of
    /// its roughness), which `+aniso` puts in its place; `None` where it has none.
    fn anisotropic(&self) -> Option<Arc<dyn Bsdf>> {
        None
    }
    /// The isotropic GGX lobe this node holds, where, and which of its factors are
    /// tabulated: what `+ndf` and `+fresnel` read to put another form in its place.
    fn ggx_lobe(&self) -> Option<(GgxPlace, Tabulated)> {
        None
    }
    /// An anisotropic lobe's (α_u, α_v, φ0): the positions of the two roughnesses and of
    /// the frame's azimuth (degrees) among the node's parameters. (α_u, α_v, φ0) and
    /// (α_v, α_u, φ0 ∓ 90°) are the same surface; [`Model::canonical_form`] picks the one
    /// with |φ0| ≤ 45°.
    fn frame_params(&self) -> Option<[usize; 3]> {
        None
    }
    /// Whether f(i, o) = f(o, i) holds (tests check it where claimed).
    fn reciprocal(&self) -> bool {
        true
    }
    /// Whether the directional albedo stays at most 1 at every parameter value in bounds
    /// (tests check it where claimed; a tabulated factor without a bound, `+fresnel`'s,
    /// does not claim it).
    fn bounded_albedo(&self) -> bool {
        true
    }
    fn wgsl(&self) -> WgslFn;
    /// A WGSL function `fn <name>(o: u32)`, in one of [`Self::wgsl`]'s sources, that
    /// computes once per candidate what depends on this node's shared (neither rgb nor
    /// per-axis) parameters alone, into module-scope variables its node function then
    /// reads instead of recomputing it for every record (as `eval_channels` computes
    /// such parts once per parameter vector). The generated module calls it with the
    /// node's offset after loading each candidate, and declares `const <NAME>D: bool`
    /// (the name in upper case) in every module: true when the model has exactly one such
    /// node, false otherwise (none, or several whose values would collide), in which case
    /// the node function must compute the parts itself.
    fn wgsl_prepare(&self) -> Option<&'static str> {
        None
    }
    /// A lookup table the WGSL twin reads as `LUT` (f32 copy of the CPU's f64 table), if any.
    fn lut(&self) -> Option<Vec<f32>> {
        None
    }
}

/// A node with its children and its offset into the per-channel scalar view.
#[derive(Clone, Debug)]
pub struct Node {
    pub bsdf: Arc<dyn Bsdf>,
    pub children: Vec<Node>,
    /// Index of this node's first parameter in the scalar view (set by [`Model::compile`]).
    pub offset: usize,
    /// Number of this node's own parameters (set by [`Model::compile`]).
    pub nparams: usize,
    /// No rgb parameter in the subtree (set by [`Model::compile`]): every channel of one
    /// [`Node::eval_channels`] call then has the same value, computed once.
    pub uniform: bool,
}

impl Node {
    pub fn leaf(bsdf: impl Bsdf + 'static) -> Node {
        Node {
            bsdf: Arc::new(bsdf),
            children: vec![],
            offset: 0,
            nparams: 0,
            uniform: false,
        }
    }
    pub fn with(bsdf: impl Bsdf + 'static, children: Vec<Node>) -> Node {
        Node {
            bsdf: Arc::new(bsdf),
            children,
            offset: 0,
            nparams: 0,
            uniform: false,
        }
    }
    /// Evaluate the subtree on the scalar view `s`.
    pub fn eval(&self, s: &[f64], wi: DVec3, wo: DVec3) -> f64 {
        let mut child = [0.0f64; MAX_CHILDREN];
        for (k, c) in self.children.iter().enumerate() {
            child[k] = c.eval(s, wi, wo);
        }
        self.bsdf.eval(
            &s[self.offset..self.offset + self.nparams],
            wi,
            wo,
            &child[..self.children.len()],
        )
    }
    /// Evaluate the subtree for the channels `p` at the directions `dirs` into `out`
    /// (`out[d · n + i]`, n = `p.len()`), equal to [`Node::eval`] per direction and
    /// channel bit for bit. `scratch` holds the children's values: at least
    /// [`Model::scratch_len`] of `out.len()` values.
    pub fn eval_channels(&self, p: Channels, dirs: &[Dir], out: &mut [f64], scratch: &mut [f64]) {
        let (n, m) = (p.len(), dirs.len());
        debug_assert_eq!(out.len(), n * m);
        if n == 0 || m == 0 {
            return;
        }
        if self.uniform {
            // Only shared parameters below: channel 0's value is every channel's.
            let view = p.full_view(0);
            each_direction(dirs, n, out, |_, wi, wo, out| {
                out.fill(self.eval(view, wi, wo))
            });
            return;
        }
        let block = n * m;
        let (mine, rest) = scratch.split_at_mut(self.children.len() * block);
        for (k, c) in self.children.iter().enumerate() {
            c.eval_channels(p, dirs, &mut mine[k * block..(k + 1) * block], rest);
        }
        let children = Children::new(mine, m, n);
        self.bsdf
            .eval_channels(p.node(self.offset, self.nparams), dirs, children, out);
    }
    /// [`Self::eval_channels`] in lanes: `dirs` holds lane-directions, `out[d · n + i]`
    /// lane-direction d, channel i; `scratch` at least [`Model::scratch_len`] of
    /// `out.len()`.
    pub fn eval_lanes<R: kernel::LaneReal>(
        &self,
        p: Channels,
        dirs: &[kernel::LaneDir<R>],
        out: &mut [R],
        scratch: &mut [R],
    ) {
        let (n, m) = (p.len(), dirs.len());
        debug_assert_eq!(out.len(), n * m);
        if n == 0 || m == 0 {
            return;
        }
        if self.uniform && n > 1 {
            // Only shared parameters below: channel 0's values are every channel's.
            let (first, rest) = scratch.split_at_mut(m);
            self.eval_lanes(p.first(), dirs, first, rest);
            for (o, &v) in out.chunks_exact_mut(n).zip(first.iter()) {
                o.fill(v);
            }
            return;
        }
        let block = n * m;
        let (mine, rest) = scratch.split_at_mut(self.children.len() * block);
        for (k, c) in self.children.iter().enumerate() {
            c.eval_lanes(p, dirs, &mut mine[k * block..(k + 1) * block], rest);
        }
        let children = kernel::LaneChildren::new(mine, m, n);
        R::eval_node(
            self.bsdf.as_ref(),
            p.node(self.offset, self.nparams),
            dirs,
            children,
            out,
        );
    }
    pub fn visit<'a>(&'a self, f: &mut impl FnMut(&'a Node)) {
        f(self);
        for c in &self.children {
            c.visit(f);
        }
    }
    /// The tree with every node that `form` gives another form of (`+aniso`'s anisotropic
    /// lobes, `+ndf`'s data-driven ones) replaced by it, children first; with how many were
    /// replaced and the names of every node met (a suffix checks it is not given twice).
    pub fn with_forms(self, form: &FormOf) -> (Node, usize, Vec<&'static str>) {
        fn swap(
            node: Node,
            form: &FormOf,
            count: &mut usize,
            names: &mut Vec<&'static str>,
        ) -> Node {
            names.push(node.bsdf.name());
            let children = node
                .children
                .into_iter()
                .map(|c| swap(c, form, count, names))
                .collect();
            let bsdf = match form(node.bsdf.as_ref()) {
                Some(other) => {
                    *count += 1;
                    other
                }
                None => node.bsdf,
            };
            Node {
                bsdf,
                children,
                offset: 0,
                nparams: 0,
                uniform: false,
            }
        }
        let (mut count, mut names) = (0, Vec::new());
        let node = swap(self, form, &mut count, &mut names);
        (node, count, names)
    }
}

/// Another form of a node, where it has one ([`Bsdf::anisotropic`]; the microfacet lobes'
/// forms of [`registry::ggx_form`]).
pub type FormOf<'a> = dyn Fn(&dyn Bsdf) -> Option<Arc<dyn Bsdf>> + 'a;

/// A parameter of a compiled model: its declaration, full name and place in the flat vector.
#[derive(Clone, Debug)]
pub struct FlatParam {
    /// Full name with role prefixes, e.g. `base.rho`.
    pub name: String,
    pub decl: ParamDecl,
    /// First index in the flat parameter vector (rgb parameters take `channels` entries).
    pub index: usize,
    /// Number of measurement planes with a value of their own (1 unless under `+peraxis`).
    pub axes: usize,
}

impl FlatParam {
    /// Entries in the flat vector: channels (if rgb) × axes (if per-axis), axis-major.
    pub fn width(&self, channels: usize) -> usize {
        (if self.decl.rgb { channels } else { 1 }) * self.axes
    }
}

/// A model tree compiled for a number of channels: the flat layout both backends share.
#[derive(Clone, Debug)]
pub struct Model {
    /// The spec string as given (whitespace removed).
    pub spec: String,
    pub root: Node,
    pub kind: Kind,
    pub channels: usize,
    /// Measurement planes (φ, degrees) with parameters of their own: several only for a
    /// `+peraxis` model compiled for data measured on several planes.
    pub axes: Vec<f64>,
    /// Declared parameters in scalar-view order (node pre-order, own before children).
    pub params: Vec<FlatParam>,
    /// Length P of the flat parameter vector.
    pub dim: usize,
}

/// Errors in spec strings and parameter assignments.
#[derive(Debug, thiserror::Error)]
pub enum SpecError {
    #[error("model spec '{spec}': {msg}")]
    Parse { spec: String, msg: String },
    #[error("{0}")]
    Other(String),
}

impl Model {
    /// Parse `spec` and compile it for `channels` channels (one measurement plane).
    pub fn parse(spec: &str, channels: usize) -> Result<Model, SpecError> {
        Model::parse_for(spec, channels, &[0.0])
    }

    /// Parse `spec` and compile it for the channels and measurement planes of `data`.
    pub fn for_data(spec: &str, data: &crate::data::Dataset) -> Result<Model, SpecError> {
        Model::parse_for(spec, data.channel_count(), &data.axes)
    }

    /// Parse `spec` and compile it for `channels` channels and the planes `axes` (degrees;
    /// they matter only under `+peraxis`).
    pub fn parse_for(spec: &str, channels: usize, axes: &[f64]) -> Result<Model, SpecError> {
        let clean: String = spec.chars().filter(|c| !c.is_whitespace()).collect();
        let ast = Ast::parse(&clean)?;
        let root = build(&ast).map_err(|msg| SpecError::Parse {
            spec: clean.clone(),
            msg,
        })?;
        Model::compile_for(&clean, root, channels, axes)
    }

    /// Lay out the scalar view and the flat vector of a built tree.
    pub fn compile(spec: &str, root: Node, channels: usize) -> Result<Model, SpecError> {
        Model::compile_for(spec, root, channels, &[0.0])
    }

    fn compile_for(
        spec: &str,
        mut root: Node,
        channels: usize,
        axes: &[f64],
    ) -> Result<Model, SpecError> {
        if channels == 0 {
            return Err(SpecError::Other(
                "a model needs at least one channel".into(),
            ));
        }
        let mut has_peraxis = false;
        root.visit(&mut |n| has_peraxis |= n.bsdf.name() == "peraxis");
        let axes: Vec<f64> = if has_peraxis && !axes.is_empty() {
            axes.to_vec()
        } else {
            vec![0.0]
        };
        let n_axes = axes.len();
        let kind = root.bsdf.kind();
        let mut params = Vec::new();
        struct Layout<'a> {
            params: &'a mut Vec<FlatParam>,
            dim: usize,
            channels: usize,
            axes: usize,
            kind: Kind,
            ok: bool,
        }
        fn lay(node: &mut Node, prefix: &str, per_axis: bool, l: &mut Layout) {
            if node.bsdf.kind() != l.kind {
                l.ok = false;
            }
            node.offset = l.params.len();
            let decls = node.bsdf.params();
            node.nparams = decls.len();
            for decl in decls {
                let axes = if per_axis && decl.per_axis { l.axes } else { 1 };
                let p = FlatParam {
                    name: format!("{prefix}{}", decl.name),
                    decl,
                    index: l.dim,
                    axes,
                };
                l.dim += p.width(l.channels);
                l.params.push(p);
            }
            let roles = node.bsdf.child_roles();
            let below = per_axis || node.bsdf.name() == "peraxis";
            for (k, child) in node.children.iter_mut().enumerate() {
                let role = roles.get(k).copied().unwrap_or("");
                let pre = if role.is_empty() {
                    prefix.to_string()
                } else {
                    format!("{prefix}{role}.")
                };
                lay(child, &pre, below, l);
            }
            node.uniform = node.children.iter().all(|c| c.uniform)
                && l.params[node.offset..].iter().all(|p| !p.decl.rgb);
        }
        let mut layout = Layout {
            params: &mut params,
            dim: 0,
            channels,
            axes: n_axes,
            kind,
            ok: true,
        };
        lay(&mut root, "", false, &mut layout);
        let dim = layout.dim;
        let kinds_ok = layout.ok;
        if !kinds_ok {
            return Err(SpecError::Parse {
                spec: spec.into(),
                msg: "mixes BRDF and BTDF nodes".into(),
            });
        }
        let mut names: Vec<&str> = params.iter().map(|p| p.name.as_str()).collect();
        names.sort();
        if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
            return Err(SpecError::Parse {
                spec: spec.into(),
                msg: format!("parameter '{}' appears twice", w[0]),
            });
        }
        Ok(Model {
            spec: spec.to_string(),
            root,
            kind,
            channels,
            axes,
            params,
            dim,
        })
    }

    /// Number of (plane, channel) groups, each with its own scalar view.
    pub fn groups(&self) -> usize {
        self.channels * self.axes.len()
    }

    /// The scalar-view group of a sample: its channel, and its plane under `+peraxis`.
    pub fn group_of(&self, s: &crate::data::Sample) -> usize {
        if self.axes.len() > 1 {
            s.axis.min(self.axes.len() - 1) * self.channels + s.channel
        } else {
            s.channel
        }
    }

    /// Number of scalars in the per-channel view.
    pub fn scalar_count(&self) -> usize {
        self.params.len()
    }

    /// Index in the flat vector of scalar `j` for group `g` (= channel, unless `+peraxis`
    /// splits groups by plane: g = axis · channels + channel).
    pub fn slot(&self, j: usize, g: usize) -> usize {
        let p = &self.params[j];
        let (axis, ch) = (g / self.channels, g % self.channels);
        let rgb_width = if p.decl.rgb { self.channels } else { 1 };
        p.index + if p.axes > 1 { axis * rgb_width } else { 0 } + if p.decl.rgb { ch } else { 0 }
    }

    /// The scalar view of group `g` (see [`Self::scalars_into`]).
    pub fn scalars(&self, flat: &[f64], g: usize) -> Vec<f64> {
        let mut v = Vec::with_capacity(self.params.len());
        self.scalars_into(flat, g, &mut v);
        v
    }

    /// Resolve the flat vector into the scalar view of group `g`.
    pub fn scalars_into(&self, flat: &[f64], g: usize, out: &mut Vec<f64>) {
        out.clear();
        out.extend((0..self.params.len()).map(|j| flat[self.slot(j, g)]));
    }

    /// The flat index of every group's scalars, group after group
    /// (`slots[g * scalar_count() + j] = slot(j, g)`): [`Self::views_into`] from a table.
    pub fn slot_table(&self) -> Vec<usize> {
        (0..self.groups())
            .flat_map(|g| (0..self.params.len()).map(move |j| self.slot(j, g)))
            .collect()
    }

    /// Resolve the flat vector into the scalar views of every group, one after the other
    /// (what [`Channels::new`] takes), with `slots` from [`Self::slot_table`].
    pub fn views_into(flat: &[f64], slots: &[usize], out: &mut Vec<f64>) {
        out.clear();
        out.extend(slots.iter().map(|&i| flat[i]));
    }

    /// Scratch values [`Node::eval_channels`] needs for a block of `values` outputs
    /// (directions × channels): one per node and output (the children's values at
    /// every level).
    pub fn scratch_len(&self, values: usize) -> usize {
        self.nodes().len() * values
    }

    /// Evaluate the model for the groups `groups` at the directions `dirs` into `out`
    /// (`out[d · groups.len() + i]`) from the views of [`Self::views_into`]; equal to
    /// [`Self::eval`] per direction and group bit for bit. The groups must lie on one
    /// plane (the channels of a direction). Allocates its scratch: the CPU backend keeps
    /// one per thread instead.
    pub fn eval_channels(&self, views: &[f64], groups: &[u32], dirs: &[Dir], out: &mut [f64]) {
        debug_assert!(groups
            .iter()
            .all(|&g| g as usize / self.channels == groups[0] as usize / self.channels));
        let mut scratch = vec![0.0; self.scratch_len(out.len())];
        let p = Channels::new(views, self.scalar_count(), groups);
        self.root.eval_channels(p, dirs, out, &mut scratch);
    }

    /// Evaluate the model for one flat parameter vector at one geometry and group (the
    /// channel index when there is one plane).
    pub fn eval(&self, flat: &[f64], g: usize, wi: DVec3, wo: DVec3) -> f64 {
        self.root.eval(&self.scalars(flat, g), wi, wo)
    }

    /// The declaration of each flat entry (rgb declarations repeated per channel).
    pub fn flat_decls(&self) -> Vec<ParamDecl> {
        let mut v = Vec::with_capacity(self.dim);
        for p in &self.params {
            for _ in 0..p.width(self.channels) {
                v.push(p.decl);
            }
        }
        v
    }

    /// Human-readable name of each flat entry: `rho[1]` for channel 1 of an rgb parameter,
    /// `alpha@phi90` for the plane φ = 90° of a per-axis parameter.
    pub fn flat_names(&self) -> Vec<String> {
        let mut v = Vec::with_capacity(self.dim);
        for p in &self.params {
            for a in 0..p.axes {
                let axis = if p.axes > 1 {
                    format!("@phi{}", self.axes[a])
                } else {
                    String::new()
                };
                if p.decl.rgb {
                    for c in 0..self.channels {
                        v.push(format!("{}[{c}]{axis}", p.name));
                    }
                } else {
                    v.push(format!("{}{axis}", p.name));
                }
            }
        }
        v
    }

    pub fn defaults(&self) -> Vec<f64> {
        self.flat_decls().iter().map(|d| d.default).collect()
    }

    pub fn to_unit(&self, flat: &[f64]) -> Vec<f64> {
        self.flat_decls()
            .iter()
            .zip(flat)
            .map(|(d, &v)| d.to_unit(v))
            .collect()
    }

    pub fn from_unit(&self, unit: &[f64]) -> Vec<f64> {
        self.flat_decls()
            .iter()
            .zip(unit)
            .map(|(d, &u)| d.from_unit(u))
            .collect()
    }

    /// Parse `name=value` assignments (`rho=0.5` sets every channel, `rho=0.4:0.5:0.6`
    /// one value per channel); unnamed parameters keep their defaults. A message names
    /// the assignment or parameter at fault, not an option: the caller adds which of its
    /// options the text came from.
    pub fn params_from_assignments(&self, text: &str) -> Result<Vec<f64>, SpecError> {
        let mut flat = self.defaults();
        for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (name, value) = item
                .split_once('=')
                .ok_or_else(|| SpecError::Other(format!("'{item}' is not name=value")))?;
            let p = self
                .params
                .iter()
                .find(|p| p.name == name.trim())
                .ok_or_else(|| {
                    SpecError::Other(format!(
                        "model {} has no parameter '{}' (it has: {})",
                        self.spec,
                        name.trim(),
                        self.params
                            .iter()
                            .map(|p| p.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })?;
            let values: Vec<f64> = value
                .split(':')
                .map(|v| {
                    v.trim()
                        .parse::<f64>()
                        .ok()
                        .filter(|x| x.is_finite())
                        .ok_or_else(|| {
                            SpecError::Other(format!("'{v}' for {} is not a number", p.name))
                        })
                })
                .collect::<Result<_, _>>()?;
            let width = p.width(self.channels);
            let values = match values.len() {
                1 => vec![values[0]; width],
                n if n == width => values,
                n => {
                    return Err(SpecError::Other(format!(
                        "{} takes 1 or {width} values, got {n}",
                        p.name
                    )))
                }
            };
            for (k, v) in values.into_iter().enumerate() {
                if v < p.decl.lo || v > p.decl.hi {
                    return Err(SpecError::Other(format!(
                        "{} = {v} is outside its bounds [{}, {}]",
                        p.name, p.decl.lo, p.decl.hi
                    )));
                }
                flat[p.index + k] = v;
            }
        }
        Ok(flat)
    }

    /// `flat` with every anisotropic lobe in the form with |φ0| ≤ 45° (swapping α_u and
    /// α_v, φ0 ∓ 90°): the same model values, so a fit reports one form of each surface.
    /// A lobe is left as it is unless `free` holds for its three flat indices (a user's
    /// bounds, fixed values or priors are not carried over a swap).
    pub fn canonical_form(&self, flat: &mut [f64], free: impl Fn(usize) -> bool) {
        for [u, v, phi] in self.frames() {
            if ![u, v, phi].into_iter().all(&free) {
                continue;
            }
            if flat[phi].abs() > 45.0 {
                flat.swap(u, v);
                flat[phi] -= 90.0f64.copysign(flat[phi]);
            }
        }
    }

    /// The flat indices (α_u, α_v, φ0) of every anisotropic lobe with one frame (not
    /// per-plane), in pre-order.
    pub fn frames(&self) -> Vec<[usize; 3]> {
        self.nodes()
            .into_iter()
            .filter_map(|node| {
                let local = node.bsdf.frame_params()?;
                (self.params[node.offset + local[0]].axes == 1)
                    .then(|| local.map(|k| self.params[node.offset + k].index))
            })
            .collect()
    }

    /// The lanes the SIMD engine evaluates the model in: f64 where a node needs it, else
    /// sixteen f32 lanes unless a node runs faster in eight ([`kernel::Kernel::NARROW_LANES`];
    /// eight without AVX-512: [`kernel::LaneKind::on_this_processor`]).
    pub fn lane_kind(&self) -> kernel::LaneKind {
        use kernel::LaneKind::{F32x16, F32x8, F64x4};
        let kinds: Vec<_> = self.nodes().iter().filter_map(|n| n.bsdf.lanes()).collect();
        [F64x4, F32x8]
            .into_iter()
            .find(|k| kinds.contains(k))
            .unwrap_or(F32x16)
    }

    /// The nodes without a [`kernel::Kernel`] (evaluated lane by lane through the f64
    /// reference on the SIMD engine), by name.
    pub fn nodes_without_kernel(&self) -> Vec<&'static str> {
        self.nodes()
            .iter()
            .filter(|n| n.bsdf.lanes().is_none())
            .map(|n| n.bsdf.name())
            .collect()
    }

    /// Every node in pre-order (the order of offsets).
    pub fn nodes(&self) -> Vec<&Node> {
        let mut v = Vec::new();
        self.root.visit(&mut |n| v.push(n));
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_nested_and_suffixed_specs() {
        let a = Ast::parse("fa(eon)+retro").unwrap();
        assert_eq!(
            a,
            Ast::Suffix {
                inner: Box::new(Ast::Term {
                    name: "fa".into(),
                    arg: Some(Box::new(Ast::Term {
                        name: "eon".into(),
                        arg: None
                    }))
                }),
                name: "retro".into()
            }
        );
        assert!(Ast::parse("fa(eon").is_err());
        assert!(Ast::parse("").is_err());
        assert!(Ast::parse("fa(eon))").is_err());
    }

    #[test]
    fn nested_parameters_are_prefixed_and_laid_out() {
        let m = Model::parse("dmg(eon)", 3).unwrap();
        let names: Vec<&str> = m.params.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["tau0", "beta", "rho_g", "base.rho", "base.r"]);
        // tau0, beta shared; rho_g and base.rho rgb: 1 + 1 + 3 + 3 + 1
        assert_eq!(m.dim, 9);
        assert_eq!(m.slot(3, 2), 2 + 3 + 2);
    }

    #[test]
    fn unknown_models_are_clear_errors() {
        let e = Model::parse("lambret", 3).unwrap_err().to_string();
        assert!(e.contains("unknown model 'lambret'"), "{e}");
        let e = Model::parse("dmg(fa(eon))", 3).unwrap_err().to_string();
        assert!(e.contains("takes a base"), "{e}");
    }

    #[test]
    fn unit_box_round_trips() {
        for spec in catalogue(Kind::Brdf)
            .iter()
            .chain(catalogue(Kind::Btdf).iter())
        {
            let m = Model::parse(spec, 3).unwrap();
            let d = m.defaults();
            let back = m.from_unit(&m.to_unit(&d));
            for (a, b) in d.iter().zip(&back) {
                assert!(
                    (a - b).abs() <= 1e-9 * a.abs().max(1.0),
                    "{spec}: {a} vs {b}"
                );
            }
        }
    }
}
