//! The study file's schema: the parameters, designs, metrics and overlays a study names
//! (docs/studies.md).

use super::*;

/// A study file (docs/studies.md documents each field).
#[derive(Clone, Debug, Deserialize)]
#[serde(rename = "Study", deny_unknown_fields)]
pub struct StudySpec {
    /// Output folder name: `out/studies/<name>` by default.
    pub name: String,
    /// The base scenario, relative to the study file.
    pub scenario: String,
    /// Full grid or one parameter at a time. Default: one at a time.
    #[serde(default)]
    pub design: Design,
    /// `--set` overrides applied to every case, e.g. `"end_time=1.7"`.
    #[serde(default)]
    pub set: Vec<String>,
    pub parameters: Vec<Parameter>,
    #[serde(default)]
    pub metrics: Vec<Metric>,
    /// Time histories drawn with one line per case.
    #[serde(default)]
    pub overlays: Vec<Overlay>,
    /// Times of the cases' `snapshot_t<time>.png` (Snapshots stage) shown side by side.
    #[serde(default)]
    pub snapshots: Vec<f64>,
    /// A second scheme for the cases that stop early. Default: none.
    #[serde(default)]
    pub fallback: Option<Fallback>,
}

/// The scheme a case that stops early runs again with: the case's overrides, then
/// `set`, into `<case>__<label>/`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fallback {
    /// The fallback scheme's name: the `scheme` column of its rows, the suffix of their
    /// folders, the legends of the figures. Default `fallback`.
    #[serde(default = "fallback_label")]
    pub label: String,
    /// The base scheme's name in the `scheme` column. Default `paper`.
    #[serde(default = "paper_label")]
    pub base: String,
    /// `--set` overrides appended to the case's, e.g.
    /// `"pipeline.reinitialise.every=1000000000"`.
    pub set: Vec<String>,
}

pub(crate) fn fallback_label() -> String {
    "fallback".into()
}
pub(crate) fn paper_label() -> String {
    "paper".into()
}

/// How the parameters' values combine into cases.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
pub enum Design {
    /// The base case (every parameter at its first value), then each parameter through
    /// its other values with the rest at their first.
    #[default]
    OneAtATime,
    /// Every combination.
    Grid,
}

/// One varied parameter: an override path and its values (RON text, as for `--set`).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Parameter {
    /// Column name in study.csv, e.g. `c0`.
    pub name: String,
    /// Override path, e.g. `fluid.sound_speed`.
    pub path: String,
    /// Values, e.g. `["12.0", "25.0"]`.
    pub values: Vec<String>,
    /// Names of the values in study.csv and folder names. Default: the values.
    #[serde(default)]
    pub labels: Vec<String>,
    /// Paths set together with this one, one value per value of it (e.g. `h_over_dx`
    /// with the kernel).
    #[serde(default)]
    pub linked: Vec<Linked>,
}

/// A path varied in step with a [`Parameter`].
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Linked {
    pub path: String,
    pub values: Vec<String>,
}

pub(crate) fn inf() -> f64 {
    f64::INFINITY
}
pub(crate) fn gate_delay() -> f64 {
    0.175
}
pub(crate) fn one() -> f64 {
    1.0
}
pub(crate) fn three() -> f64 {
    3.0
}
pub(crate) fn two() -> f64 {
    2.0
}
pub(crate) fn three_neighbours() -> usize {
    3
}
pub(crate) fn first_mode() -> usize {
    1
}

