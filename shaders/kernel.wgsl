// Batched evaluation kernels. One workgroup per candidate parameter vector: its threads
// stride over every (sample, channel) pair, then reduce in workgroup memory to one cost —
// no per-sample read-back. `values` writes y′ per sample instead (LM, diagnostics).
// The host composes this file after common.wgsl, the model files, the generated
// `eval_model`, and loss.wgsl (src/backend/wgsl.rs).

struct Sample {
    wi: vec4<f32>,   // xyz: incident direction; w: loss weight
    wo: vec4<f32>,   // xyz: outgoing direction; w: inner factor a
    ext: vec4<f32>,  // x: y, y: g(y), z: channel, w: unused
}

struct Dims {
    n_candidates: u32,
    n_samples: u32,
    dim: u32,
    groups_x: u32,
}

@group(0) @binding(0) var<uniform> dims: Dims;
@group(0) @binding(1) var<storage, read> samples: array<Sample>;
// slots[ch * S + j]: index in a candidate's flat vector of scalar j for channel ch.
@group(0) @binding(2) var<storage, read> slots: array<u32>;
@group(0) @binding(3) var<storage, read> params: array<f32>;
@group(0) @binding(4) var<storage, read_write> out: array<f32>;
// Lookup table of models that need one (GG's Smith Λ); a single zero otherwise.
@group(0) @binding(5) var<storage, read> LUT: array<f32>;

var<workgroup> partial: array<f32, WG>;

// Resolve the candidate's flat vector into the per-channel scalar views P[ch * S + j].
fn load_params(c: u32) {
    let base = c * dims.dim;
    for (var j = 0u; j < S * C; j = j + 1u) {
        P[j] = params[base + slots[j]];
    }
}

@compute @workgroup_size(WG)
fn costs(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let c = wg.x + wg.y * dims.groups_x;
    if (c >= dims.n_candidates) {
        return;
    }
    load_params(c);
    var acc = 0.0;
    for (var k = lid; k < dims.n_samples; k = k + WG) {
        let s = samples[k];
        let ch = u32(s.ext.z);
        let yp = eval_model(s.wi.xyz, s.wo.xyz, ch * S);
        acc = acc + loss_term(yp, s.ext.x, s.ext.y, s.wi.w, s.wo.w);
    }
    partial[lid] = acc;
    workgroupBarrier();
    for (var stride = WG / 2u; stride > 0u; stride = stride / 2u) {
        if (lid < stride) {
            partial[lid] = partial[lid] + partial[lid + stride];
        }
        workgroupBarrier();
    }
    if (lid == 0u) {
        out[c] = loss_finish(partial[0], f32(dims.n_samples));
    }
}

@compute @workgroup_size(WG)
fn values(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let c = wg.x + wg.y * dims.groups_x;
    if (c >= dims.n_candidates) {
        return;
    }
    load_params(c);
    for (var k = lid; k < dims.n_samples; k = k + WG) {
        let s = samples[k];
        let ch = u32(s.ext.z);
        out[c * dims.n_samples + k] = eval_model(s.wi.xyz, s.wo.xyz, ch * S);
    }
}
