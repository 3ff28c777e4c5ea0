// The diffuse body's angular profile made data-driven (`+body`): the diffuse base's value
// times rho(theta_i) rho(theta_o), ln rho a spline on 9 knots in theta (knot_factor,
// knots.wgsl; 0 at normal incidence), shared by the channels. f32 twin of
// src/bsdf/body.rs, which documents the profile and the knots.
// Parameters (generated accessors, declaration order): body1 .. body8; `base` is the
// diffuse base's value.
fn body_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, base: f32) -> f32 {
    let knots = array<f32, 9>(
        0.0,
        body_body1(o),
        body_body2(o),
        body_body3(o),
        body_body4(o),
        body_body5(o),
        body_body6(o),
        body_body7(o),
        body_body8(o),
    );
    return base * (knot_factor(knots, wi.z) * knot_factor(knots, wo.z));
}
