//! Output writers of the WCSPH engine: ParaView frames ([`vtk`], [`frame`]), PNG
//! particle snapshots ([`png`]) and plots ([`plot`]), and the end-of-run plots of a
//! time series ([`SeriesPlot`]). The CSV series writer and the atomic file writer are
//! in `sph-core` (a plugin writes series without the plotting libraries).

pub mod frame;
pub mod plot;
pub mod png;
pub mod vtk;

use plot::{plot_series, Series, Style};
use sph_core::series::SeriesWriter;
use sph_core::stage::StepError;
use std::path::Path;

/// Plots of a [`SeriesWriter`]'s rows (kept in memory as they are written).
pub trait SeriesPlot {
    /// Plots the given columns against time into one PNG.
    fn plot(
        &self,
        path: &Path,
        title: &str,
        y_label: &str,
        names: &[&str],
    ) -> Result<(), StepError>;
}

impl SeriesPlot for SeriesWriter {
    fn plot(
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
