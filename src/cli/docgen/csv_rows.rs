//! Reading the committed CSV files by column name, with errors that name the file.
use std::collections::HashMap;
use std::path::Path;

use anyhow::{Context, Result};

/// One row: column name to text.
#[derive(Debug, Clone)]
pub struct Row(HashMap<String, String>);

impl Row {
    pub fn text(&self, column: &str) -> &str {
        self.0.get(column).map_or("", String::as_str)
    }

    /// The column as a number; empty, missing or unparsable reads as NaN.
    pub(crate) fn num(&self, column: &str) -> f64 {
        self.text(column).parse().unwrap_or(f64::NAN)
    }

    pub fn count(&self, column: &str) -> usize {
        self.text(column).parse().unwrap_or(0)
    }
}

/// Every row of a CSV file with a header line; lines starting with `#` are comments.
pub fn read(path: &Path) -> Result<Vec<Row>> {
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_path(path)
        .with_context(|| format!("reading {}", path.display()))?;
    let header: Vec<String> = reader
        .headers()
        .with_context(|| format!("reading the header of {}", path.display()))?
        .iter()
        .map(str::to_string)
        .collect();
    reader
        .records()
        .map(|r| {
            let r = r.with_context(|| format!("reading {}", path.display()))?;
            Ok(Row(header.iter().cloned().zip(r.iter().map(str::to_string)).collect()))
        })
        .collect()
}

/// The comment lines (`# ...`) at the top of a file, without the `# `.
pub(crate) fn comments(path: &Path) -> Result<Vec<String>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(text.lines().take_while(|l| l.starts_with('#')).map(|l| l.trim_start_matches('#').trim().to_string()).collect())
}
