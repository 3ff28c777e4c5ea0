// How threads map to work on a SIMD CPU device with subgroups (lavapipe): CPT candidates
// per thread, samples in subgroup tiles.
//
// Why: such a device runs a subgroup as the lanes of one SIMD register and, for a
// storage-buffer load, loads lane by lane with a bounds check each, even when every lane
// reads the same address (Mesa 22's llvmpipe). Loading each sample in every thread made
// the kernel's rate the same ≈ 2e7 evaluations/s for every model on a 2-core AMD EPYC,
// lambert and ggx alike: loads, not the model, bounded it. So lane l of a subgroup loads
// sample k0 + l of a tile of as many samples as lanes, once, and the subgroup passes the
// tile's samples round with subgroupShuffle (a register permutation); each thread may
// evaluate every sample it has in registers for CPT candidates, so that one load serves
// lanes × CPT candidates (the engine uses CPT = 1: see Shape::CPU_DEVICE_TILED). Measured there (lambert, ggx evals/s): 2.5e7, 2.4e7 loading
// every sample in every thread; 1.7e8, 1.1e8 with tiles; with the loads out of the loop
// altogether (wrong results, a bound) 6.7–8.8e8, 2.3e8.
//
// Thread x of a workgroup holds candidates first + m·CL + x, m < CPT, so a subgroup's
// lanes hold consecutive candidates. Every lane of a subgroup must walk the same samples,
// so the tiles are used where all its lanes' candidates belong to one problem (one fit);
// a subgroup straddling problems of a batch walks each candidate's samples the plain way.
// Slots past the last candidate shadow it (every lane must take part in the shuffles)
// and write nothing.

struct Invocation {
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
    @builtin(subgroup_size) lanes: u32,
}

// This thread's CPT candidates, their parameters loaded at P[m·S·C]; returns the problem
// all of them and the rest of the subgroup share, or u32 max where they do not.
fn load_candidates(inv: Invocation, c: ptr<function, array<u32, CPT>>) -> u32 {
    let first = first_candidate(inv.wg) + inv.lid.x;
    let q0 = subgroupBroadcastFirst(owners[2u * min(first, dims.n_candidates - 1u)]);
    var same = true;
    for (var m = 0u; m < CPT; m = m + 1u) {
        let cm = min(first + m * CL, dims.n_candidates - 1u);
        (*c)[m] = cm;
        load_params(cm, m * S * C);
        same = same && owners[2u * cm] == q0;
    }
    return select(0xffffffffu, q0, subgroupAll(same));
}

fn is_live(inv: Invocation, m: u32) -> bool {
    return first_candidate(inv.wg) + m * CL + inv.lid.x < dims.n_candidates;
}

@compute @workgroup_size(CL, 1)
fn costs(inv: Invocation) {
    var c: array<u32, CPT>;
    let q = load_candidates(inv, &c);
    var acc: array<f32, CPT>;
    var comp: array<f32, CPT>;
    if (q == 0xffffffffu) {
        for (var m = 0u; m < CPT; m = m + 1u) {
            let sums = plain_costs(m * S * C, ranges(owners[2u * c[m]]), 0u);
            acc[m] = sums.x;
            comp[m] = sums.y;
        }
    } else {
        let r = ranges(q);
        for (var ch = 0u; ch < C; ch = ch + 1u) {
            let end = slots[r + ch + 1u];
            for (var k0 = slots[r + ch]; k0 < end; k0 = k0 + inv.lanes) {
                // Only the fields the loss needs: each loaded component costs a
                // lane-by-lane loop.
                let mine = min(k0 + inv.lane, end - 1u);
                let my_wi = samples[mine].wi;
                let my_wo = samples[mine].wo;
                let my_e = samples[mine].ext.xy;
                let n = min(end - k0, inv.lanes);
                for (var j = 0u; j < n; j = j + 1u) {
                    let wi = subgroupShuffle(my_wi, j);
                    let wo = subgroupShuffle(my_wo, j);
                    let e = subgroupShuffle(my_e, j);
                    for (var m = 0u; m < CPT; m = m + 1u) {
                        let yp = eval_model(wi.xyz, wo.xyz, m * S * C + ch * S);
                        let t = loss_term(yp, e.x, e.y, wi.w, wo.w);
                        let sum = acc[m] + t;
                        comp[m] = comp[m] + two_sum_err(acc[m], t, sum);
                        acc[m] = sum;
                    }
                }
            }
        }
    }
    let completed = loops_completed();
    for (var m = 0u; m < CPT; m = m + 1u) {
        if (is_live(inv, m)) {
            out[c[m]] = select(
                bitcast<f32>(LOOPS_CUT_SHORT),
                finish_cost(acc[m], comp[m], ranges(owners[2u * c[m]])),
                completed
            );
        }
    }
}

@compute @workgroup_size(CL, 1)
fn values(inv: Invocation) {
    var c: array<u32, CPT>;
    let q = load_candidates(inv, &c);
    var row: array<u32, CPT>;
    for (var m = 0u; m < CPT; m = m + 1u) {
        row[m] = owners[2u * c[m] + 1u];
    }
    if (q == 0xffffffffu) {
        for (var m = 0u; m < CPT; m = m + 1u) {
            if (is_live(inv, m)) {
                plain_values(m * S * C, ranges(owners[2u * c[m]]), row[m], 0u);
            }
        }
        mark_cut_short(inv, row);
        return;
    }
    let r = ranges(q);
    for (var ch = 0u; ch < C; ch = ch + 1u) {
        let end = slots[r + ch + 1u];
        for (var k0 = slots[r + ch]; k0 < end; k0 = k0 + inv.lanes) {
            let mine = min(k0 + inv.lane, end - 1u);
            let my_wi = samples[mine].wi;
            let my_wo = samples[mine].wo;
            let my_o = bitcast<u32>(samples[mine].ext.w);
            let n = min(end - k0, inv.lanes);
            for (var j = 0u; j < n; j = j + 1u) {
                let wi = subgroupShuffle(my_wi, j);
                let wo = subgroupShuffle(my_wo, j);
                let o = subgroupShuffle(my_o, j);
                for (var m = 0u; m < CPT; m = m + 1u) {
                    // A slot past the last candidate shadows it and stores the very same
                    // value to the same place: no branch on liveness inside the tile.
                    out[row[m] + o] = eval_model(wi.xyz, wo.xyz, m * S * C + ch * S);
                }
            }
        }
    }
    mark_cut_short(inv, row);
}

// Where this thread's loops were cut short, the first value of each of its rows says so.
fn mark_cut_short(inv: Invocation, row: array<u32, CPT>) {
    if (!loops_completed()) {
        for (var m = 0u; m < CPT; m = m + 1u) {
            if (is_live(inv, m)) {
                out[row[m]] = bitcast<f32>(LOOPS_CUT_SHORT);
            }
        }
    }
}
