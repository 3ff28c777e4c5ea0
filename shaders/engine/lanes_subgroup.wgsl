// How threads map to work on a SIMD CPU device with subgroups (lavapipe): a candidate
// per thread, records in subgroup tiles.
//
// Why: such a device runs a subgroup as the lanes of one SIMD register and, for a
// storage-buffer load, loads lane by lane with a bounds check each, even when every lane
// reads the same address (Mesa 22's llvmpipe). Loading each sample in every thread made
// the kernel's rate the same ≈ 2e7 evaluations/s for every model on a 2-core AMD EPYC,
// lambert and ggx alike: loads, not the model, bounded it. So lane l of a subgroup loads
// record k0 + l of a tile of as many records as lanes, once, and the subgroup passes the
// tile's records round with subgroupShuffle (a register permutation). Measured there
// (lambert, ggx evals/s): 2.5e7, 2.4e7 loading every sample in every thread; 1.7e8,
// 1.1e8 with tiles; with the loads out of the loop altogether (wrong results, a bound)
// 6.7–8.8e8, 2.3e8. (Several candidates per thread, so that one load serves more of
// them, ran faster still, 16: ggx 2.9e8, but lavapipe compiled those pipelines 13×
// slower and they multiply a thread's loop iterations, which llvmpipe caps.)
//
// Thread x of a workgroup holds candidate first + x, so a subgroup's lanes hold
// consecutive candidates. Every lane of a subgroup must walk the same records, so the
// tiles are used where all its lanes' candidates belong to one problem (one fit); a
// subgroup straddling problems of a batch walks each candidate's records the plain way.
// Lanes past the last candidate shadow it (every lane must take part in the shuffles)
// and write nothing.

struct Invocation {
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
    @builtin(subgroup_size) lanes: u32,
}

// This thread's candidate (the last one for lanes past it), its parameters loaded into P.
fn load_candidate(inv: Invocation) -> u32 {
    let c = min(first_candidate(inv.wg) + inv.lid.x, dims.n_candidates - 1u);
    load_params(c);
    return c;
}

// The problem of every candidate of the subgroup, or NO_SAMPLE where they differ.
fn subgroup_problem(q: u32) -> u32 {
    return select(NO_SAMPLE, q, subgroupAll(q == subgroupBroadcastFirst(q)));
}

fn is_live(inv: Invocation) -> bool {
    return first_candidate(inv.wg) + inv.lid.x < dims.n_candidates;
}

// Whether no lane of this subgroup holds a candidate (the last workgroup of a small
// batch): it returns at once rather than shadow the last candidate, whose work the
// SIMD device would otherwise repeat for every such subgroup. Uniform in the subgroup,
// and the kernels have no workgroup barrier.
fn subgroup_idle(inv: Invocation) -> bool {
    return !subgroupAny(is_live(inv));
}

@compute @workgroup_size(CL, 1)
fn costs(inv: Invocation) {
    if (subgroup_idle(inv)) {
        return;
    }
    let c = load_candidate(inv);
    let q = owners[2u * c];
    let range = tile_range(q, inv.wg.z);
    var acc = vec2<f32>(0.0, 0.0);
    if (subgroup_problem(q) == NO_SAMPLE) {
        acc = plain_costs(range, 0u);
    } else {
        let end = range.y;
        for (var k0 = range.x; k0 < end; k0 = k0 + inv.lanes) {
            // Each loaded component costs a lane-by-lane loop: only what the loss needs.
            let mine = min(k0 + inv.lane, end - 1u);
            let my_wi = record_texel(mine, 0u);
            let my_wo = record_texel(mine, 1u);
            let my_obs = record_obs(mine);
            let n = min(end - k0, inv.lanes);
            for (var j = 0u; j < n; j = j + 1u) {
                let wi = subgroupShuffle(my_wi, j);
                let wo = subgroupShuffle(my_wo, j);
                let y = eval_record(wi.xyz, wo.xyz, begin_record(wi.w));
                acc = record_costs(acc, y, shuffle_obs(my_obs, j), wo.w);
            }
        }
    }
    let completed = loops_completed();
    if (is_live(inv)) {
        out[c * dims.n_tiles + inv.wg.z] = select(bitcast<f32>(LOOPS_CUT_SHORT), cost_sum(acc), completed);
    }
}

@compute @workgroup_size(CL, 1)
fn values(inv: Invocation) {
    if (subgroup_idle(inv)) {
        return;
    }
    let c = load_candidate(inv);
    let q = owners[2u * c];
    let row = owners[2u * c + 1u];
    let range = tile_range(q, inv.wg.z);
    let first = window_range(q).x;
    if (subgroup_problem(q) == NO_SAMPLE) {
        if (is_live(inv)) {
            plain_values(range, first, row, 0u);
        }
    } else {
        let end = range.y;
        for (var k0 = range.x; k0 < end; k0 = k0 + inv.lanes) {
            let mine = min(k0 + inv.lane, end - 1u);
            let my_wi = record_texel(mine, 0u);
            let my_wo = record_texel(mine, 1u).xyz;
            let n = min(end - k0, inv.lanes);
            for (var j = 0u; j < n; j = j + 1u) {
                let wi = subgroupShuffle(my_wi, j);
                let y = eval_record(wi.xyz, subgroupShuffle(my_wo, j), begin_record(wi.w));
                // A lane past the last candidate shadows it and stores the very same
                // values to the same places: no branch on liveness inside the tile.
                store_values(row + (k0 + j - first) * CB, y);
            }
        }
    }
    // Where this thread's loops were cut short, the first value of its tile says so.
    if (is_live(inv) && !loops_completed() && range.x < range.y) {
        out[row + (range.x - first) * CB] = bitcast<f32>(LOOPS_CUT_SHORT);
    }
}
