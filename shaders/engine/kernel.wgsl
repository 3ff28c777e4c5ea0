// Batched evaluation kernels. A workgroup is CL candidate lanes × SL sample slices:
// thread (lane, slice) evaluates candidate `lane` on samples slice, slice + SL, …, then
// the SL partial sums of each candidate are reduced in workgroup memory to one cost — no
// per-sample read-back. `values` writes y′ per sample instead (LM, diagnostics); LM's
// normal equations are then reduced from them on the device (normal.wgsl).
//
// Why this shape: neighbouring threads (x = lane) hold different candidates but read the
// same sample at the same time, so sample loads are broadcasts and only the parameters
// differ per thread. On a SIMD CPU device (lavapipe) SL = 1: each thread walks all
// samples with a loop counter the compiler sees as uniform, the fastest form there; on a
// GPU SL > 1 keeps enough threads in flight when candidates are few.
// Samples arrive sorted by channel and the channel loop is outermost, so a thread's
// parameter reads P[ch * S + j] use the same offsets in every thread.

struct Sample {
    wi: vec4<f32>,   // xyz: incident direction; w: loss weight
    wo: vec4<f32>,   // xyz: outgoing direction; w: inner factor a
    ext: vec4<f32>,  // x: y, y: g(y), z: channel, w: original sample index (bits of a u32)
}

