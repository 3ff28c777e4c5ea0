//! `bsdfit merge` of collection folders: the cells of shard folders (or of other
//! collection folders) gathered into one, with their reports, then the table written.

use super::record::{write_tables, CellRecord, CellStatus};
use super::{
    list_data, read_cells, report, write_cell, CollectionConfig, CELLS_DIR, COLLECTION_JSON,
    REPORTS_DIR,
};
use crate::output::files::check_writable_dir;
use crate::text::plural;
use crate::workflows::sweep::lock::DirLock;
use crate::workflows::sweep::{slurm, SweepObserver};
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// Whether `dir` holds a collection's diagnosis (its options, or those of its job array).
pub fn is_collection(dir: &Path) -> bool {
    dir.join(COLLECTION_JSON).exists() || dir.join("slurm").join(COLLECTION_JSON).exists()
}

/// A better record of one cell: done beats failed.
fn better(new: &CellRecord, old: Option<&CellRecord>) -> bool {
    match old {
        None => true,
        Some(o) => o.status == CellStatus::Failed && new.status == CellStatus::Done,
    }
}

/// Copy a cell's report folder (flat files) from `src` to `out`.
fn copy_report(src: &Path, out: &Path, name: &str) -> Result<()> {
    let from = src.join(REPORTS_DIR).join(name);
    if !from.is_dir() {
        return Ok(());
    }
    let to = out.join(REPORTS_DIR).join(name);
    std::fs::create_dir_all(&to).with_context(|| format!("cannot create {}", to.display()))?;
    for e in std::fs::read_dir(&from).with_context(|| format!("cannot list {}", from.display()))? {
        let p = e?.path();
        if p.is_file() {
            let dest = to.join(p.file_name().unwrap_or_default());
            std::fs::copy(&p, &dest)
                .with_context(|| format!("cannot copy {} to {}", p.display(), dest.display()))?;
        }
    }
    Ok(())
}

/// Merge the cells of `inputs` (collection folders) and, with `shards`, of OUT's shard
/// folders into `out`; with `shards`, every data set of the array's collection
/// (OUT/slurm/collection.json) that no shard diagnosed is named and the merge fails after
/// writing what there is, so a lost task is never silent.
pub fn merge(
    out: &Path,
    inputs: &[PathBuf],
    shards: bool,
    pictures: bool,
    obs: &mut dyn SweepObserver,
) -> Result<()> {
    std::fs::create_dir_all(out)
        .with_context(|| format!("--out: cannot create {}", out.display()))?;
    check_writable_dir(out, "--out")?;
    let _lock = DirLock::acquire(out, "merge", &mut |m| obs.note(&format!("note: {m}")))?;
    super::refuse_sweep_folder(out)?;
    let mut sources: Vec<PathBuf> = inputs.to_vec();
    let config = if shards {
        let path = out.join("slurm").join(COLLECTION_JSON);
        let cfg = CollectionConfig::load(&path).with_context(|| {
            format!(
                "--shards: {} holds no collection job array (written by `diagnose --emit-slurm`)",
                out.display()
            )
        })?;
        sources.extend(slurm::shard_dirs(out)?);
        super::check_identity(&cfg, out)?;
        Some(cfg)
    } else {
        None
    };
    let mut added = 0;
    for src in &sources {
        anyhow::ensure!(
            src.join(CELLS_DIR).is_dir() || src.join(COLLECTION_JSON).exists(),
            "{} is not a collection's folder (no {CELLS_DIR}/ or {COLLECTION_JSON})",
            src.display()
        );
        // The same diagnosis as the merged folder's (the array's, else the first input's).
        let saved = src.join(COLLECTION_JSON);
        if saved.exists() {
            super::check_identity(&CollectionConfig::load(&saved)?, out).with_context(|| {
                format!("{} cannot be merged into {}", src.display(), out.display())
            })?;
        }
        for r in read_cells(src)? {
            let old = super::read_cell(out, &r.data);
            if better(&r, old.as_ref()) {
                write_cell(out, &r)?;
                if pictures {
                    copy_report(src, out, &r.data)?;
                }
                added += 1;
            }
        }
    }
    let cells = read_cells(out)?;
    write_tables(out, &cells)?;
    report::write(out, &cells, pictures)?;
    obs.note(&format!(
        "merged {} from {} into {} ({} in all)",
        plural(added, "cell"),
        plural(sources.len(), "folder"),
        out.display(),
        plural(cells.len(), "data set")
    ));
    if let Some(cfg) = config {
        let listed = list_data(&cfg.data, &mut |_| {})?;
        let missing: Vec<&str> = listed
            .iter()
            .filter(|l| !cells.iter().any(|c| c.data == l.name))
            .map(|l| l.name.as_str())
            .collect();
        if !missing.is_empty() {
            anyhow::bail!(
                "{} of {} no shard diagnosed: {} (re-submit the array: only missing cells run)",
                plural(missing.len(), "data set"),
                listed.len(),
                missing.join(", ")
            );
        }
    }
    Ok(())
}
