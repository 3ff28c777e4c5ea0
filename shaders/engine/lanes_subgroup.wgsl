// How a thread walks its candidate's samples on a SIMD CPU device (lavapipe), with
// subgroups: in sample tiles. Such a device runs a subgroup as the lanes of one SIMD
// register and, for a storage-buffer load, loads lane by lane, with a bounds check each,
// even when every lane reads the same address (Mesa 22's llvmpipe): loading each sample
// in every thread made the kernel's rate the same ≈ 2e7 evaluations/s for every model.
// Here lane l of a subgroup loads sample k0 + l of a tile of as many samples as lanes,
// once, and the subgroup then passes the tile's samples round with subgroupShuffle, a
// register permutation: a lambert poll went from 2.5e7 to 1.6e8 evaluations/s and ggx
// from 2.4e7 to 1.1e8 on lavapipe (2-core AMD EPYC).
//
// Every lane of the subgroup must walk the same samples, so the tiles are used where all
// its lanes' candidates belong to one problem (one fit); a subgroup straddling two
// problems of a batch walks them the plain way. Lanes past the last candidate take part
// (shadowing it) and their results are dropped by the caller.

struct Invocation {
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(subgroup_invocation_id) lane: u32,
    @builtin(subgroup_size) lanes: u32,
}

// The problem of this subgroup's candidates, or u32 max where they are not all the same.
fn subgroup_problem(c: u32) -> u32 {
    let q = owners[2u * c];
    let first = subgroupBroadcastFirst(q);
    return select(0xffffffffu, first, subgroupAll(q == first));
}

fn candidate_costs(inv: Invocation, c: u32, live: bool) -> vec2<f32> {
    load_params(c);
    let q = subgroup_problem(c);
    if (q == 0xffffffffu) {
        return plain_costs(c, ranges(owners[2u * c]), slice(inv.lid));
    }
    let r = ranges(q);
    var acc = 0.0;
    var comp = 0.0;
    for (var ch = 0u; ch < C; ch = ch + 1u) {
        let end = slots[r + ch + 1u];
        for (var k0 = slots[r + ch]; k0 < end; k0 = k0 + inv.lanes) {
            let mine = samples[min(k0 + inv.lane, end - 1u)];
            let n = min(end - k0, inv.lanes);
            for (var j = 0u; j < n; j = j + 1u) {
                let wi = subgroupShuffle(mine.wi, j);
                let wo = subgroupShuffle(mine.wo, j);
                let e = subgroupShuffle(mine.ext.xy, j);
                let yp = eval_model(wi.xyz, wo.xyz, ch * S);
                let t = loss_term(yp, e.x, e.y, wi.w, wo.w);
                let sum = acc + t;
                comp = comp + two_sum_err(acc, t, sum);
                acc = sum;
            }
        }
    }
    return vec2<f32>(acc, comp);
}

fn candidate_values(inv: Invocation, c: u32, live: bool) {
    load_params(c);
    let q = subgroup_problem(c);
    let row = owners[2u * c + 1u];
    if (q == 0xffffffffu) {
        if (live) {
            plain_values(c, ranges(owners[2u * c]), row, slice(inv.lid));
        }
        return;
    }
    let r = ranges(q);
    for (var ch = 0u; ch < C; ch = ch + 1u) {
        let end = slots[r + ch + 1u];
        for (var k0 = slots[r + ch]; k0 < end; k0 = k0 + inv.lanes) {
            let mine = samples[min(k0 + inv.lane, end - 1u)];
            let n = min(end - k0, inv.lanes);
            for (var j = 0u; j < n; j = j + 1u) {
                let wi = subgroupShuffle(mine.wi, j);
                let wo = subgroupShuffle(mine.wo, j);
                let o = subgroupShuffle(bitcast<u32>(mine.ext.w), j);
                let v = eval_model(wi.xyz, wo.xyz, ch * S);
                if (live) {
                    out[row + o] = v;
                }
            }
        }
    }
}
