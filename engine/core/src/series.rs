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
