// How threads map to work, plain form (GPUs, and CPU devices without subgroups): a
// workgroup is CL candidate lanes × SL slices; thread (lane, slice) evaluates candidate
// `lane` on records slice, slice + SL, …, then the SL partial sums of each candidate are
// reduced in workgroup memory to one cost. Neighbouring threads hold different
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
        let sums = plain_costs(q, slice(inv.lid));
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
    if (live && inv.lid.y == 0u) {
        out[c] = cost_sum(vec2<f32>(acc, comp));
    }
    // Any slice's loops cut short spoils the candidate's sum.
    if (live && !loops_completed()) {
        out[c] = bitcast<f32>(LOOPS_CUT_SHORT);
    }
}

@compute @workgroup_size(CL, SL)
fn values(inv: Invocation) {
    let c = first_candidate(inv.wg) + inv.lid.x;
    if (c >= dims.n_candidates) {
        return;
    }
    load_params(c);
    plain_values(owners[2u * c], owners[2u * c + 1u], slice(inv.lid));
    if (!loops_completed()) {
        out[owners[2u * c + 1u]] = bitcast<f32>(LOOPS_CUT_SHORT);
    }
}
