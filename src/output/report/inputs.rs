//! What the pictures are drawn from: the data sets the rows name (read again and checked
//! against their hashes) and each fit's model with its parameters.

use crate::bsdf::Model;
use crate::data::{Dataset, Kind};
use crate::output::results::{self, Row};
use anyhow::Result;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// A data set as the report sees it.
pub(super) struct DataInfo {
    pub(super) name: String,
    pub(super) hash: String,
    pub(super) data: Option<Dataset>,
    pub(super) note: Option<String>,
}

/// Each data set the rows name, by name: read from the recorded path, else from the
/// bundled data folder, and used only if its content still has the recorded hash (else a
/// note says why there are no pictures).
pub(super) fn load_data(rows: &[&Row]) -> BTreeMap<String, DataInfo> {
    let mut out = BTreeMap::new();
    for r in rows {
        if out.contains_key(&r.data) {
            continue;
        }
        let path = PathBuf::from(&r.data_path);
        let candidates = [
            path.clone(),
            crate::data::bundled_data_dir().join(path.file_name().unwrap_or_default()),
        ];
        let mut info = DataInfo {
            name: r.data.clone(),
            hash: r.data_hash.clone(),
            data: None,
            note: None,
        };
        for p in candidates.iter() {
            if let Ok(bytes) = std::fs::read(p) {
                if results::content_hash(&bytes) != r.data_hash {
                    info.note = Some(format!(
                        "{} has changed since the fits; no pictures",
                        p.display()
                    ));
                    continue;
                }
                match results::DataFile::read(p, &Default::default()) {
                    Ok(f) => {
                        info.data = Some(f.data);
                        info.note = None;
                        break;
                    }
                    Err(e) => info.note = Some(format!("{e:#}")),
                }
            }
        }
        if info.data.is_none() && info.note.is_none() {
            info.note = Some(format!("{} not found; no pictures", r.data_path));
        }
        out.insert(r.data.clone(), info);
    }
    out
}

/// A fit's model and flat parameter vector, rebuilt from its row.
pub(super) struct Compiled {
    pub(super) model: Model,
    pub(super) flat: Vec<f64>,
}

pub(super) fn compile(r: &Row, data: &Dataset) -> Result<Compiled> {
    let model = Model::for_data(&r.model, data)?;
    let flat = results::flat_from_params(&model, &r.params_json())?;
    Ok(Compiled { model, flat })
}

/// The data set called `name`, if it could be read.
pub(super) fn dataset<'d>(
    datas: &'d BTreeMap<String, DataInfo>,
    name: &str,
) -> Option<&'d Dataset> {
    datas.get(name).and_then(|d| d.data.as_ref())
}

/// The baseline of each BRDF material, by material: the name of its data set with the most
/// samples (the first by name among equals). Renders of the material's fits are judged
/// against it.
pub(super) fn baselines(datas: &BTreeMap<String, DataInfo>) -> BTreeMap<String, String> {
    let mut baseline_of: BTreeMap<String, String> = BTreeMap::new();
    for d in datas.values() {
        if let Some(ds) = &d.data {
            if ds.kind == Kind::Brdf {
                let e = baseline_of
                    .entry(ds.material.clone())
                    .or_insert(d.name.clone());
                let cur_n = datas[e.as_str()]
                    .data
                    .as_ref()
                    .map(|x| x.len())
                    .unwrap_or(0);
                if ds.len() > cur_n {
                    *e = d.name.clone();
                }
            }
        }
    }
    baseline_of
}
