// VMF diffuse (d'Eon & Weidlich, "VMF Diffuse: A Unified Rough Diffuse BRDF", CGF 43(4),
// EGSR 2024; reference shadertoy MXKSWW). f32 twin of src/bsdf/vmf.rs, which documents the
// formula, the sources and the deviations. Parameters (generated accessors, declaration order): rho, r.
// Every global name here starts with vmf_/Vmf/VMF_ (one composed module holds all models).

const VMF_SQRT_PI: f32 = 1.77245385090552;
const VMF_MU_MIN: f32 = 1e-6;
const VMF_M_SWITCH: f32 = 0.25;

// erfc(x) for x >= 0, Abramowitz & Stegun 7.1.26 (abs. error < 1.5e-7).
fn vmf_erfc(x: f32) -> f32 {
    let t = 1.0 / (1.0 + 0.3275911 * x);
    let p = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))));
    return p * exp(-x * x);
}

// Slope m = -ln(1 - sqrt(r)) without cancellation (large but finite at r = 1).
// Below sqrt(r) = 1/2: 2 atanh(z), z = s/(2 - s) <= 1/3, by its series (error < 2e-10).
fn vmf_slope(r: f32) -> f32 {
    let sr = sqrt(r);
    if (sr < 0.5) {
        let z = sr / (2.0 - sr);
        let z2 = z * z;
        var s = 1.0 / 19.0;
        for (var k: i32 = 8; k >= 0; k = k - 1) {
            s = 1.0 / f32(2 * k + 1) + z2 * s;
        }
        return 2.0 * z * s;
    }
    let t = (1.0 - r) / (1.0 + sr);   // = 1 - sqrt(r)
    return -log(max(t, 1e-30));
}

// A_l = I_{l+1/2}(kappa) / I_{1/2}(kappa), l = 0..12, by the backward ratio recurrence.
fn vmf_moments(kappa: f32) -> array<f32, 13> {
    var ratio: array<f32, 13>;
    let lf = 33.5;
    var ratio_next = kappa / (lf + sqrt(lf * lf + kappa * kappa));
    for (var l: i32 = 32; l >= 1; l = l - 1) {
        ratio_next = kappa / (f32(2 * l + 1) + kappa * ratio_next);
        if (l <= 12) {
            ratio[l] = ratio_next;
        }
    }
    var a: array<f32, 13>;
    a[0] = 1.0;
    for (var l: i32 = 1; l <= 12; l = l + 1) {
        a[l] = a[l - 1] * ratio[l];
    }
    return a;
}

// Cross section sigma(u) = E_vMF[max(0, n.w)], u the cosine of w (may be negative).
fn vmf_sigma(u: f32, m: f32, a_in: array<f32, 13>) -> f32 {
    if (m < VMF_M_SWITCH) {
        let pos = max(u, 0.0);
        let ms = m * sqrt(max(1.0 - u * u, 0.0));
        var beckmann = pos;
        if (abs(u) < 9.0 * ms) {
            let x = u / ms;
            var one_plus_erf = 2.0 - vmf_erfc(x);
            if (x < 0.0) {
                one_plus_erf = vmf_erfc(-x);
            }
            beckmann = 0.5 * (ms * exp(-x * x) / VMF_SQRT_PI + u * one_plus_erf);
        }
        return beckmann - 0.5 * m * m * pos;
    }
    var a = a_in;
    var cl = array<f32, 13>(0.25, 0.5, 0.3125, 0.0, -0.09375, 0.0, 0.05078125, 0.0,
                            -0.033203125, 0.0, 0.02392578125, 0.0, -0.018310546875);
    var p_prev = 1.0;
    var p = u;
    var s = cl[0] + cl[1] * a[1] * u;
    for (var l: i32 = 1; l < 12; l = l + 1) {
        let p_next = (f32(2 * l + 1) * u * p - f32(l) * p_prev) / f32(l + 1);
        p_prev = p;
        p = p_next;
        s = s + cl[l + 1] * a[l + 1] * p;
    }
    return s;
}

struct VmfGeometry {
    ui: f32,
    uo: f32,
    prod: f32,   // ui uo
    sum: f32,    // ui + uo
    sin2: f32,   // sin^2(theta_i) sin^2(theta_o)
    cphi: f32,
    c2phi: f32,
}

// C100..C103, C110..C112, C120, C121 of order 1 (rational fits in r).
fn vmf_order1_coefficients(r: f32) -> array<f32, 9> {
    let r2 = r * r;
    let r3 = r2 * r;
    let r4 = r2 * r2;
    return array<f32, 9>(
        1.0 + (-0.1 * r + 0.84 * r4) / (1.0 + 9.0 * r3),
        (0.0173 * r + 20.4 * r2 - 9.47 * r3) / (1.0 + 7.46 * r),
        (-0.927 * r + 2.37 * r2) / (1.24 + r2),
        (-0.11 * r - 1.54 * r2) / (1.0 - 1.05 * r + 7.1 * r2),
        (0.54 * r - 0.182 * r3) / (1.0 + 1.32 * r2),
        (-0.097 * r + 0.62 * r2 - 0.375 * r3) / (1.0 + 0.4 * r3),
        0.283 + 0.862 * r - 0.681 * r2,
        (2.25 * r + 5.1 * r2) / (1.0 + 9.8 * r + 32.4 * r2),
        (-4.32 * r + 6.0 * r3) / (1.0 + 9.7 * r + 287.0 * r3),
    );
}

