// Anisotropic microfacet lobes (`M+aniso`): α_u along the tangent u, α_v along the
// bitangent v, the frame turned by φ0 degrees about the normal. Twin of src/bsdf/stretched.rs
// (the formulas and their sources are there), of the reflection lobes' anisotropic forms
// in ggx.rs, fa.rs and coat.rs, and of the `+aniso` suffix (aniso.rs); the BTDF forms are
// in btdf.wgsl. D, G1 in the stretched forms of Heitz 2014, §5.3, evaluated on the
// directions turned into the tangent frame.

const ANISO_DEG: f32 = 0.017453292519943295;

// (cos φ0, sin φ0).
fn aniso_frame(phi0: f32) -> vec2<f32> {
    let a = phi0 * ANISO_DEG;
    return vec2<f32>(cos(a), sin(a));
}

// w in the tangent frame: (w·u, w·v, w·n).
fn aniso_local(w: vec3<f32>, f: vec2<f32>) -> vec3<f32> {
    return vec3<f32>(w.x * f.x + w.y * f.y, w.y * f.x - w.x * f.y, w.z);
}

// (α_u ω_x)² + (α_v ω_y)²: α² sin²θ of the isotropic forms.
fn aniso_projected2(au: f32, av: f32, w: vec3<f32>) -> f32 {
    let x = au * w.x;
    let y = av * w.y;
    return x * x + y * y;
}

// (m_x/α_u)² + (m_y/α_v)²: sin²θ/α² of the isotropic forms.
fn aniso_stretched2(au: f32, av: f32, m: vec3<f32>) -> f32 {
    let x = m.x / au;
    let y = m.y / av;
    return x * x + y * y;
}

fn aniso_ggx_d(m: vec3<f32>, au: f32, av: f32) -> f32 {
    if (m.z <= 0.0) {
        return 0.0;
    }
    let t = aniso_stretched2(au, av, m) + m.z * m.z;
    return 1.0 / (PI * au * av * t * t);
}

fn aniso_ggx_g1_over_mu(w: vec3<f32>, au: f32, av: f32) -> f32 {
    let mu = abs(w.z);
    return 2.0 / (mu + sqrt(mu * mu + aniso_projected2(au, av, w)));
}

// D(h) G1(ωi, h) G1(ωo, h) / (4 μi μo) at the unit half vector h (tangent frame).
fn aniso_ggx_reflection(au: f32, av: f32, wi: vec3<f32>, wo: vec3<f32>, h: vec3<f32>) -> f32 {
    if (dot(wi, h) * wi.z <= 0.0 || dot(wo, h) * wo.z <= 0.0) {
        return 0.0;
    }
    return aniso_ggx_d(h, au, av) * aniso_ggx_g1_over_mu(wi, au, av) * aniso_ggx_g1_over_mu(wo, au, av) * 0.25;
}

// F(ωi·h; η) D G1 G1 / (4 μi μo), directions in the data's frame (0 below the surface).
fn aniso_ggx_lobe(au: f32, av: f32, phi0: f32, eta: f32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let f = aniso_frame(phi0);
    let li = aniso_local(wi, f);
    let lo = aniso_local(wo, f);
    let h = half_vector(li, lo);
    return fresnel_dielectric(dot(li, h), eta) * aniso_ggx_reflection(au, av, li, lo, h);
}

fn aniso_beckmann_d(m: vec3<f32>, au: f32, av: f32) -> f32 {
    let c2 = m.z * m.z;
    if (m.z <= 0.0 || c2 < MF_C2_MIN) {
        return 0.0;
    }
    return exp(-aniso_stretched2(au, av, m) / c2 - 2.0 * log(c2)) / (PI * au * av);
}

// The GG shape constants of β_u, β_v: gg_new at β = √(β_u β_v) has the anisotropic
// normalisation ln(p / (π β_u β_v Γ(1/p))).
fn aniso_gg_d(m: vec3<f32>, s: Gg, bu: f32, bv: f32) -> f32 {
    let c2 = m.z * m.z;
    if (m.z <= 0.0 || c2 < MF_C2_MIN) {
        return 0.0;
    }
    let z = aniso_stretched2(bu, bv, m) / c2;
    var e = 0.0;
    if (z > 0.0) {
        e = exp(clamp(s.p * log(z), -80.0, 80.0));
    }
    return exp(s.ln_norm - e - 2.0 * log(c2));
}

fn aniso_gg_g1_over_mu(w: vec3<f32>, s: Gg, bu: f32, bv: f32) -> f32 {
    let mu = abs(w.z);
    let bs = sqrt(aniso_projected2(bu, bv, w));
    let b = bs * s.rc;
    let x = b / (mu + b);
    let t = gg_table(s.p, x);
    return 1.0 / (mu + t * s.j0 * (bs + mu / s.rc));
}

// Parameters (generated accessors, declaration order): ks, alpha_u, alpha_v, phi0, eta.
fn ggx_aniso_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let lobe = aniso_ggx_lobe(ggx_aniso_alpha_u(o), ggx_aniso_alpha_v(o), ggx_aniso_phi0(o), ggx_aniso_eta(o), wi, wo);
    return ggx_aniso_ks(o) * lobe;
}

// Parameters: lobe.alpha_u, lobe.alpha_v, lobe.phi0, lobe.eta, lobe.ks; `base` is the
// base model's value.
fn fa_aniso_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, base: f32) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let eta = fa_aniso_lobe_eta(o);
    let transmit = fresnel_transmittance(wi.z, eta) * fresnel_transmittance(wo.z, eta);
    let lobe = aniso_ggx_lobe(fa_aniso_lobe_alpha_u(o), fa_aniso_lobe_alpha_v(o), fa_aniso_lobe_phi0(o), eta, wi, wo);
    return fa_aniso_lobe_ks(o) * lobe + transmit * base;
}

// Parameters: kc, alpha_c_u, alpha_c_v, phi0_c; `inner` is the wrapped model's value.
fn coat_aniso_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    let kc = coat_aniso_kc(o);
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return (1.0 - kc) * inner;
    }
    let f = aniso_frame(coat_aniso_phi0_c(o));
    let li = aniso_local(wi, f);
    let lo = aniso_local(wo, f);
    let h = half_vector(li, lo);
    return (1.0 - kc) * inner + kc * aniso_ggx_reflection(coat_aniso_alpha_c_u(o), coat_aniso_alpha_c_v(o), li, lo, h);
}

// `+aniso` itself passes its inner model's value through.
fn aniso_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    return inner;
}
