// How a thread walks its candidate's samples, plain form: every thread loads each sample
// it evaluates. On a GPU neighbouring threads read the same sample at once, which the
// hardware serves as one broadcast load. (lanes_subgroup.wgsl is the form for SIMD CPU
// devices.)

struct Invocation {
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
}

fn candidate_costs(inv: Invocation, c: u32, live: bool) -> vec2<f32> {
    if (!live) {
        return vec2<f32>(0.0, 0.0);
    }
    load_params(c);
    return plain_costs(c, ranges(owners[2u * c]), slice(inv.lid));
}

fn candidate_values(inv: Invocation, c: u32, live: bool) {
    if (!live) {
        return;
    }
    load_params(c);
    plain_values(c, ranges(owners[2u * c]), owners[2u * c + 1u], slice(inv.lid));
}
