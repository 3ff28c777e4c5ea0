// Batched evaluation kernels: every candidate (a parameter vector of some problem) over
// every sample of its problem, reduced on the device to one cost per candidate — no
// per-sample read-back — or, for `values`, y′ per sample (LM, diagnostics; LM's normal
// equations are then reduced from them on the device, normal.wgsl). How threads map to
// candidates and samples is in lanes_plain.wgsl (GPUs) and lanes_subgroup.wgsl (SIMD CPU
// devices); this file holds what both share.
//
// Channels together: samples arrive as records, one per direction (and plane), holding
// the measurements of up to CB channels there. A thread evaluates all of a record's
// channels at once (the generated `eval_record`, unrolled), so what does not depend on
// the per-channel parameters is computed once per direction where the compiler can see it
// is shared: it can wherever every parameter index is a constant (FIXED_BASE, one plane
// and at most CB channels: RGB and monochrome data).

// Record r, texel t of the records texture (RPR records of TPR texels per row): texel 0
// holds ωi (xyz) and the record's packed word (w, bits of a u32: its first scalar-view
// group, then the indices of its μi and μo in its problem's μ table), texel 1 ωo
// and the loss's inner factor a, then each texel two channel slots (v, w): the
// measurement as the loss compares it (y for SMAPE, g(y) otherwise) and the loss weight
// (w < 0: no sample in this slot); the generated `record_obs` reads those.
fn record_texel(r: u32, t: u32) -> vec4<f32> {
    let local = r - dims.seg_first;
    return textureLoad(records, vec2<u32>((local % RPR) * TPR + t, local / RPR), 0);
}

// Channel slot i of record r.
fn record_slot(r: u32, i: u32) -> vec2<f32> {
    let t = record_texel(r, 2u + i / 2u);
    return select(t.zw, t.xy, i % 2u == 0u);
}

// The bindings (`dims`, `records`, `tables`, `params`, `out`, `LUT`, `owners`,
// `normal_out`) and the `Dims` struct are declared once, in src/engine/gpu/bindings.rs,
// which writes their WGSL declarations ahead of this file. What they hold:
// - `tables`: per problem q (several independent fits share a dispatch, their records
//   one after the other): tables[3q] = its first record, tables[3q + 1] = one past its
//   last, tables[3q + 2] = its number of samples K_q. Then, for n problems,
//   tables[3n + q] = where problem q's μ table starts: its length there, then its values
//   (f32 bits): the distinct cos θi and cos θo of its records, none where there are more
//   than MU_TABLE_LEN.
// - `owners`: owners[2c] = the problem of candidate c; owners[2c + 1] = where its row of
//   model values starts in `out` (values entry point only).
// - `LUT`: the lookup table of models that need one (GG's Smith Λ), LUT_WIDTH entries per
//   row of an R32F texture (fetched as vectors on CPU devices, like the records); a zero
//   otherwise.
// - `normal_out`: the `normal` pass's output (normal.wgsl).
//
// Records are numbered over the whole batch; the bound `records` texture holds a segment
// of them from dims.seg_first. A pass covers the window [dims.win_first, dims.win_end) of
// those numbers, cut into tiles of dims.tile records: workgroup z = t works on tile t of
// each of its candidates' records there, so that much data spreads over many workgroups
// and no invocation walks more than a tile (llvmpipe's loop limit, `loops_completed`).

const NO_SAMPLE: u32 = 0xffffffffu;

const LUT_WIDTH: u32 = 256u;

// Entry k of the lookup table (shaders/bsdf/microfacet.wgsl reads it through this).
fn lut(k: u32) -> f32 {
    return textureLoad(LUT, vec2<u32>(k % LUT_WIDTH, k / LUT_WIDTH), 0).x;
}

// Neumaier's compensated addition (Neumaier 1974, "Rundungsfehleranalyse einiger
// Verfahren zur Summation endlicher Summen"; Kahan–Babuška): s = acc + x rounded, and the
// exact rounding error of that addition, (acc − s) + x or (x − s) + acc with the larger
// operand first, is returned to be added to the running compensation. Without it an f32
// cost that has absorbed one large term drops every later term below half its ulp
// (tests/gpu_accuracy.rs). A compiler that reassociates float additions sees that
// (acc − (acc + x)) + x is 0 and drops the error: lavapipe does not, NVIDIA's driver
// (580, H200) did in part (the test's cost came out 3.7e-5 low, its bound 3.4e-5; with
// the barrier 1.1e-7). So the sum and the difference pass through `opaque`, which the
// compiler cannot see through.
fn two_sum_err(acc: f32, x: f32, s: f32) -> f32 {
    let so = opaque(s);
    return select(opaque(x - so) + acc, opaque(acc - so) + x, abs(acc) >= abs(x));
}

// v itself, behind a barrier to algebraic rewriting: its bits ORed with a uniform that
// is 0 at run time, unknown at compile time (src/engine/gpu/bindings.rs, `OpaqueZero`).
fn opaque(v: f32) -> f32 {
    return bitcast<f32>(bitcast<u32>(v) | dims.opaque_zero);
}

