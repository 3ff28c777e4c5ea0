// Levenberg–Marquardt normal equations reduced on the device (the `normal` entry point),
// run right after `values` in the same submission: `out` then holds the model values of
// every group of PD + 1 candidates (the group's point, then the point moved along each
// parameter) at the records of the pass's window, each candidate's row in record-slot
// order (CB slots a record), and workgroup (g, t) reduces group g over the records of
// tile t to NE = PD(PD + 1)/2 + PD + 1 numbers in `normal_out` (at (g·n_tiles + t)·NE),
// so the host reads back those, and adds up the tiles and windows in f64, instead of
// (PD + 1) × K values.
//
// Per sample, the group's PD + 1 residual factors are x_0 = r = √w (g(y′_0) − g(y)) and
// x_{j+1} = d_j = √w (g(y′_j) − g(y′_0)) (y′_0 the point's value, y′_j the one moved along
// parameter j). The sums written, per group, are
//   the upper triangle of Σ d_a d_b (a ≤ b, row-major), then Σ d_j r, then Σ r².
// The host divides by the unit-box steps in f64 (JᵀJ_ab = Σ d_a d_b / (h_a h_b), Jᵀr_j =
// Σ d_j r / h_j), which is the forward-difference Jacobian J_kj = (r_k(moved_j) − r_k) / h_j
// of src/engine/mod.rs. Dividing on the host keeps h (≈ 1e-3) out of f32: products of
// d's overflow f32 only where the moved point's Σr² would too. A NaN or ±∞ model value
// propagates as it does in the host's f64 arithmetic (NaN − x, ∞ − ∞, 0 · ∞ are NaN;
// ∞ − x is ∞): a NaN value at a sample of candidate j makes row and column j of JᵀJ and
// Jᵀr_j NaN, one at the point makes everything NaN.
//
// Two forms of the same sums; the host picks one per device (src/engine/gpu/mod.rs).
//
// `normal` (GPUs): thread (lane, slice) owns row a = lane of the (PD + 1)² Gram matrix Σ x_a x_b and
// walks channel slots slice, slice + SL, … (CB per record, the empty ones skipped) in a loop whose counter is the same in every lane:
// it forms every x_b of the sample (loads at the same address in every lane: broadcasts,
// no gathers — the shape the costs kernel relies on, kernel.wgsl) and its own x_a, and
// adds x_a x_b to PD + 1 Neumaier-compensated sums. Row 0 gives Σ r d_j and Σ r², row
// a ≥ 1 gives Σ d_{a−1} d_b for b ≥ a − 1; the lower triangle is computed and dropped,
// which keeps the loop free of lane-dependent bounds. Lanes beyond PD loop over further
// rows (NB blocks, one unless PD ≥ EL). At the end the SL partial sums of each entry are
// reduced pairwise in workgroup memory exactly as the costs kernel does.

var<workgroup> npartial: array<f32, EL * SL>;
var<workgroup> npartial_comp: array<f32, EL * SL>;

// g(v) of the loss's term shape (loss.wgsl): ln(1 + a v) for the logarithmic BTDF losses,
// a v otherwise (SMAPE has no residuals; it gets those of a v, as on the host).
fn residual_g(v: f32, a: f32) -> f32 {
    if (TERM == 2u) {
        return log1p_f32(a * v);
    }
    return a * v;
}

// Channel slot k of the records (CB per record): whether it holds a sample (its weight
// is not negative), √w, the inner factor a, and g(y) (records hold y itself for SMAPE,
// whose residuals are those of a y).
struct ChannelSlot {
    present: bool,
    rw: f32,
    a: f32,
    gy: f32,
}

fn channel_slot(k: u32) -> ChannelSlot {
    let r = k / CB;
    let v = record_slot(r, k % CB);
    let a = record_texel(r, 1u).w;
    return ChannelSlot(v.y >= 0.0, sqrt(max(v.y, 0.0)), a, select(v.x, a * v.x, TERM == 0u));
}

// Where group g's values are, and which of its slots tile t covers: the point's row
// starts at `row0`, candidate j's at row0 + j·`stride`; the tile's slots are
// [first, end) (global slot numbers, CB per record), and slot k is at offset
// k − `base` of a row.
struct GroupTile {
    row0: u32,
    stride: u32,
    base: u32,
    first: u32,
    end: u32,
}