/// A metric. Columns that end in `_error` compare with reference data or theory and
/// get a speed-against-error figure. `column` names a probes.csv column, or `name.*`
/// for the first column starting with `name.` (any extraction method).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum Metric {
    /// Surge front (probes.csv `front`) against Martin & Moyce: T = t sqrt(2g/a),
    /// Z = z/a with a the first fluid block's width; the simulation delayed by `delay`
    /// (T units, the gate's opening time) and compared over T in [from, to] as an RMS
    /// relative error `surge_front_error`.
    SurgeFront {
        reference: String,
        #[serde(default = "gate_delay")]
        delay: f64,
        #[serde(default = "one")]
        from: f64,
        #[serde(default = "three")]
        to: f64,
    },
    /// A wall pressure against Buchner-style data in t* = t sqrt(g/H), p* = p/(rho_0 g H)
    /// (H the fluid height), window [from, to] in t*: `<c>_rms_error` (RMS of p*
    /// differences), and in the window `peak` (default: the same) `<c>_peak`,
    /// `<c>_peak_time`, `<c>_peak_error` (relative to the data's largest value there)
    /// and `<c>_peak_time_error` (t* difference).
    Pressure {
        column: String,
        reference: String,
        from: f64,
        to: f64,
        #[serde(default)]
        peak: Option<(f64, f64)>,
        /// Prefix of the columns instead of `<c>`, to compare one sensor twice.
        #[serde(default)]
        name: Option<String>,
    },
    /// A wave gauge against data (t [s], eta [m]): the gauge's rise above its first
    /// reading (the still-water level as the gauge reads it; probes.csv holds the surface
    /// height above the floor) against eta, `<c>_rms_error` [m] over [from, to] s.
    WaveGauge {
        column: String,
        reference: String,
        #[serde(default)]
        from: f64,
        #[serde(default = "inf")]
        to: f64,
    },
    /// Mean |p - rho_0 g (H - y_s)| / (rho_0 g H) from `from` [s] on, y_s the sensor's
    /// height: `<c>_hydrostatic_error`.
    Hydrostatic {
        column: String,
        #[serde(default)]
        from: f64,
    },
    /// Zero-crossing frequency of a signal from `from` [s] on against linear sloshing
    /// theory's mode `mode` for the tank and the filled depth: `<c>_omega` [rad/s] and
    /// `<c>_omega_error` (relative).
    NaturalFrequency {
        column: String,
        #[serde(default)]
        from: f64,
        #[serde(default = "first_mode")]
        mode: usize,
    },
    /// First harmonic of a signal at the tank's roll period over the whole periods
    /// from `from` [s] ([`metrics::forced_harmonic`]): `<c>_amplitude` and `<c>_lag_deg`
    /// (how many degrees it trails the roll angle). For a forced-roll tank, e.g. the
    /// liquid's `roll_moment`.
    RollHarmonic {
        column: String,
        #[serde(default)]
        from: f64,
    },
    /// One peak per roll period of the tank from `from` [s] ([`metrics::period_peaks`]):
    /// `<c>_peak_median` and `<c>_peak_max`, in the column's unit. For impacts that
    /// recur once per period, e.g. a wall sensor in a sloshing tank.
    PeriodPeaks {
        column: String,
        #[serde(default)]
        from: f64,
    },
    /// Impact peaks against a measured band: the largest reading of each whole roll
    /// period from `from` [s] is impact k = 1, 2, ..., set against row k of `reference`
    /// (the Test 10 peak statistics: peak, mean, std, median, min, max, cv, band low,
    /// band high, pressures in mbar). Per impact `<c>_impact<k>` [Pa] and
    /// `<c>_impact<k>_band` (its [`metrics::band_distance`] from mean +- 2 std); over
    /// them `<c>_band_error` (the mean |distance|: 0 when every impact is inside),
    /// `<c>_impacts_median_2_4` [Pa] (the median of impacts 2-4) and
    /// `<c>_above_measured_max` (how many impacts exceed the largest peak measured in
    /// any repetition of their row).
    ImpactBand {
        column: String,
        reference: String,
        #[serde(default)]
        from: f64,
    },
    /// (E(0) - E(t))/E(0) of E = kinetic + potential (energy.csv) at each time:
    /// `energy_loss_t<t>`.
    EnergyLoss { times: Vec<f64> },
    /// The largest |rho/rho_0 - 1| over the run (probes.csv `max_density_fluctuation`).
    DensityFluctuation,
    /// The same over [from, to] s only: `max_density_fluctuation_t<from>-<to>` (e.g.
    /// before the first impact, where it measures the bulk's compressibility rather
    /// than a single splash particle).
    DensityFluctuationWindow { from: f64, to: f64 },
    /// Fluid particles at the end with fewer than `min_neighbours` others within
    /// `radius` ds ([`metrics::spattered`]): `spattered`.
    Spatter {
        #[serde(default = "two")]
        radius: f64,
        #[serde(default = "three_neighbours")]
        min_neighbours: usize,
    },
    /// Total variation of a pressure over [from, to] s, over rho_0 g H:
    /// `<c>_total_variation`.
    Roughness {
        column: String,
        #[serde(default)]
        from: f64,
        #[serde(default = "inf")]
        to: f64,
    },
    /// Smallest and largest neighbour count over the run: `neighbours_min`,
    /// `neighbours_max` (needs `Probe(neighbours: true)`).
    NeighbourRange,
    /// Fluid particles outside the tank at the end (`lost`) and the integrator's
    /// `wall_reflections` count.
    Lost,
}

/// A time history drawn for every case in one figure.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Overlay {
    /// `probes.csv` or `energy.csv`.
    pub file: String,
    /// A column, `name.*`, or a sum `a+b`.
    pub column: String,
    /// Axis label of the values.
    #[serde(default)]
    pub label: String,
    /// Draw t sqrt(g/H) and value/(rho_0 g H), as the pressure data.
    #[serde(default)]
    pub nondimensional: bool,
    /// Reference data drawn as points (same units as the figure).
    #[serde(default)]
    pub reference: Option<String>,
    /// Vertical axis limits (lo, hi) in the figure's units; values beyond are drawn at
    /// the limit (e.g. to see the pressure around an impact spike). Default: all data.
    #[serde(default)]
    pub y_limits: Option<(f64, f64)>,
}
