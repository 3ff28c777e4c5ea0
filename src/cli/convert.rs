//! `bsdfit convert`.

use super::DataArgs;
use crate::data::readers;
use crate::text::plural_with as count;
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct ConvertArgs {
    #[arg(help = super::DATA_FILE_HELP)]
    pub input: PathBuf,
    /// Output v1 CSV file.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub data_args: DataArgs,
}

pub fn run(a: &ConvertArgs) -> Result<()> {
    let ds = readers::convert(&a.input, &a.out, &a.data_args.read_options()?)?;
    for n in &ds.notices {
        eprintln!("note: {n}");
    }
    eprintln!(
        "wrote {} ({}, {} channel(s): {:?} nm)",
        a.out.display(),
        count(ds.len(), "sample", "samples"),
        ds.channel_count(),
        ds.channels
    );
    Ok(())
}
