//! Every generated WGSL module (each catalogue spec × each loss shape) parses and
//! validates with naga — no device needed.

use bsdfit::bsdf::{catalogue, Model};
use bsdfit::data::Kind;
use bsdfit::engine::loss::Term;
use bsdfit::engine::wgsl::{compose, validate, Shape};

#[test]
fn every_generated_module_validates() {
    let mut specs: Vec<String> = catalogue(Kind::Brdf);
    specs.extend(catalogue(Kind::Btdf));
    specs.extend(["lambert+retro", "fa(vmf)+retro", "btdf(gg)+scale+diffuse"].map(String::from));
    let mut failures = Vec::new();
    for spec in &specs {
        for channels in [1usize, 3] {
            let model = match Model::parse(spec, channels) {
                Ok(m) => m,
                Err(e) => {
                    failures.push(format!("{spec}: {e}"));
                    continue;
                }
            };
            for term in [Term::AbsRatio, Term::Square, Term::LogSquare] {
                // With and without μ tables: the models' table and per-record paths.
                for shape in Shape::ALL
                    .into_iter()
                    .flat_map(|s| [true, false].map(|t| s.with_mu_tables(t)))
                {
                    if let Err(e) = validate(&compose(&model, term, shape)) {
                        failures.push(format!("{spec} ({channels} ch, {term:?}, {shape:?}):\n{e}"));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn eval_model_calls_nested_nodes_with_their_offsets() {
    let m = Model::parse("fa(eon)+retro", 3).unwrap();
    let src = bsdfit::engine::wgsl::eval_model_source(&m);
    // retro (offset 0: kr, alpha_r) wraps fa (offset 2: alpha, eta, ks) over eon (offset 5:
    // rho, r), and multiplies its lobe by its efficiency slot (E = 1, no parameter).
    assert!(src.contains("eon_eval(b + 5u, wi, wo)"), "{src}");
    assert!(src.contains("fa_eval(b + 2u, wi, wo, v0)"), "{src}");
    assert!(src.contains("falloff_none_eval(b + 7u, wi, wo)"), "{src}");
    assert!(src.contains("retro_eval(b + 0u, wi, wo, v1, v2)"), "{src}");
    // With +falloff the slot holds the efficiency, whose q follows the model's parameters:
    // mrm82 (0: kr, alpha_r, f0, f82), fa (4), eon (7), then q at 9.
    let m = Model::parse("fa(eon)+mrm82+falloff", 3).unwrap();
    let src = bsdfit::engine::wgsl::eval_model_source(&m);
    assert!(src.contains("eon_eval(b + 7u, wi, wo)"), "{src}");
    assert!(src.contains("fa_eval(b + 4u, wi, wo, v0)"), "{src}");
    assert!(src.contains("falloff_eval(b + 9u, wi, wo)"), "{src}");
    assert!(src.contains("mrm82_eval(b + 0u, wi, wo, v1, v2)"), "{src}");
}

/// The WGSL twins read their parameters only through the accessors generated from the Rust
/// declarations, so the two sides cannot disagree on the order.
#[test]
fn twins_read_parameters_only_through_generated_accessors() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders/bsdf");
    let mut offenders = Vec::new();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        for (i, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            if code.contains("P[") {
                offenders.push(format!("{}:{}: {line}", path.display(), i + 1));
            }
        }
    }
    assert!(offenders.is_empty(), "{}", offenders.join("\n"));
}

/// A run of knots is read in a loop through its first knot's `_run` accessor, which
/// indexes from that knot: one per run (the NDF's, then the Fresnel curve's), none for
/// the other knots.
#[test]
fn a_run_of_knots_gets_one_indexed_accessor_at_its_first_knot() {
    let m = Model::parse("ggx+ndf+fresnel", 1).unwrap();
    let lobe = m
        .nodes()
        .into_iter()
        .find(|n| n.bsdf.wgsl().function == "ggx_ndf_fresnel_eval")
        .expect("the lobe with both factors");
    let src = bsdfit::engine::wgsl::accessors_source(lobe);
    let names: Vec<&str> = lobe.bsdf.params().iter().map(|p| p.name).collect();
    let at = |name: &str| names.iter().position(|&n| n == name).unwrap();
    let run = |name: &str| {
        format!(
            "fn ggx_ndf_fresnel_{name}_run(o: u32, j: u32) -> f32 {{ return P[o + {}u + j]; }}",
            at(name)
        )
    };
    assert!(src.contains(&run("ndf1")), "{src}");
    assert!(src.contains(&run("fresnel1")), "{src}");
    assert_eq!(src.matches("_run(").count(), 2, "{src}");
}

#[test]
fn a_single_vmf_node_is_prepared_once_per_candidate() {
    // dmg(vmf): the VMF base (offset 3 in the scalar view: tau0, beta, rho_g, then the
    // base's rho, r) is prepared by load_params, and its function reads the lobe.
    let m = Model::parse("dmg(vmf)", 3).unwrap();
    let src = compose(&m, Term::Square, Shape::ALL[0]);
    assert!(src.contains("const VMF_PREPARED: bool = true;"), "{src}");
    let load = &src[src.find("fn load_params").unwrap()..];
    let load = &load[..load.find("\n}\n").unwrap()];
    assert!(load.contains("vmf_prepare(3u);"), "{load}");
    // Models without a VMF node call nothing, and their constant is false.
    let m = Model::parse("dmg(eon)", 3).unwrap();
    let src = compose(&m, Term::Square, Shape::ALL[0]);
    assert!(src.contains("const VMF_PREPARED: bool = false;"), "{src}");
    assert!(!src.contains("vmf_prepare("), "{src}");
    // The other branch (several VMF nodes, each computing its own lobe) validates too.
    let m = Model::parse("vmf", 3).unwrap();
    for shape in Shape::ALL {
        let src = compose(&m, Term::Square, shape).replace(
            "const VMF_PREPARED: bool = true;",
            "const VMF_PREPARED: bool = false;",
        );
        assert!(src.contains("const VMF_PREPARED: bool = false;"));
        validate(&src).unwrap_or_else(|e| panic!("{shape:?}: {e}"));
    }
}
