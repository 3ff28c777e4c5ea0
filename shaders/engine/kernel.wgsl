// Batched evaluation kernels: every candidate (a parameter vector of some problem) over
// every sample of its problem, reduced on the device to one cost per candidate — no
// per-sample read-back — or, for `values`, y′ per sample (LM, diagnostics; LM's normal
// equations are then reduced from them on the device, normal.wgsl). How threads map to
// candidates and samples is in lanes_plain.wgsl (GPUs) and lanes_subgroup.wgsl (SIMD CPU
// devices); this file holds what both share.
//
// Samples arrive sorted by channel and the channel loop is outermost, so a thread's
// parameter reads P[at + ch * S + j] use the same offsets in every thread.

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
    // 2, a count the compiler cannot see (`loops_completed`).
    probe_trips: u32,
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

// Resolve candidate c's flat vector into per-channel scalar views at P[at..at + S·C]
// (a thread holding several candidates keeps each at its own `at`).
fn load_params(c: u32, at: u32) {
    let base = c * dims.dim;
    for (var j = 0u; j < S * C; j = j + 1u) {
        P[at + j] = params[base + slots[j]];
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

// The first candidate of a workgroup (CL threads of CPT candidates each).
fn first_candidate(wg: vec3<u32>) -> u32 {
    return (wg.x + wg.y * dims.groups_x) * CL * CPT;
}

// Σ of the loss terms of the candidate whose views start at P[at] over the samples of
// its problem (from `ranges` r), this thread's slice of them: (sum, Neumaier compensation).
fn plain_costs(at: u32, r: u32, slice: u32) -> vec2<f32> {
    var acc = 0.0;
    var comp = 0.0;
    for (var ch = 0u; ch < C; ch = ch + 1u) {
        let end = slots[r + ch + 1u];
        for (var k = slots[r + ch] + slice; k < end; k = k + SL) {
            let s = samples[k];
            let yp = eval_model(s.wi.xyz, s.wo.xyz, at + ch * S);
            let t = loss_term(yp, s.ext.x, s.ext.y, s.wi.w, s.wo.w);
            let sum = acc + t;
            comp = comp + two_sum_err(acc, t, sum);
            acc = sum;
        }
    }
    return vec2<f32>(acc, comp);
}

// The model values of the candidate whose views start at P[at] at each sample of its
// problem (this thread's slice), written to its row of `out` in the samples' original
// order.
fn plain_values(at: u32, r: u32, row: u32, slice: u32) {
    for (var ch = 0u; ch < C; ch = ch + 1u) {
        let end = slots[r + ch + 1u];
        for (var k = slots[r + ch] + slice; k < end; k = k + SL) {
            let s = samples[k];
            out[row + bitcast<u32>(s.ext.w)] = eval_model(s.wi.xyz, s.wo.xyz, at + ch * S);
        }
    }
}

// Whether every loop of this invocation ran to its end. llvmpipe (Mesa's lavapipe) ends
// every loop of a shader invocation once all its loops together have run 65,535
// iterations (LP_MAX_TGSI_LOOP_ITERATIONS, "shared between every loop"), silently: a
// thread walking more samples than that (fewer for models with loops of their own, such
// as micrograin's series) would return a partial sum as if complete. After the limit,
// every loop stops after one iteration, so a loop of two that the compiler cannot
// unroll (its count comes from the host) tells: it ran twice only if the limit was not
// reached. On every other device it always runs twice.
fn loops_completed() -> bool {
    var trips = 0u;
    for (var i = 0u; i < dims.probe_trips; i = i + 1u) {
        trips = trips + 1u;
    }
    return trips == dims.probe_trips;
}

// What an invocation whose loops were cut short writes instead of its result: a NaN with
// a payload the host looks for (src/engine/gpu.rs, LOOPS_CUT_SHORT), to fail loudly.
const LOOPS_CUT_SHORT: u32 = 0x7fa11ed5u;

// A candidate's cost from its compensated sum over the samples of `ranges` r. An
// overflowed (±∞) or NaN sum stays what it is: its compensation is NaN.
fn finish_cost(acc: f32, comp: f32, r: u32) -> f32 {
    let total = select(acc, acc + comp, abs(acc) <= 3.4028235e38);
    return loss_finish(total, f32(slots[r + C] - slots[r]));
}

// The entry points, `costs` and `values`, are in lanes_plain.wgsl (a candidate per thread,
// its samples in SL slices) or lanes_subgroup.wgsl (SIMD CPU devices with subgroups:
// CPT candidates per thread, samples in subgroup tiles); compose() includes one of them.