fn group_tile(g: u32, t: u32) -> GroupTile {
    // The group's candidates are consecutive: its point is candidate g (PD + 1), whose
    // owner entry gives the problem and where its row of values starts; the moved
    // candidates' rows follow, one window of the problem's slots apart.
    let c0 = g * (PD + 1u);
    let q = owners[2u * c0];
    let w = window_range(q);
    let tile = tile_range(q, t);
    return GroupTile(owners[2u * c0 + 1u], (w.y - w.x) * CB, w.x * CB, tile.x * CB, tile.y * CB);
}

// g(y1) − g(y0). For g(v) = a v this is a (y1 − y0): the difference of two f32 values
// within a factor 2 of each other is exact (Sterbenz), so the only rounding is the
// product's. Non-finite operands give what the host's a y1 − a y0 gives (see above).
fn residual_g_diff(y1: f32, y0: f32, a: f32) -> f32 {
    if (TERM == 2u) {
        return log1p_f32(a * y1) - log1p_f32(a * y0);
    }
    return a * (y1 - y0);
}

// Where Σ x_a x_b goes in a group's NE outputs, or NE when it is not one of them (the
// lower triangle, and rows past PD).
fn normal_slot(a: u32, b: u32) -> u32 {
    if (a == 0u) {
        // Σ r², then Σ d_j r after the triangle.
        return select(NJJ + b - 1u, NE - 1u, b == 0u);
    }
    if (a > PD || b < a) {
        return NE;
    }
    // (a − 1, b − 1) in the row-major upper triangle of a PD × PD matrix.
    let i = a - 1u;
    return i * PD - (i * (i - 1u)) / 2u + (b - a);
}

@compute @workgroup_size(EL, SL)
fn normal(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    // Group g of the batch (the same for every thread of the workgroup).
    let g = wg.x + wg.y * dims.normal_groups_x;
    let live = g < dims.n_groups;
    var gt = GroupTile(0u, 0u, 0u, 0u, 0u);
    if (live) {
        gt = group_tile(g, wg.z);
    }
    let row0 = gt.row0;
    let base = gt.base;
    let kq = gt.stride;
    let first = gt.first;
    let end = gt.end;
    for (var block = 0u; block < NB; block = block + 1u) {
        let a = block * EL + lid.x;
        // Lanes past the last row repeat row 0; nothing of theirs is written.
        let own = select(0u, a, a <= PD);
        var acc: array<f32, PD + 1u>;
        var comp: array<f32, PD + 1u>;
        for (var k = first + slice(lid); k < end; k = k + SL) {
            let s = channel_slot(k);
            if (!s.present) {
                continue;
            }
            let y0 = out[row0 + (k - base)];
            let r = s.rw * (residual_g(y0, s.a) - s.gy);
            var xa = r;
            if (own > 0u) {
                xa = s.rw * residual_g_diff(out[row0 + own * kq + (k - base)], y0, s.a);
            }
            for (var b = 0u; b <= PD; b = b + 1u) {
                var xb = r;
                if (b > 0u) {
                    xb = s.rw * residual_g_diff(out[row0 + b * kq + (k - base)], y0, s.a);
                }
                let t = xa * xb;
                let sum = acc[b] + t;
                comp[b] = comp[b] + two_sum_err(acc[b], t, sum);
                acc[b] = sum;
            }
        }
        for (var b = 0u; b <= PD; b = b + 1u) {
            var total = acc[b];
            var total_comp = comp[b];
            if (SL > 1u) {
                let me = lid.y * EL + lid.x;
                npartial[me] = total;
                npartial_comp[me] = total_comp;
                workgroupBarrier();
                for (var stride = SL / 2u; stride > 0u; stride = stride / 2u) {
                    if (lid.y < stride) {
                        let x = npartial[me];
                        let y = npartial[me + stride * EL];
                        let sum = x + y;
                        npartial[me] = sum;
                        npartial_comp[me] = npartial_comp[me] + npartial_comp[me + stride * EL]
                            + two_sum_err(x, y, sum);
                    }
                    workgroupBarrier();
                }
                total = npartial[lid.x];
                total_comp = npartial_comp[lid.x];
                // The next entry overwrites the partial sums: every thread must have read
                // its result first.
                workgroupBarrier();
            }
            let slot = normal_slot(a, b);
            if (live && lid.y == 0u && slot < NE) {
                // As for costs: an overflowed or NaN sum stays what it is.
                normal_out[(g * dims.n_tiles + wg.z) * NE + slot] =
                    select(total, total + total_comp, abs(total) <= 3.4028235e38);
            }
        }
    }
}