// Order 1: max(0, f10 + 2 f11 cos(phi) + 2 f12 cos(2 phi)), c from vmf_order1_coefficients.
fn vmf_order1(c: array<f32, 9>, g: VmfGeometry, s_io: f32, den: f32) -> f32 {
    let f10 = (c[0] + c[1] * g.prod + c[2] * g.prod * g.prod + c[3] * (g.ui * g.ui + g.uo * g.uo)) * s_io / den;
    let f11 = sqrt(g.sin2) * (c[4] + c[5] * g.prod) * pow(max(s_io, 1e-30), c[6]) / den;
    let f12 = g.sin2 * (c[7] + c[8] * g.uo) * (c[7] + c[8] * g.ui) / g.sum;
    return max(f10 + 2.0 * f11 * g.cphi + 2.0 * f12 * g.c2phi, 0.0);
}

// C_k00..C_k04 and C_k10..C_k12 of order k = 2 or 3.
struct VmfOrderK {
    c0: array<f32, 5>,
    c1: array<f32, 3>,
}

// Orders 2 and 3: max(0, f_k0 + 2 f_k1 cos(phi)).
fn vmf_order_k(c: VmfOrderK, g: VmfGeometry) -> f32 {
    let c0 = c.c0;
    let c1 = c.c1;
    let fk0 = (c0[0] + c0[1] * g.prod + c0[2] * g.sum + c0[3] * g.prod * g.prod + c0[4] * (g.ui * g.ui + g.uo * g.uo))
        / g.sum;
    let fk1 = sqrt(g.sin2) * (c1[0] + c1[1] * g.prod + c1[2] * g.sum) / g.sum;
    return max(fk0 + 2.0 * fk1 * g.cphi, 0.0);
}

fn vmf_order2_coefficients(r: f32) -> VmfOrderK {
    let r2 = r * r;
    let r3 = r2 * r;
    let r4 = r2 * r2;
    let r25 = r2 * sqrt(r);
    let c0 = array<f32, 5>(
        (0.00056 * r + 0.226 * r2) / (1.0 + 7.07 * r2),
        (-0.268 * r + 4.57 * r2 - 12.04 * r3) / (1.0 + 36.7 * r3),
        (0.418 * r + 2.52 * r2 - 0.97 * r3) / (1.0 + 10.0 * r2),
        (0.068 * r - 2.25 * r2 + 2.65 * r3) / (1.0 + 21.4 * r3),
        (0.05 * r - 4.22 * r3) / (1.0 + 17.6 * r2 + 43.1 * r3),
    );
    let c1 = array<f32, 3>(
        (-0.049 * r - 0.027 * r3) / (1.0 + 3.36 * r2),
        (2.77 * r2 - 8.332 * r25 + 6.073 * r3) / (1.0 + 50.0 * r4),
        (-0.431 * r2 - 0.295 * r3) / (1.0 + 23.9 * r3),
    );
    return VmfOrderK(c0, c1);
}

fn vmf_order3_coefficients(r: f32) -> VmfOrderK {
    let r2 = r * r;
    let r3 = r2 * r;
    let r4 = r2 * r2;
    let sr = sqrt(r);
    let r25 = r2 * sr;
    let r45 = r4 * sr;
    let r5 = r4 * r;
    let c0 = array<f32, 5>(
        (-0.083 * r3 + 0.262 * r4) / (1.0 - 1.9 * r2 + 38.6 * r4),
        (-0.627 * r2 + 4.95 * r25 - 2.44 * r3) / (1.0 + 31.5 * r4),
        (0.33 * r2 + 0.31 * r25 + 1.4 * r3) / (1.0 + 20.0 * r3),
        (-0.74 * r2 + 1.77 * r25 - 4.06 * r3) / (1.0 + 215.0 * r5),
        (-1.026 * r3) / (1.0 + 5.81 * r2 + 13.2 * r3),
    );
    let c1 = array<f32, 3>(
        (0.028 * r2 - 0.0132 * r3) / (1.0 + 7.46 * r2 - 3.315 * r4),
        (-0.134 * r2 + 0.162 * r25 + 0.302 * r3) / (1.0 + 57.5 * r45),
        (-0.119 * r2 + 0.5 * r25 - 0.207 * r3) / (1.0 + 18.7 * r3),
    );
    return VmfOrderK(c0, c1);
}

// The residual's factor K for scattering orders >= 4, f_m = max(0, K t) (1/sr, outside the
// 1/pi), t its geometric part; q = 0.0225272 + (r - 0.264641) r.
fn vmf_residual_factor(rho: f32, q: f32) -> f32 {
    let cc = sqrt(max(1.0 - rho, 0.0));
    let ck = (1.0 - 0.5441615108674713 * cc - 0.45302863761693374 * (1.0 - rho)) / (1.0 + 1.4293127703064865 * cc);
    let erf_cc = 1.0 - vmf_erfc(cc);
    let ca = rho / pow(1.0075 + 1.16942 * cc, atan(q * erf_cc));
    return 0.384016 * (ca - 0.341969) * ca * ck;
}

