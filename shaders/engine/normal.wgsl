// Levenberg–Marquardt normal equations reduced on the device (the `normal` entry point),
// run right after `values` in the same submission: `out` then holds the model values of
// every group of PD + 1 candidates (the group's point, then the point moved along each
// parameter), and each workgroup reduces one group to NE = PD(PD + 1)/2 + PD + 1 numbers
// in `normal_out`, so the host reads back those instead of (PD + 1) × K values.
//
// With d_j = √w (g(y′_j) − g(y′_0)) (y′_0 the point's value, y′_j the one moved along
// parameter j) and r = √w (g(y′_0) − g(y)), entry e of a group is
//   e < NJJ:            Σ d_a d_b over the samples, a ≤ b (upper triangle, row-major),
//   NJJ ≤ e < NJJ + PD: Σ d_j r,
//   e = NE − 1:         Σ r².
// The host divides by the unit-box steps in f64 (JᵀJ_ab = Σ d_a d_b / (h_a h_b), Jᵀr_j =
// Σ d_j r / h_j), which is the forward-difference Jacobian J_kj = (r_k(moved_j) − r_k) / h_j
// of src/engine/mod.rs. Dividing on the host keeps h (≈ 1e-3) out of f32: products of
// d's overflow f32 only where Σr² would too. A NaN or ±∞ model value propagates as it
// does in the host's f64 arithmetic (NaN − x, ∞ − ∞, 0 · ∞ are NaN; ∞ − x is ∞): a NaN
// value at sample k of candidate j makes row and column j of JᵀJ and Jᵀr_j NaN, one at
// the point makes everything NaN.
//
// Thread (lane, slice) computes entries lane, lane + EL, … over samples slice, slice + SL,
// … with Neumaier-compensated sums, then the SL partial sums are reduced pairwise in
// workgroup memory exactly as the costs kernel does (kernel.wgsl).

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

// g(y1) − g(y0). For g(v) = a v this is a (y1 − y0): the difference of two f32 values
// within a factor 2 of each other is exact (Sterbenz), so the only rounding is the
// product's. Non-finite operands give what the host's a y1 − a y0 gives (see above).
fn residual_g_diff(y1: f32, y0: f32, a: f32) -> f32 {
    if (TERM == 2u) {
        return log1p_f32(a * y1) - log1p_f32(a * y0);
    }
    return a * (y1 - y0);
}

// The first (u) and second (v) factor of entry e: 0 means r, j ≥ 1 means d_{j−1}.
fn entry_factors(e: u32) -> vec2<u32> {
    if (e < NJJ) {
        var a = 0u;
        var rest = e;
        while (rest >= PD - a) {
            rest = rest - (PD - a);
            a = a + 1u;
        }
        return vec2<u32>(a + 1u, a + rest + 1u);
    }
    if (e < NJJ + PD) {
        return vec2<u32>(e - NJJ + 1u, 0u);
    }
    return vec2<u32>(0u, 0u);
}

// Group g of the batch: the workgroup's flat index.
fn normal_group(wg: vec3<u32>) -> u32 {
    return wg.x + wg.y * dims.normal_groups_x;
}

@compute @workgroup_size(EL, SL)
fn normal(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let g = normal_group(wg);
    let live = g < dims.n_groups;
    var row0 = 0u;
    var first = 0u;
    var end = 0u;
    var kq = 0u;
    if (live) {
        // The group's candidates are consecutive: its point is candidate g (PD + 1), whose
        // owner entry gives the problem and where its row of values starts; the moved
        // candidates' rows follow, K_q values apart.
        let c0 = g * (PD + 1u);
        let r = ranges(owners[2u * c0]);
        row0 = owners[2u * c0 + 1u];
        first = slots[r];
        end = slots[r + C];
        kq = end - first;
    }
    // The entry blocks are the same for every thread (NE and EL are constants), so the
    // barriers of the reduction below stay in uniform control flow.
    for (var e0 = 0u; e0 < NE; e0 = e0 + EL) {
        let e = e0 + lid.x;
        var acc = 0.0;
        var comp = 0.0;
        if (live && e < NE) {
            let f = entry_factors(e);
            let row_u = row0 + f.x * kq;
            let row_v = row0 + f.y * kq;
            for (var k = first + slice(lid); k < end; k = k + SL) {
                let s = samples[k];
                let o = bitcast<u32>(s.ext.w);
                let rw = sqrt(s.wi.w);
                let y0 = out[row0 + o];
                var u = rw * (residual_g(y0, s.wo.w) - s.ext.y);
                var v = u;
                if (f.x > 0u) {
                    u = rw * residual_g_diff(out[row_u + o], y0, s.wo.w);
                }
                if (f.y > 0u) {
                    v = rw * residual_g_diff(out[row_v + o], y0, s.wo.w);
                }
                let t = u * v;
                let sum = acc + t;
                comp = comp + two_sum_err(acc, t, sum);
                acc = sum;
            }
        }
        if (SL > 1u) {
            npartial[lid.y * EL + lid.x] = acc;
            npartial_comp[lid.y * EL + lid.x] = comp;
            workgroupBarrier();
            for (var stride = SL / 2u; stride > 0u; stride = stride / 2u) {
                if (lid.y < stride) {
                    let a = npartial[lid.y * EL + lid.x];
                    let b = npartial[(lid.y + stride) * EL + lid.x];
                    let sum = a + b;
                    npartial[lid.y * EL + lid.x] = sum;
                    npartial_comp[lid.y * EL + lid.x] = npartial_comp[lid.y * EL + lid.x]
                        + npartial_comp[(lid.y + stride) * EL + lid.x] + two_sum_err(a, b, sum);
                }
                workgroupBarrier();
            }
            acc = npartial[lid.x];
            comp = npartial_comp[lid.x];
            // The next block overwrites the partial sums: every thread must have read its
            // result first.
            workgroupBarrier();
        }
        if (live && e < NE && lid.y == 0u) {
            // As for costs: an overflowed or NaN sum stays what it is.
            normal_out[g * NE + e] = select(acc, acc + comp, abs(acc) <= 3.4028235e38);
        }
    }
}
