//! Time-series CSV files (probes.csv, energy.csv): a header `time,<columns>`, one row
//! per sample, flushed at least every two seconds of wall time so a killed run keeps
//! what it reported. The rows are also kept in memory for the end-of-run plots
//! (`sph_output::SeriesPlot`).

use crate::atomic::write_atomic;
use crate::checkpoint::Resuming;
use crate::sim::Sim;
use crate::stage::StepError;
use std::fs::{File, OpenOptions};
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

    /// [`SeriesWriter::create`], or on a run resuming from a checkpoint
    /// ([`crate::checkpoint::Resuming`] among the resources) [`SeriesWriter::resume`].
    pub fn open(sim: &Sim, path: &Path, columns: Vec<String>) -> Result<Self, StepError> {
        match sim.resources.get::<Resuming>() {
            Some(r) => Self::resume(path, columns, r.time),
            None => Self::create(path, columns),
        }
    }

    /// [`SeriesWriter::open`] for a stage sampling every `interval` seconds, first
    /// refusing an interval that would give more than [`MAX_SAMPLES`] rows over the
    /// run ([`check_samples`]).
    pub fn open_sampled(
        sim: &Sim,
        path: &Path,
        columns: Vec<String>,
        interval: f64,
    ) -> Result<Self, OpenSampledError> {
        check_samples(sim.clock.end_time, interval, MAX_SAMPLES, "rows")?;
        Ok(Self::open(sim, path, columns)?)
    }

    /// Continues a file an earlier run wrote: keeps the header and the rows up to
    /// simulated time `time` (those a checkpoint taken then had flushed), drops the
    /// rest (rows written after the checkpoint, or a half-written last line), and
    /// appends from there. The header must match `columns`.
    pub fn resume(path: &Path, columns: Vec<String>, time: f64) -> Result<Self, StepError> {
        let err = |m: String| StepError::output(path, format!("cannot resume: {m}"));
        let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
        let header = format!("time,{}", columns.join(","));
        let mut lines = text.split_inclusive('\n');
        if lines.next().map(str::trim_end) != Some(header.as_str()) {
            return Err(err(format!(
                "its header is not `{header}` (the file was changed, or the scenario's columns differ)"
            )));
        }
        let mut kept = format!("{header}\n");
        let mut rows = Vec::new();
        for line in lines {
            let Some(line) = line.strip_suffix('\n') else {
                break; // a half-written last line
            };
            let values: Result<Vec<f64>, _> = line.split(',').map(str::parse::<f64>).collect();
            let Ok(mut values) = values else { break };
            if values.len() != columns.len() + 1 || values[0] > time {
                break;
            }
            let t = values.remove(0);
            rows.push((t, values));
            kept.push_str(line);
            kept.push('\n');
        }
        write_atomic(path, kept.as_bytes()).map_err(|e| StepError::output(path, e))?;
        let file = OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|e| StepError::output(path, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            columns,
            file: BufWriter::new(file),
            last_flush: Instant::now(),
            rows,
        })
    }

    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// Appends one row; values are written with full round-trip precision.
    pub fn push(&mut self, time: f64, values: Vec<f64>) -> Result<(), StepError> {
        let _span = tracing::info_span!("write_row").entered();
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
}

/// The most rows a time series (or frames a frame sequence) may hold: each row is also
/// kept in memory for the plots, so more would risk exhausting it.
pub const MAX_SAMPLES: f64 = 5e6;

/// A sampling interval that would give more samples than a run can keep.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("field `interval` = {interval} s gives {samples:.0} {what} over end_time = {end_time} s; accepted: at most {max:.0} (use a longer interval or a shorter run)")]
pub struct TooManySamples {
    /// [s]
    pub interval: f64,
    /// How many the interval would give.
    pub samples: f64,
    /// What is sampled ("rows", "frames").
    pub what: &'static str,
    /// [s]
    pub end_time: f64,
    pub max: f64,
}

/// Why [`SeriesWriter::open_sampled`] refused.
#[derive(Debug, thiserror::Error)]
pub enum OpenSampledError {
    #[error(transparent)]
    TooMany(#[from] TooManySamples),
    #[error(transparent)]
    Open(#[from] StepError),
}

/// Refuses, before the run, a sampling `interval` [s] that would give more than
/// `max` samples over `end_time`; the message names the stage's `interval` field. An
/// interval of 0 (every step) is not checked here.
pub fn check_samples(
    end_time: f64,
    interval: f64,
    max: f64,
    what: &'static str,
) -> Result<(), TooManySamples> {
    if interval > 0.0 && end_time / interval > max {
        return Err(TooManySamples {
            interval,
            samples: (end_time / interval).ceil(),
            what,
            end_time,
            max,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resume_keeps_rows_up_to_the_checkpoint_and_drops_a_half_line() {
        let dir = std::env::temp_dir().join(format!("sph_core_series_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("s.csv");
        let columns = vec!["a".to_string(), "b".to_string()];
        std::fs::write(&path, "time,a,b\n0,1,2\n0.1,3,NaN\n0.2,5,6\n0.3,7").unwrap();
        let mut w = SeriesWriter::resume(&path, columns.clone(), 0.1).unwrap();
        assert_eq!(w.column("a"), [(0.0, 1.0), (0.1, 3.0)]);
        w.push(0.15, vec![9.0, 10.0]).unwrap();
        w.flush().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text, "time,a,b\n0,1,2\n0.1,3,NaN\n0.15,9,10\n");
        // Past a half-written line nothing is kept; a wrong header is refused.
        std::fs::write(&path, "time,a,b\n0,1,2\n0.1,3").unwrap();
        let w = SeriesWriter::resume(&path, columns.clone(), 1.0).unwrap();
        assert_eq!(w.column("b"), [(0.0, 2.0)]);
        std::fs::write(&path, "time,a\n0,1\n").unwrap();
        let err = SeriesWriter::resume(&path, columns, 1.0).err().unwrap();
        assert!(err.to_string().contains("header"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
