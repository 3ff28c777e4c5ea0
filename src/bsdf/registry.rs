//! What is derived from the registry ([`REGISTRY`], one line per model file in
//! `src/bsdf/mod.rs`). Everything about the catalogue is derived from
//! the models' declarations ([`Entry`], [`ParamDecl`](super::ParamDecl)): the default
//! catalogue, the bases a layer accepts, the kind of a spec, and `bsdfit models`.

use super::decl::{Builder, Entry, GgxPlace, InCatalogue, Role, Tabulated};
use super::spec::Ast;
use super::{btdf, btdf_ndf, coat, fa, fresnel, ggx, ndf, ndf_fresnel, Bsdf};
use super::{Node, SpecError, REGISTRY};
use crate::data::Kind;
use std::sync::Arc;
use std::sync::RwLock;

/// The node holding the microfacet lobe of `place` with the factors `tabulated`: the one
/// table of the lobe forms, from which `+ndf` and `+fresnel` swap a lobe for the form with
/// one factor more (see [`form_suffix`]). None where the place has no such form (a
/// transmission lobe's Fresnel factor is a transmittance, not tabulated).
pub fn ggx_form(place: GgxPlace, tabulated: Tabulated) -> Option<Arc<dyn Bsdf>> {
    use GgxPlace::{Aggregate, Coat, Ggx, Transmission};
    Some(match (place, tabulated.ndf, tabulated.fresnel) {
        (Ggx, false, false) => Arc::new(ggx::Ggx),
        (Ggx, true, false) => Arc::new(ndf::GgxNdf),
        (Ggx, false, true) => Arc::new(fresnel::GgxFresnel),
        (Ggx, true, true) => Arc::new(ndf_fresnel::GgxNdfFresnel),
        (Aggregate, false, false) => Arc::new(fa::FresnelAggregate),
        (Aggregate, true, false) => Arc::new(ndf::FaNdf),
        (Aggregate, false, true) => Arc::new(fresnel::FaFresnel),
        (Aggregate, true, true) => Arc::new(ndf_fresnel::FaNdfFresnel),
        (Coat, false, false) => Arc::new(coat::Coat),
        (Coat, true, false) => Arc::new(ndf::CoatNdf),
        (Coat, false, true) => Arc::new(fresnel::CoatFresnel),
        (Coat, true, true) => Arc::new(ndf_fresnel::CoatNdfFresnel),
        (Transmission, false, false) => Arc::new(btdf::Btdf { ndf: btdf::Ndf::Tr }),
        (Transmission, true, false) => Arc::new(btdf_ndf::BtdfNdf),
        (Transmission, _, true) => return None,
    })
}

/// The build of a suffix that tabulates one factor of each isotropic microfacet lobe
/// (`+ndf`, `+fresnel`): every lobe whose `factor` is not yet tabulated is swapped for the
/// form that adds it ([`ggx_form`]) and the result wrapped in the suffix's pass-through
/// node `wrap`; refused on models of another kind than `kind` (where given), when given
/// twice, and where no node holds such a lobe (`needs` says which do).
pub fn form_suffix(
    inner: Node,
    suffix: &'static str,
    kind: Option<Kind>,
    factor: fn(&mut Tabulated) -> &mut bool,
    wrap: impl Bsdf + 'static,
    needs: &str,
) -> Result<Node, String> {
    if let Some(kind) = kind.filter(|&k| inner.bsdf.kind() != k) {
        let kind = kind.to_string().to_uppercase();
        return Err(format!("+{suffix} applies to {kind} models"));
    }
    let form = |b: &dyn Bsdf| {
        let (place, mut tabulated) = b.ggx_lobe()?;
        let f = factor(&mut tabulated);
        if *f {
            return None;
        }
        *f = true;
        ggx_form(place, tabulated)
    };
    let (swapped, count, names) = inner.with_forms(&form);
    if names.contains(&suffix) {
        return Err(format!("+{suffix} given twice"));
    }
    if count == 0 {
        return Err(format!("+{suffix} needs {needs}"));
    }
    Ok(Node::with(wrap, vec![swapped]))
}

fn is_suffix(e: &Entry) -> bool {
    matches!(e.build, Builder::Suffix(_))
}

/// Models registered at run time ([`register`]), after the built-in [`REGISTRY`].
static REGISTERED: RwLock<Vec<&'static Entry>> = RwLock::new(Vec::new());

