// Per-sample loss terms and their finalisation: the GPU twin of src/loss.rs.
// TERM and FINISH are constants generated per pipeline (see src/backend/wgsl.rs):
// TERM 0 = |y′−y|/(|y′|+|y|+ε) (SMAPE), 1 = (a y′ − a y)², 2 = (ln(1+a y′) − ln(1+a y))².
// FINISH 0 = Σ/K, 1 = sqrt(Σ/K), 2 = Σ.

const LOSS_EPS: f32 = 1e-6;

// `gy` is the measured value already transformed by the term's g (computed in f64).
fn loss_term(yp: f32, y: f32, gy: f32, w: f32, a: f32) -> f32 {
    if (TERM == 0u) {
        return w * abs(yp - y) / (abs(yp) + abs(y) + LOSS_EPS);
    }
    if (TERM == 2u) {
        let d = log(1.0 + a * yp) - gy;
        return w * d * d;
    }
    let d = a * yp - gy;
    return w * d * d;
}

fn loss_finish(sum: f32, k: f32) -> f32 {
    if (FINISH == 0u) {
        return sum / k;
    }
    if (FINISH == 1u) {
        return sqrt(max(sum / k, 0.0));
    }
    return sum;
}