struct Dims {
    n_candidates: u32,
    n_problems: u32,
    dim: u32,
    groups_x: u32,
    // The `normal` pass (normal.wgsl): groups of dim + 1 candidates, workgroups per row.
    n_groups: u32,
    normal_groups_x: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> dims: Dims;
@group(0) @binding(1) var<storage, read> samples: array<Sample>;
// slots[g * S + j]: index in a candidate's flat vector of scalar j for group g (a channel,
// or a (plane, channel) pair under `+peraxis`; C counts the groups);
// then per problem q (several independent fits share a dispatch, their samples one after
// the other): slots[S * C + q * (C + 1) + g] = first sample of group g of problem q, and
// slots[S * C + q * (C + 1) + C] = one past its last sample.
@group(0) @binding(2) var<storage, read> slots: array<u32>;
@group(0) @binding(3) var<storage, read> params: array<f32>;
@group(0) @binding(4) var<storage, read_write> out: array<f32>;
// Lookup table of models that need one (GG's Smith Λ); a single zero otherwise.
@group(0) @binding(5) var<storage, read> LUT: array<f32>;
// owners[2c] = the problem of candidate c; owners[2c + 1] = where its row of model values
// starts in `out` (values entry point only).
@group(0) @binding(6) var<storage, read> owners: array<u32>;
// The `normal` pass's output: NE numbers per group of dim + 1 candidates (normal.wgsl).
@group(0) @binding(7) var<storage, read_write> normal_out: array<f32>;

var<workgroup> partial: array<f32, CL * SL>;
var<workgroup> partial_comp: array<f32, CL * SL>;

// Neumaier's compensated addition (Neumaier 1974, "Rundungsfehleranalyse einiger
// Verfahren zur Summation endlicher Summen"; Kahan–Babuška): s = acc + x rounded, and the
// exact rounding error of that addition, (acc − s) + x or (x − s) + acc with the larger
// operand first, is returned to be added to the running compensation. Without it an f32
// cost that has absorbed one large term drops every later term below half its ulp
// (tests/gpu_accuracy.rs). naga emits plain SPIR-V float ops and lavapipe does not
// reassociate them, so the error term is not optimised away (the same test checks it).
fn two_sum_err(acc: f32, x: f32, s: f32) -> f32 {
    return select((x - s) + acc, (acc - s) + x, abs(acc) >= abs(x));
}

// Resolve candidate c's flat vector into this thread's per-channel scalar views.
fn load_params(c: u32) {
    let base = c * dims.dim;
    for (var j = 0u; j < S * C; j = j + 1u) {
        P[j] = params[base + slots[j]];
    }
}

// The thread's sample slice; a constant 0 when SL = 1, so the sample index is a plain
// uniform loop counter the compiler can see (broadcast loads on SIMD CPU devices).
fn slice(lid: vec3<u32>) -> u32 {
    if (SL == 1u) {
        return 0u;
    }
    return lid.y;
}

// Where problem q's sample ranges start in `slots`.
fn ranges(q: u32) -> u32 {
    return S * C + q * (C + 1u);
}

fn candidate(wg: vec3<u32>, lid: vec3<u32>) -> u32 {
    return (wg.x + wg.y * dims.groups_x) * CL + lid.x;
}

// Σ of candidate c's loss terms over its problem's samples (from `ranges` r), this
// thread's slice of them: (sum, Neumaier compensation).
fn plain_costs(c: u32, r: u32, slice: u32) -> vec2<f32> {
    var acc = 0.0;
    var comp = 0.0;
    for (var ch = 0u; ch < C; ch = ch + 1u) {
        let end = slots[r + ch + 1u];
        for (var k = slots[r + ch] + slice; k < end; k = k + SL) {
            let s = samples[k];
            let yp = eval_model(s.wi.xyz, s.wo.xyz, ch * S);
            let t = loss_term(yp, s.ext.x, s.ext.y, s.wi.w, s.wo.w);
            let sum = acc + t;
            comp = comp + two_sum_err(acc, t, sum);
            acc = sum;
        }
    }
    return vec2<f32>(acc, comp);
}

// Candidate c's model value at each sample of its problem (this thread's slice), written
// to its row of `out` in the samples' original order.
fn plain_values(c: u32, r: u32, row: u32, slice: u32) {
    for (var ch = 0u; ch < C; ch = ch + 1u) {
        let end = slots[r + ch + 1u];
        for (var k = slots[r + ch] + slice; k < end; k = k + SL) {
            let s = samples[k];
            out[row + bitcast<u32>(s.ext.w)] = eval_model(s.wi.xyz, s.wo.xyz, ch * S);
        }
    }
}

// The entry points take an `Invocation` and call `candidate_costs` / `candidate_values`,
// both from lanes_plain.wgsl, or from lanes_subgroup.wgsl where the device has subgroups
// and the shape asks for sample tiles (see there): compose() includes one of the two.

@compute @workgroup_size(CL, SL)
fn costs(inv: Invocation) {
    let c = candidate(inv.wg, inv.lid);
    let live = c < dims.n_candidates;
    // A lane past the last candidate shadows it, so that every lane of a SIMD group takes
    // part in whatever the group does together; it writes nothing.
    let cc = min(c, dims.n_candidates - 1u);
    let r = ranges(owners[2u * cc]);
    var sums = candidate_costs(inv, cc, live);
    var acc = sums.x;
    var comp = sums.y;
    if (SL > 1u) {
        partial[inv.lid.y * CL + inv.lid.x] = acc;
        partial_comp[inv.lid.y * CL + inv.lid.x] = comp;
        workgroupBarrier();
        for (var stride = SL / 2u; stride > 0u; stride = stride / 2u) {
            if (inv.lid.y < stride) {
                // Pairwise: the two partial sums added with their rounding error, and both
                // partial compensations carried along.
                let a = partial[inv.lid.y * CL + inv.lid.x];
                let b = partial[(inv.lid.y + stride) * CL + inv.lid.x];
                let sum = a + b;
                partial[inv.lid.y * CL + inv.lid.x] = sum;
                partial_comp[inv.lid.y * CL + inv.lid.x] = partial_comp[inv.lid.y * CL + inv.lid.x]
                    + partial_comp[(inv.lid.y + stride) * CL + inv.lid.x] + two_sum_err(a, b, sum);
            }
            workgroupBarrier();
        }
        acc = partial[inv.lid.x];
        comp = partial_comp[inv.lid.x];
    }
    if (live && inv.lid.y == 0u) {
        // An overflowed (±∞) or NaN sum stays what it is: its compensation is NaN.
        let total = select(acc, acc + comp, abs(acc) <= 3.4028235e38);
        out[c] = loss_finish(total, f32(slots[r + C] - slots[r]));
    }
}

@compute @workgroup_size(CL, SL)
fn values(inv: Invocation) {
    let c = candidate(inv.wg, inv.lid);
    candidate_values(inv, min(c, dims.n_candidates - 1u), c < dims.n_candidates);
}
