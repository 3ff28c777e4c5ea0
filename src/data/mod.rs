//! Measurements in: the in-memory [`Dataset`], the v1 CSV format and its validation,
//! channel selection, [`readers`] for the other formats (ALTA text, MERL binary, …),
//! chosen by content, and the named [`geometries`] of synthetic and sampled data.
mod azimuths;
mod builder;
mod channels;
mod dataset;
pub mod geometries;
pub mod readers;
pub use azimuths::{AzimuthCoverage, MirrorSides};
pub(crate) use builder::{Builder, Cells};
pub use dataset::*;

/// The bundled data directory: `./data` if present, else the crate's own `data/`.
pub fn bundled_data_dir() -> std::path::PathBuf {
    let local = std::path::PathBuf::from("data");
    if local.is_dir() {
        return local;
    }
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data")
}
