// A tabulated log-factor on 9 knots in a cosine c (`+fresnel`: c = cos theta_d, `+body`:
// c = mu_i and mu_o): s is a Catmull-Rom spline through the knots at x = 8 (1 - c),
// continued linearly past both ends; s[0] (c = 1) is 0. f32 twin of `log_factor` and
// `knot_coordinate` in src/bsdf/fresnel.rs, which documents the knots.

const FACTOR_KNOTS: u32 = 9u;

// exp(s(x)) for the knots s at the cosine c.
fn knot_factor(knots: array<f32, 9>, c: f32) -> f32 {
    var s = knots;
    let x = clamp(8.0 * (1.0 - c), 0.0, 8.0);
    let k = min(u32(x), FACTOR_KNOTS - 2u);
    let t = x - f32(k);
    var p0 = 2.0 * s[0] - s[1];
    if (k > 0u) {
        p0 = s[k - 1u];
    }
    let p1 = s[k];
    let p2 = s[k + 1u];
    var p3 = 2.0 * s[FACTOR_KNOTS - 1u] - s[FACTOR_KNOTS - 2u];
    if (k + 2u < FACTOR_KNOTS) {
        p3 = s[k + 2u];
    }
    let a = 2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3;
    let b = -p0 + 3.0 * (p1 - p2) + p3;
    return exp(0.5 * (2.0 * p1 + t * ((p2 - p0) + t * (a + t * b))));
}
