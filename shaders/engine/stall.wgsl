// The workload of the `hang@N` fault injection (src/engine/gpu/stall.rs): each invocation
// runs one loop within llvmpipe's per-invocation bound of 65,535 iterations; the grid's
// size sets how long the pass takes.
@group(0) @binding(0) var<storage, read_write> sink: array<u32>;

@compute @workgroup_size(64)
fn stall(@builtin(global_invocation_id) id: vec3<u32>) {
    var x = id.x * 2654435761u + id.y;
    for (var i = 0u; i < 60000u; i++) {
        x = (x ^ (x >> 13u)) * 1664525u + i;
    }
    // Stored so that the loop is not removed; which invocation's value lands is moot.
    sink[(id.x + id.y) & 1023u] = x;
}
