//! Time-series CSV files (probes.csv, energy.csv): a header `time,<columns>`, one row
//! per sample, flushed at least every two seconds of wall time so a killed run keeps
//! what it reported. The rows are also kept in memory for the end-of-run plots.

use crate::output::plot::{plot_series, Series, Style};
use crate::stage::StepError;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

const FLUSH_EVERY: Duration = Duration::from_secs(2);

pub struct SeriesWriter {
    path: PathBuf,
    columns: Vec<String>,
    file: BufWriter<File>,
    last_flush: Instant,
    rows: Vec<(f64, Vec<f64>)>,
}

impl SeriesWriter {
    /// Creates (truncates) the file and writes the header.
    pub fn create(path: &Path, columns: Vec<String>) -> Result<Self, StepError> {
        let file = File::create(path).map_err(|e| StepError::output(path, e))?;
        let mut w = Self {
            path: path.to_path_buf(),
            columns,
            file: BufWriter::new(file),
            last_flush: Instant::now(),
            rows: Vec::new(),
        };
        let header = format!("time,{}\n", w.columns.join(","));
        w.file
            .write_all(header.as_bytes())
            .map_err(|e| StepError::output(path, e))?;
        w.flush()?;
        Ok(w)
    }

    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// Appends one row; values are written with full round-trip precision.
    pub fn push(&mut self, time: f64, values: Vec<f64>) -> Result<(), StepError> {
        let mut line = format!("{time}");
        for v in &values {
            line.push(',');
            line.push_str(&v.to_string());
        }
        line.push('\n');
        self.file
            .write_all(line.as_bytes())
            .map_err(|e| StepError::output(&self.path, e))?;
        self.rows.push((time, values));
        if self.last_flush.elapsed() >= FLUSH_EVERY {
            self.flush()?;
        }
        Ok(())
    }

    pub fn flush(&mut self) -> Result<(), StepError> {
        self.last_flush = Instant::now();
        self.file
            .flush()
            .map_err(|e| StepError::output(&self.path, e))
    }

    /// The samples of column `name` as (time, value) pairs.
    pub fn column(&self, name: &str) -> Vec<(f64, f64)> {
        match self.columns.iter().position(|c| c == name) {
            Some(k) => self.rows.iter().map(|(t, v)| (*t, v[k])).collect(),
            None => Vec::new(),
        }
    }

    /// Plots the given columns against time into one PNG.
    pub fn plot(
        &self,
        path: &Path,
        title: &str,
        y_label: &str,
        names: &[&str],
    ) -> Result<(), StepError> {
        let series: Vec<Series> = names
            .iter()
            .map(|n| Series {
                name: n.to_string(),
                points: self.column(n),
                style: Style::Line,
            })
            .collect();
        plot_series(path, title, "time [s]", y_label, &series)
            .map_err(|e| StepError::output(path, e))
    }
}

/// A CSV file as (header, rows of numbers), skipping `#` comment lines (the reference
/// data's source lines); a cell that is not a number reads NaN.
pub fn read_table(path: &Path) -> Result<(Vec<String>, Vec<Vec<f64>>), String> {
    let at = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .flexible(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| at(&e))?;
    let header = reader
        .headers()
        .map_err(|e| at(&e))?
        .iter()
        .map(str::to_string)
        .collect();
    let mut rows = Vec::new();
    for row in reader.records() {
        let row = row.map_err(|e| at(&e))?;
        rows.push(row.iter().map(|v| v.parse().unwrap_or(f64::NAN)).collect());
    }
    Ok((header, rows))
}

/// The header column `pattern` selects: a name, or `prefix.*` for the first column
/// starting with `prefix.` (e.g. `P1.*` whichever extraction method a run wrote).
pub fn find_column(header: &[String], pattern: &str) -> Option<usize> {
    match pattern.strip_suffix('*') {
        Some(prefix) => header.iter().position(|h| h.starts_with(prefix)),
        None => header.iter().position(|h| h == pattern),
    }
}

/// Column `expr` of a time-series CSV against its first column (time), rows with a
/// non-finite value left out. `expr` is a column ([`find_column`]) or a sum of columns
/// written `a+b` (e.g. `kinetic+potential` of energy.csv).
pub fn read_series(path: &Path, expr: &str) -> Result<Vec<(f64, f64)>, String> {
    let (header, rows) = read_table(path)?;
    let columns = expr
        .split('+')
        .map(|name| {
            find_column(&header, name.trim()).ok_or_else(|| {
                format!(
                    "{}: no column `{}` (columns: {})",
                    path.display(),
                    name.trim(),
                    header.join(", ")
                )
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(rows
        .iter()
        .filter_map(|r| {
            let t = *r.first()?;
            let v: f64 = columns
                .iter()
                .map(|&k| r.get(k).copied().unwrap_or(f64::NAN))
                .sum();
            (t.is_finite() && v.is_finite()).then_some((t, v))
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_columns_sums_and_prefix_patterns_skipping_comments() {
        let dir = std::env::temp_dir().join(format!("sph-series-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("s.csv");
        std::fs::write(
            &path,
            "# source line\ntime,P1.nearest,a,b\n0,1,2,3\n1,4,5,x\n",
        )
        .unwrap();
        assert_eq!(
            read_series(&path, "P1.*").unwrap(),
            vec![(0.0, 1.0), (1.0, 4.0)]
        );
        assert_eq!(read_series(&path, "a + b").unwrap(), vec![(0.0, 5.0)]);
        assert!(read_series(&path, "c")
            .unwrap_err()
            .contains("no column `c`"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
