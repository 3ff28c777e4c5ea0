// Entrance-angle efficiency of a retro lobe. Twin of src/bsdf/falloff.rs.
// A retro lobe multiplies its own value by its efficiency slot: falloff_none_eval (no
// +falloff, E = 1) or falloff_eval, E = (mu_i mu_o)^q.
// Parameters of falloff_eval (generated accessors): q.

fn falloff_none_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    return 1.0;
}

fn falloff_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    // exp(q ln(mu_i mu_o)): exactly 1 at q = 0; mu_i mu_o >= 1e-30 keeps the log finite.
    return exp(falloff_q(o) * log(max(wi.z * wo.z, 1e-30)));
}