/// Every model: the built-in [`REGISTRY`] in its order, then those added by [`register`].
pub fn all() -> Vec<&'static Entry> {
    let extra = REGISTERED.read().unwrap_or_else(|e| e.into_inner());
    REGISTRY
        .iter()
        .copied()
        .chain(extra.iter().copied())
        .collect()
}

/// Add a model defined outside this crate (a test's toy model, a program's own model):
/// from then on it parses, fits on both backends, is swept, listed, diagnosed and
/// exported like a built-in one, because everything derives from the entries. Its name
/// must be new among the terms (or among the suffixes, for a suffix); registering the
/// same entry twice is allowed and does nothing.
pub fn register(e: &'static Entry) -> Result<(), String> {
    let mut extra = REGISTERED.write().unwrap_or_else(|e| e.into_inner());
    match REGISTRY
        .iter()
        .chain(extra.iter())
        .find(|x| x.name == e.name && is_suffix(x) == is_suffix(e))
    {
        Some(x) if std::ptr::eq(*x, e) => Ok(()),
        Some(_) => Err(format!("a model named '{}' is already registered", e.name)),
        None => {
            extra.push(e);
            Ok(())
        }
    }
}

/// The entry of a term (`lambert`, `btdf`) or, with `suffix`, of a suffix (`retro`).
pub fn entry(name: &str, suffix: bool) -> Option<&'static Entry> {
    all()
        .into_iter()
        .find(|e| e.name == name && is_suffix(e) == suffix)
}