// `normal_by_samples` (CPU devices, lavapipe, SL = 1): a workgroup's lanes are SIMD lanes
// there, and each load from a storage buffer costs about as much as a model evaluation's
// arithmetic, so the row-per-lane form, which loads every factor again in every SIMD chunk
// of rows, took three times the `values` pass. Here lane i walks channel slots i, i + NSL, …,
// loads and forms the sample's PD + 1 factors once, and adds all NE products to private
// compensated sums; the NSL partial sums of each entry are then added up in workgroup
// memory, NBLK entries at a time (measured on a 2-core lavapipe: rmg(eon), 16 groups of
// 383 samples, 4–5 ms for the pass, against 25–40 ms for the row-per-lane form).
const NBLK: u32 = 16u;
// Threads of a `normal_by_samples` workgroup: its own constant, since the evaluation
// kernel's lane count CL depends on its shape (8 under subgroup tiles, below NBLK).
const NSL: u32 = 64u;
var<workgroup> nblock: array<f32, NSL * NBLK>;
var<workgroup> nblock_comp: array<f32, NSL * NBLK>;
// Set by a thread whose loops were cut short (kernel.wgsl, `loops_completed`); zero at
// the start (wgpu zero-initialises workgroup memory).
var<workgroup> ncut_short: atomic<u32>;

@compute @workgroup_size(NSL)
fn normal_by_samples(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let g = wg.x + wg.y * dims.normal_groups_x;
    let live = g < dims.n_groups;
    var gt = GroupTile(0u, 0u, 0u, 0u, 0u);
    if (live) {
        gt = group_tile(g, wg.z);
    }
    let row0 = gt.row0;
    let base = gt.base;
    let kq = gt.stride;
    let first = gt.first;
    let end = gt.end;
    var acc: array<f32, NE>;
    var comp: array<f32, NE>;
    var x: array<f32, PD + 1u>;
    for (var k = first + lid.x; k < end; k = k + NSL) {
        let s = channel_slot(k);
        if (!s.present) {
            continue;
        }
        let y0 = out[row0 + (k - base)];
        x[0] = s.rw * (residual_g(y0, s.a) - s.gy);
        for (var j = 1u; j <= PD; j = j + 1u) {
            x[j] = s.rw * residual_g_diff(out[row0 + j * kq + (k - base)], y0, s.a);
        }
        var e = 0u;
        for (var a = 1u; a <= PD; a = a + 1u) {
            for (var b = a; b <= PD; b = b + 1u) {
                let t = x[a] * x[b];
                let sum = acc[e] + t;
                comp[e] = comp[e] + two_sum_err(acc[e], t, sum);
                acc[e] = sum;
                e = e + 1u;
            }
        }
        for (var j = 0u; j <= PD; j = j + 1u) {
            // Σ d_j r, then Σ r² (j = PD + 1 − 1 wraps to the factor r itself).
            let t = x[(j + 1u) % (PD + 1u)] * x[0];
            let sum = acc[e] + t;
            comp[e] = comp[e] + two_sum_err(acc[e], t, sum);
            acc[e] = sum;
            e = e + 1u;
        }
    }
    if (!loops_completed()) {
        atomicStore(&ncut_short, 1u);
    }
    for (var b0 = 0u; b0 < NE; b0 = b0 + NBLK) {
        for (var i = 0u; i < NBLK; i = i + 1u) {
            if (b0 + i < NE) {
                nblock[i * NSL + lid.x] = acc[b0 + i];
                nblock_comp[i * NSL + lid.x] = comp[b0 + i];
            }
        }
        workgroupBarrier();
        let e = b0 + lid.x;
        if (live && lid.x < NBLK && e < NE) {
            var total = 0.0;
            var total_comp = 0.0;
            for (var l = 0u; l < NSL; l = l + 1u) {
                let v = nblock[lid.x * NSL + l];
                let sum = total + v;
                total_comp = total_comp + nblock_comp[lid.x * NSL + l] + two_sum_err(total, v, sum);
                total = sum;
            }
            normal_out[(g * dims.n_tiles + wg.z) * NE + e] = select(total, total + total_comp, abs(total) <= 3.4028235e38);
        }
        workgroupBarrier();
    }
    if (live && lid.x == 0u && atomicLoad(&ncut_short) != 0u) {
        normal_out[(g * dims.n_tiles + wg.z) * NE] = bitcast<f32>(LOOPS_CUT_SHORT);
    }
}
