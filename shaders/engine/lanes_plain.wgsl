// How threads map to work, plain form (GPUs, and CPU devices without subgroups): a
// workgroup is CL candidate lanes × SL slices; thread (lane, slice) evaluates candidate
// `lane` on records slice, slice + SL, … of the workgroup's tile (workgroup z), then the
// SL partial sums of each candidate are reduced in workgroup memory to one partial cost
// per (candidate, tile), which the host adds up in f64. Neighbouring threads hold different
// candidates and read the same record at once, which a GPU serves as one broadcast load;
// SL > 1 keeps enough threads in flight when candidates are few.

struct Invocation {
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
}

var<workgroup> partial: array<f32, CL * SL>;
var<workgroup> partial_comp: array<f32, CL * SL>;

@compute @workgroup_size(CL, SL)
fn costs(inv: Invocation) {
    let c = first_candidate(inv.wg) + inv.lid.x;
    let live = c < dims.n_candidates;
    var acc = 0.0;
    var comp = 0.0;
    var q = 0u;
    if (live) {
        q = owners[2u * c];
        load_params(c);
        let sums = plain_costs(tile_range(q, inv.wg.z), slice(inv.lid));
        acc = sums.x;
        comp = sums.y;
    }
    if (SL > 1u) {
        let me = inv.lid.y * CL + inv.lid.x;
        partial[me] = acc;
        partial_comp[me] = comp;
        workgroupBarrier();
        for (var stride = SL / 2u; stride > 0u; stride = stride / 2u) {
            if (inv.lid.y < stride) {
                // Pairwise: the two partial sums added with their rounding error, and both
                // partial compensations carried along.
                let other = me + stride * CL;
                let a = partial[me];
                let b = partial[other];
                let sum = a + b;
                partial[me] = sum;
                partial_comp[me] = partial_comp[me] + partial_comp[other] + two_sum_err(a, b, sum);
            }
            workgroupBarrier();
        }
        acc = partial[inv.lid.x];
        comp = partial_comp[inv.lid.x];
    }
    let o = c * dims.n_tiles + inv.wg.z;
    if (live && inv.lid.y == 0u) {
        out[o] = cost_sum(vec2<f32>(acc, comp));
    }
    // Any slice's loops cut short spoils the candidate's sum.
    if (live && !loops_completed()) {
        out[o] = bitcast<f32>(LOOPS_CUT_SHORT);
    }
}

@compute @workgroup_size(CL, SL)
fn values(inv: Invocation) {
    let c = first_candidate(inv.wg) + inv.lid.x;
    if (c >= dims.n_candidates) {
        return;
    }
    load_params(c);
    let q = owners[2u * c];
    let row = owners[2u * c + 1u];
    let tile = tile_range(q, inv.wg.z);
    plain_values(tile, window_range(q).x, row, slice(inv.lid));
    // Where this thread's loops were cut short, the first value of its tile says so.
    if (!loops_completed() && tile.x < tile.y) {
        out[row + (tile.x - window_range(q).x) * CB] = bitcast<f32>(LOOPS_CUT_SHORT);
    }
}
