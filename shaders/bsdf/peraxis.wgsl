// `+peraxis`: passes the inner model's value through; the per-plane roughness lives in
// the scalar views the engine resolves per (plane, channel) group. Twin of
// src/bsdf/peraxis.rs.
fn peraxis_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    return inner;
}