// What VMF depends on at one roughness r > 0, whatever the directions and rho.
struct VmfLobe {
    m: f32,
    a: array<f32, 13>,
    c1: array<f32, 9>,
    c2: VmfOrderK,
    c3: VmfOrderK,
    q: f32,
    t_r: f32,   // |tanh(r) - 0.0898863|
}

fn vmf_lobe(r: f32) -> VmfLobe {
    let m = vmf_slope(r);
    var a: array<f32, 13>;
    if (m >= VMF_M_SWITCH) {
        var kappa = 0.0;
        if (r < 1.0) {
            kappa = 2.0 / (m * m);
        }
        a = vmf_moments(kappa);
    }
    return VmfLobe(m, a, vmf_order1_coefficients(r), vmf_order2_coefficients(r), vmf_order3_coefficients(r),
                   0.0225272 + (r - 0.264641) * r, abs(tanh(r) - 0.0898863));
}

// The lobe of the candidate being evaluated, computed once by `vmf_prepare` when the
// generated module calls it after loading the candidate's parameters (VMF_PREPARED: the
// model has one VMF node; src/engine/wgsl.rs), rather than once per record as the lobe
// depends on r alone. The CPU twin computes it once per parameter vector likewise.
// (A memo keyed on r, updated inside the record loop, was slower on lavapipe.)
var<private> VMF_LOBE: VmfLobe;

// σ(μ) and σ(−μ) of the candidate's lobe at every μ of its problem's μ table (kernel.wgsl),
// computed by `vmf_prepare` (when MU_TABLES) so that the record loop only looks them up:
// σ's Legendre series is a loop, which costs lavapipe much inside the record loop.
var<private> VMF_SIGMA_AT_MU: array<f32, MU_TABLE_LEN>;
var<private> VMF_SIGMA_AT_NEG_MU: array<f32, MU_TABLE_LEN>;

fn vmf_prepare(o: u32) {
    let r = min(vmf_r(o), 1.0);
    if (r > 0.0) {
        VMF_LOBE = vmf_lobe(r);
        if (MU_TABLES) {
            let n = mu_table_len();
            for (var i = 0u; i < n; i = i + 1u) {
                let u = clamp(mu_table_at(i), VMF_MU_MIN, 1.0);
                VMF_SIGMA_AT_MU[i] = vmf_sigma(u, VMF_LOBE.m, VMF_LOBE.a);
                VMF_SIGMA_AT_NEG_MU[i] = vmf_sigma(-u, VMF_LOBE.m, VMF_LOBE.a);
            }
        }
    }
}

fn vmf_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let rho = vmf_rho(o);
    let r = min(vmf_r(o), 1.0);
    if (!(r > 0.0)) {
        return rho * INV_PI;
    }
    var lobe: VmfLobe;
    if (VMF_PREPARED) {
        lobe = VMF_LOBE;
    } else {
        lobe = vmf_lobe(r);
    }
    let ui = clamp(wi.z, VMF_MU_MIN, 1.0);
    let uo = clamp(wo.z, VMF_MU_MIN, 1.0);
    var s_i: f32;
    var s_o: f32;
    var s_mo: f32;
    if (VMF_PREPARED && MU_TABLES) {
        let slots = min(RECORD_MU, vec2<u32>(MU_TABLE_LEN - 1u));
        s_i = VMF_SIGMA_AT_MU[slots.x];
        s_o = VMF_SIGMA_AT_MU[slots.y];
        s_mo = VMF_SIGMA_AT_NEG_MU[slots.y];
    } else {
        s_i = vmf_sigma(ui, lobe.m, lobe.a);
        s_o = vmf_sigma(uo, lobe.m, lobe.a);
        s_mo = vmf_sigma(-uo, lobe.m, lobe.a);
    }
    let den = max(uo * s_i + ui * s_mo, 1e-30);

    let nn = dot(wi.xy, wi.xy) * dot(wo.xy, wo.xy);
    var cphi = 1.0;
    if (nn > 1e-30) {
        cphi = clamp(dot(wi.xy, wo.xy) / sqrt(nn), -1.0, 1.0);
    }
    let g = VmfGeometry(ui, uo, ui * uo, ui + uo, max(1.0 - ui * ui, 0.0) * max(1.0 - uo * uo, 0.0), cphi,
                        2.0 * cphi * cphi - 1.0);

    let orders = rho * vmf_order1(lobe.c1, g, s_i * s_o, den) + rho * rho * vmf_order_k(lobe.c2, g)
        + rho * rho * rho * vmf_order_k(lobe.c3, g);
    let t = -0.0578978 / (0.287663 + g.prod) + lobe.t_r;
    return INV_PI * orders + max(vmf_residual_factor(rho, lobe.q) * t, 0.0);
}
