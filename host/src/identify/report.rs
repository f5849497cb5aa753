//! `identify --report DIR`: a Markdown summary with the paper's tables and SVG figures.
use std::path::{Path, PathBuf};

use anyhow::Result;

use super::Identification;

/// Writes the report into `dir`; returns the summary's path.
pub fn write_report(dir: &Path, id: &Identification) -> Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let path = dir.join("summary.md");
    std::fs::write(&path, super::summary(id))?;
    Ok(path)
}