fn known(suffix: bool) -> String {
    all()
        .iter()
        .filter(|e| is_suffix(e) == suffix)
        .map(|e| {
            if suffix {
                format!("+{}", e.name)
            } else {
                e.name.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Build a node tree from syntax.
pub fn build(ast: &Ast) -> Result<Node, String> {
    match ast {
        Ast::Term { name, arg } => {
            let e = entry(name, false)
                .ok_or_else(|| format!("unknown model '{name}' (known: {})", known(false)))?;
            match e.build {
                Builder::Leaf(b) => no_arg(name, arg.as_deref()).map(|()| b()),
                Builder::Layer(b) => base_arg(e, arg.as_deref()).map(b),
                Builder::Term(b) => b(arg.as_deref()),
                Builder::Suffix(_) => unreachable!("entry() matched a term"),
            }
        }
        Ast::Suffix { inner, name } => {
            let e = entry(name, true)
                .ok_or_else(|| format!("unknown suffix '+{name}' (known: {})", known(true)))?;
            match e.build {
                Builder::Suffix(b) => b(build(inner)?),
                Builder::Leaf(_) | Builder::Layer(_) | Builder::Term(_) => {
                    unreachable!("entry() matched a suffix")
                }
            }
        }
    }
}

/// The kind of data a spec is for, from its syntax and the declarations alone (it works
/// for specs that would not build, e.g. with a base a layer does not accept).
pub fn spec_kind(spec: &str) -> Result<Kind, SpecError> {
    let clean: String = spec.chars().filter(|c| !c.is_whitespace()).collect();
    let ast = Ast::parse(&clean)?;
    fn kind_of(ast: &Ast) -> Result<Kind, String> {
        match ast {
            Ast::Term { name, .. } => entry(name, false)
                .and_then(|e| e.kind)
                .ok_or_else(|| format!("unknown model '{name}' (known: {})", known(false))),
            Ast::Suffix { inner, name } => {
                let e = entry(name, true)
                    .ok_or_else(|| format!("unknown suffix '+{name}' (known: {})", known(true)))?;
                match e.kind {
                    Some(k) => Ok(k),
                    None => kind_of(inner),
                }
            }
        }
    }
    kind_of(&ast).map_err(|msg| SpecError::Parse { spec: clean, msg })
}

/// Builders' helper: a term that takes no argument.
pub fn no_arg(name: &str, arg: Option<&Ast>) -> Result<(), String> {
    match arg {
        None => Ok(()),
        Some(_) => Err(format!("'{name}' takes no argument")),
    }
}

/// The leaf models (no argument, no children) whose role is one of `roles`, in registry
/// order: the bases a layer with `Role::Layer { over: roles }` accepts.
pub fn leaves_with_role(roles: &[Role]) -> Vec<&'static str> {
    all()
        .iter()
        .filter(|e| roles.contains(&e.role))
        .map(|e| e.name)
        .collect()
}

/// The bases a layer accepts (empty for a model that is not a layer).
pub fn bases_of(layer: &Entry) -> Vec<&'static str> {
    match layer.role {
        Role::Layer { over } => leaves_with_role(over),
        _ => Vec::new(),
    }
}

/// Layers' helper: build the base model of `layer(B)` and check that the layer's
/// declaration accepts it.
pub fn base_arg(layer: &Entry, arg: Option<&Ast>) -> Result<Node, String> {
    let allowed = bases_of(layer);
    if allowed.is_empty() {
        return Err(format!("'{}' is not a layer", layer.name));
    }
    let name = layer.name;
    let Some(arg) = arg else {
        return Err(format!(
            "'{name}' needs a base model, e.g. {name}({})",
            allowed[0]
        ));
    };
    let node = build(arg)?;
    if !allowed.contains(&node.bsdf.name()) || !node.children.is_empty() {
        return Err(format!(
            "'{name}' takes a base among {}",
            allowed.join(", ")
        ));
    }
    Ok(node)
}

/// The catalogue a sweep runs by default for a kind of data measured on `planes` φ planes:
/// every leaf, every layer over every base it accepts, every transmission variant, each
/// with and without each catalogue suffix of its kind; plus, for data on several planes,
/// the per-plane variants.
pub fn catalogue_for(kind: Kind, planes: usize) -> Vec<String> {
    let mut cores: Vec<String> = Vec::new();
    for e in all().iter().filter(|e| e.kind == Some(kind)) {
        if e.catalogue != InCatalogue::Yes || is_suffix(e) {
            continue;
        }
        match e.role {
            Role::DiffuseBase | Role::SpecularLobe => cores.push(e.name.into()),
            Role::Layer { over } => cores.extend(
                leaves_with_role(over)
                    .into_iter()
                    .map(|b| format!("{}({b})", e.name)),
            ),
            Role::Transmission => {
                cores.extend(e.variants.iter().map(|v| format!("{}({v})", e.name)))
            }
            Role::Suffix => {}
        }
    }
    let suffixes = catalogue_suffixes(kind);
    let mut out = Vec::new();
    for c in &cores {
        out.push(c.clone());
        out.extend(suffixes.iter().map(|s| format!("{c}+{s}")));
    }
    if planes > 1 {
        let mut extra = Vec::new();
        for e in all().iter().filter(|e| is_suffix(e)) {
            if let InCatalogue::MultiPlaneAfter(after) = e.catalogue {
                if e.kind.is_none_or(|k| k == kind) {
                    let tail = format!("+{after}");
                    // Where the suffix applies: `+aniso` has no GTR form.
                    extra.extend(
                        out.iter()
                            .filter(|s| s.ends_with(&tail))
                            .map(|s| format!("{s}+{}", e.name))
                            .filter(|s| Ast::parse(s).is_ok_and(|a| build(&a).is_ok())),
                    );
                }
            }
        }
        out.extend(extra);
    }
    out
}

/// The suffixes the catalogue appends to each core model of a kind (`scale`, `absorb`
/// for BTDF), in registry order.
pub fn catalogue_suffixes(kind: Kind) -> Vec<&'static str> {
    all()
        .into_iter()
        .filter(|e| is_suffix(e) && e.catalogue == InCatalogue::Yes)
        .filter(|e| e.kind.is_none_or(|k| k == kind))
        .map(|e| e.name)
        .collect()
}

/// The catalogue for data on one plane.
pub fn catalogue(kind: Kind) -> Vec<String> {
    catalogue_for(kind, 1)
}

/// Every spec a test suite should cover for a kind: the catalogue (with its per-plane
/// variants) plus each model outside it — terms on their own, suffixes (those of
/// multi-plane data too) on each core model of their kind where they apply. Tests that enumerate this cover a new model without being edited.
pub fn every_spec(kind: Kind) -> Vec<String> {
    let mut out = catalogue_for(kind, 2);
    let cores: Vec<String> = out.iter().filter(|s| !s.contains('+')).cloned().collect();
    let extra: Vec<&Entry> = all()
        .iter()
        .copied()
        .filter(|e| e.catalogue != InCatalogue::Yes && e.kind.is_none_or(|k| k == kind))
        .collect();
    let builds = |spec: &str| Ast::parse(spec).is_ok_and(|a| build(&a).is_ok());
    for e in &extra {
        match e.build {
            Builder::Leaf(_) | Builder::Layer(_) | Builder::Term(_) => out.push(e.name.to_string()),
            Builder::Suffix(_) => {
                let on_cores: Vec<String> = cores
                    .iter()
                    .filter(|c| e.covered_on.is_empty() || e.covered_on.contains(&c.as_str()))
                    .map(|c| format!("{c}+{}", e.name))
                    .filter(|s| builds(s))
                    .collect();
                if !on_cores.is_empty() {
                    out.extend(on_cores);
                    continue;
                }
                // A suffix that only follows another one (`+falloff` scales the retro lobe
                // before it): after each suffix it accepts, on the first core model (the
                // suffix's code does not depend on the core).
                for t in extra
                    .iter()
                    .filter(|t| matches!(t.build, Builder::Suffix(_)))
                {
                    if let Some(c) = cores.iter().find(|c| builds(&format!("{c}+{}", t.name))) {
                        let s = format!("{c}+{}+{}", t.name, e.name);
                        if builds(&s) {
                            out.push(s);
                        }
                    }
                }
            }
        }
    }
    // A suffix that changes the nodes of another suffix (`+aniso` turns `+coat`'s lobe
    // anisotropic) makes node functions no spec above has: after each such suffix, on
    // the first core model it follows.
    let functions = |spec: &str| -> Vec<String> {
        let mut v = Vec::new();
        if let Ok(node) = Ast::parse(spec)
            .map_err(|e| e.to_string())
            .and_then(|a| build(&a))
        {
            node.visit(&mut |n| v.push(n.bsdf.wgsl().function));
        }
        v
    };
    let mut covered: Vec<String> = out.iter().flat_map(|s| functions(s)).collect();
    // `s` joins the specs when it builds node functions none of them has.
    let add_if_new = |s: String, out: &mut Vec<String>, covered: &mut Vec<String>| {
        let new: Vec<String> = functions(&s)
            .into_iter()
            .filter(|f| !covered.contains(f))
            .collect();
        if !new.is_empty() && !out.contains(&s) {
            covered.extend(new);
            out.push(s);
        }
    };
    for e in extra
        .iter()
        .filter(|e| matches!(e.build, Builder::Suffix(_)))
    {
        for t in extra
            .iter()
            .filter(|t| matches!(t.build, Builder::Suffix(_)))
        {
            let Some(c) = cores.iter().find(|c| builds(&format!("{c}+{}", t.name))) else {
                continue;
            };
            add_if_new(format!("{c}+{}+{}", t.name, e.name), &mut out, &mut covered);
        }
    }
    // Forms only a chain of suffixes makes (`+ndf` then `+fresnel` on `fa`'s highlight or a
    // coat's lobe): each spec so far extended by each suffix, while that makes node
    // functions no spec has.
    let mut i = 0;
    while i < out.len() {
        let base = out[i].clone();
        i += 1;
        for e in extra
            .iter()
            .filter(|e| matches!(e.build, Builder::Suffix(_)))
        {
            add_if_new(format!("{base}+{}", e.name), &mut out, &mut covered);
        }
    }
    out.dedup();
    out
}
/// The specs `bsdfit models` and Python's `bsdfit.models()` list: the default catalogue of each kind, then one example
/// of each model outside it (a suffix with the first spec the registry derives with it).
pub fn listed_specs() -> Vec<String> {
    let mut examples: Vec<String> = catalogue(Kind::Brdf);
    examples.extend(catalogue_for(Kind::Btdf, 2));
    for e in all() {
        if e.catalogue == InCatalogue::No {
            match e.role {
                // The first spec the registry derives with it (`lambert+retro`, or
                // `lambert+retro+falloff` for a suffix that follows another).
                Role::Suffix => {
                    let tail = format!("+{}", e.name);
                    let kind = e.kind.unwrap_or(Kind::Brdf);
                    examples.push(
                        every_spec(kind)
                            .into_iter()
                            .find(|s| s.ends_with(&tail))
                            .unwrap_or_else(|| format!("{}{tail}", catalogue(kind)[0])),
                    )
                }
                _ => examples.push(e.name.to_string()),
            }
        }
    }
    examples
}