// The thread's sample slice; a constant 0 when SL = 1, so the record index is a plain
// uniform loop counter the compiler can see (broadcast loads on SIMD CPU devices).
fn slice(lid: vec3<u32>) -> u32 {
    if (SL == 1u) {
        return 0u;
    }
    return lid.y;
}

// A record's packed word: bits 0–11 its first scalar-view group, 12–15 which of its
// CB channel slots hold a sample (bit i: slot i), 16–21 the index of its μi in its
// problem's μ table, 22–27 that of its μo (MU_TABLE_LEN: not in the table).
const MU_TABLE_LEN: u32 = 63u;

// The μ-table indices (μi, μo) of the record being evaluated, set by `begin_record`: a
// model that computes per candidate what depends on μ alone (`rmg_prepare`) looks its
// values up with them instead of computing them in the record loop.
var<private> RECORD_MU: vec2<u32>;

// Which channel slots of that record hold a sample (bit i: slot i), set by
// `begin_record`: the values pass writes 0 to the others (`store_values`).
var<private> RECORD_SLOTS: u32;

// The problem of the candidate being evaluated (set by the generated `load_params`).
var<private> CANDIDATE_PROBLEM: u32;

// Start a record from texel 0's w (its packed word): keep its μ indices in RECORD_MU and
// return where the views of its first group start in a candidate's views (a constant 0
// under FIXED_BASE).
fn begin_record(wi_w: f32) -> u32 {
    let word = bitcast<u32>(wi_w);
    RECORD_MU = vec2<u32>((word >> 16u) & 63u, (word >> 22u) & 63u);
    RECORD_SLOTS = (word >> 12u) & 15u;
    return select((word & 0xfffu) * S, 0u, FIXED_BASE);
}

// The length of the μ table of the candidate's problem (0: it has none).
fn mu_table_len() -> u32 {
    return tables[tables[3u * dims.n_problems + CANDIDATE_PROBLEM]];
}

// Entry i of the μ table of the candidate's problem.
fn mu_table_at(i: u32) -> f32 {
    return bitcast<f32>(tables[tables[3u * dims.n_problems + CANDIDATE_PROBLEM] + 1u + i]);
}

// The compensated sum s (sum, Neumaier compensation) plus the loss term of a channel
// slot o whose model value is yp, a the record's inner factor; an empty slot (w < 0)
// adds nothing, whatever yp is.
fn add_term(s: vec2<f32>, yp: f32, o: vec2<f32>, a: f32) -> vec2<f32> {
    let t = select(loss_term(yp, o.x, o.y, a), 0.0, o.y < 0.0);
    let sum = s.x + t;
    return vec2<f32>(sum, s.y + two_sum_err(s.x, t, sum));
}

// The first candidate of a workgroup (CL threads of a candidate each).
fn first_candidate(wg: vec3<u32>) -> u32 {
    return (wg.x + wg.y * dims.groups_x) * CL;
}

// The records of problem q in this pass's window: [x, y) (empty where it has none).
fn window_range(q: u32) -> vec2<u32> {
    let lo = max(tables[3u * q], dims.win_first);
    let hi = min(tables[3u * q + 1u], dims.win_end);
    return vec2<u32>(lo, max(lo, hi));
}

// The records of problem q in tile t of this pass's window: [x, y).
fn tile_range(q: u32, t: u32) -> vec2<u32> {
    let w = window_range(q);
    let lo = min(w.x + t * dims.tile, w.y);
    return vec2<u32>(lo, min(lo + dims.tile, w.y));
}

// Σ of the loss terms of the thread's candidate (its views in P) over the records
// [range.x, range.y), this thread's slice of them: (sum, Neumaier compensation).
fn plain_costs(range: vec2<u32>, slice: u32) -> vec2<f32> {
    var acc = vec2<f32>(0.0, 0.0);
    let end = range.y;
    for (var k = range.x + slice; k < end; k = k + SL) {
        let wi = record_texel(k, 0u);
        let wo = record_texel(k, 1u);
        acc = record_costs(acc, eval_record(wi.xyz, wo.xyz, begin_record(wi.w)), record_obs(k), wo.w);
    }
    return acc;
}

// The model values of the thread's candidate at the records [range.x, range.y) (this
// thread's slice of them), written to its row of `out`, whose slot i of record k is
// out[row + (k − first)·CB + i], `first` the first record of the candidate's row.
fn plain_values(range: vec2<u32>, first: u32, row: u32, slice: u32) {
    let end = range.y;
    for (var k = range.x + slice; k < end; k = k + SL) {
        let wi = record_texel(k, 0u);
        let y = eval_record(wi.xyz, record_texel(k, 1u).xyz, begin_record(wi.w));
        store_values(row + (k - first) * CB, y);
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

// A candidate's sum of loss terms from its compensated sum over the samples of its
// problem (the host finishes it). An overflowed (±∞) or NaN sum stays what it is: its
// compensation is NaN.
fn cost_sum(acc: vec2<f32>) -> f32 {
    return select(acc.x, acc.x + acc.y, abs(acc.x) <= 3.4028235e38);
}

// The entry points, `costs` and `values`, are in lanes_plain.wgsl (a candidate per thread,
// its samples in SL slices) or lanes_subgroup.wgsl (SIMD CPU devices with subgroups:
// records in subgroup tiles); compose() includes one of them.
