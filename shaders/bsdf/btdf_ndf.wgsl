// The transmission lobe of `btdf(tr)` with the data-driven NDF (`btdf(tr)+ndf`): Walter's
// transmission (btdf.wgsl) with D and the Smith G1/|mu| of the NDF table (ndf.wgsl, in
// NDF_TABLE: a BTDF model has one lobe). f32 twin of src/bsdf/btdf_ndf.rs.

// Parameters: alpha, eta, ndf1 .. ndf31.
fn btdf_ndf_prepare(o: u32) {
    for (var k = 1u; k < NDF_KNOTS; k = k + 1u) {
        NDF_TABLE.s[k] = btdf_ndf_ndf1_run(o, k - 1u);
    }
    ndf_build(&NDF_TABLE, btdf_ndf_alpha(o));
}

fn btdf_ndf_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (!BTDF_NDF_PREPARED) {
        btdf_ndf_prepare(o);
    }
    let g = btdf_geometry(wi, wo, btdf_ndf_eta(o));
    if (!g.valid) {
        return 0.0;
    }
    let d = ndf_d(&NDF_TABLE, g.m);
    return btdf_transmit(g, d, ndf_g1_over_mu(&NDF_TABLE, wi), ndf_g1_over_mu(&NDF_TABLE, wo));
}
