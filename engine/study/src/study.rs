//! Sensitivity studies (`engine study scenarios/studies/<name>.ron`): a base scenario,
//! parameters to vary and metrics to report. Every case is a run of the base scenario
//! with `--set` overrides ([`sph_scenario::overrides`]); cases run side by side, one thread
//! each ([`crate::parallel`]), into `<out>/<case>/`, and a case whose folder already
//! holds its finished run (same overrides, `summary.json` written) is not run again,
//! so an interrupted study resumes. The study writes `study.csv` (one row per case:
//! parameters, status, wall seconds, steps, particle-steps per second, every metric),
//! figures ([`figures`]) and `report.md`.
//!
//! A case that stops early (e.g. the density guard) is a row with its stop reason and
//! the metrics of the part it ran, not a failure of the study. A study with a
//! [`Fallback`] then runs that case again with the fallback's overrides appended, into
//! `<out>/<case>__<label>/`, as a row right after the case's; the `scheme` column says
//! which scheme each row used.

pub mod figures;
pub mod metrics;
pub mod status;

use crate::series::read_series;
use glam::DVec2;
use serde::Deserialize;
use sph_core::StageRegistry;
use sph_run::runner::{run_keeping_state, RunError, RunOptions};
use sph_scenario::overrides::Override;
use sph_scenario::scenario::{parse_ron, LoadError};
use sph_scenario::Scenario;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

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

fn fallback_label() -> String {
    "fallback".into()
}
fn paper_label() -> String {
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

fn inf() -> f64 {
    f64::INFINITY
}
fn gate_delay() -> f64 {
    0.175
}
fn one() -> f64 {
    1.0
}
fn three() -> f64 {
    3.0
}
fn two() -> f64 {
    2.0
}
fn three_neighbours() -> usize {
    3
}
fn first_mode() -> usize {
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

/// One case: its folder name, parameter labels and overrides.
#[derive(Clone, Debug)]
pub struct Case {
    pub name: String,
    pub labels: Vec<String>,
    pub overrides: Vec<Override>,
    /// The scheme's name in the `scheme` column (studies with a [`Fallback`] only).
    pub scheme: Option<String>,
    /// Whether this is the fallback run of a case that stopped early.
    pub fallback: bool,
}

impl Case {
    /// The case's name in the figures' legends: a fallback run as `<case> (<label>)`.
    pub fn legend(&self) -> String {
        match (&self.scheme, self.fallback) {
            (Some(s), true) => {
                let base = self.name.strip_suffix(&format!("__{s}"));
                format!("{} ({s})", base.unwrap_or(&self.name))
            }
            _ => self.name.clone(),
        }
    }
}

/// A loaded study: spec, where it came from, its cases.
#[derive(Clone, Debug)]
pub struct Study {
    pub spec: StudySpec,
    pub file: PathBuf,
    pub scenario: PathBuf,
    pub cases: Vec<Case>,
    /// With a [`Fallback`]: each case's fallback run, in case order (run only if the
    /// case stops early). Empty without.
    pub fallbacks: Vec<Case>,
}

/// One study.csv row.
#[derive(Clone, Debug)]
pub struct Row {
    pub case: Case,
    /// `completed`, why the run stopped, or why it could not run.
    pub status: String,
    pub fluid_particles: f64,
    pub steps: f64,
    pub simulated_time: f64,
    pub wall_seconds: f64,
    pub particle_steps_per_second: f64,
    /// Whether it was run now (false: resumed from an earlier run).
    pub ran: bool,
    pub metrics: Vec<(String, f64)>,
}

impl Row {
    pub fn completed(&self) -> bool {
        self.status == "completed"
    }
    /// The row's cells in [`header`] order, numbers written by `number`.
    pub fn cells(&self, number: impl Fn(f64) -> String) -> Vec<String> {
        let mut cells = vec![self.case.name.clone()];
        cells.extend(self.case.labels.iter().cloned());
        cells.extend(self.case.scheme.iter().cloned());
        cells.push(self.status.clone());
        let numbers = [
            self.fluid_particles,
            self.steps,
            self.simulated_time,
            self.wall_seconds,
            self.particle_steps_per_second,
        ];
        cells.extend(
            numbers
                .into_iter()
                .chain(self.metrics.iter().map(|m| m.1))
                .map(number),
        );
        cells
    }

    pub fn metric(&self, name: &str) -> Option<f64> {
        self.metrics.iter().find(|m| m.0 == name).map(|m| m.1)
    }
}

fn spec_error(file: &str, field: &str, message: String) -> LoadError {
    LoadError {
        file: file.to_string(),
        line: 0,
        column: 0,
        set: None,
        field: Some(field.to_string()),
        message,
    }
}

impl Study {
    /// Reads and checks a study file: RON errors carry `file:line:column` (the scenario
    /// loader's reporting), and every case's scenario is loaded, so a bad path or value
    /// fails before anything runs. `overrides` (command line) apply to every case.
    pub fn load(
        path: &Path,
        overrides: &[Override],
        registry: &StageRegistry,
    ) -> Result<Self, LoadError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| LoadError {
            field: None,
            ..spec_error(&file, "", format!("cannot read the study file: {e}"))
        })?;
        let spec: StudySpec = parse_ron(&text, &file)?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let scenario = dir.join(&spec.scenario);
        let cases = cases(&spec, &file, overrides)?;
        let fallbacks = fallback_cases(&spec, &file, &text, &cases)?;
        for case in &cases {
            Scenario::load(&scenario, &case.overrides, registry).map_err(|mut e| {
                e.message = format!("(study {file}, case {}) {}", case.name, e.message);
                e
            })?;
        }
        for case in &fallbacks {
            Scenario::load(&scenario, &case.overrides, registry).map_err(|mut e| {
                let (line, column) = locate(&text, "fallback");
                e.message = format!(
                    "(study {file}:{line}:{column}, the fallback of case {}) {}",
                    case.name, e.message
                );
                e
            })?;
        }
        Ok(Self {
            spec,
            file: path.to_path_buf(),
            scenario,
            cases,
            fallbacks,
        })
    }

    /// A path named in the study file (reference data), relative to the file.
    pub fn resolve(&self, p: &str) -> PathBuf {
        self.file.parent().unwrap_or(Path::new(".")).join(p)
    }
}

/// Line and column (1-based) of the first `needle` in `text` (the file's start if
/// absent), to point an error at a field of the study file; a needle that is a field
/// name (`fallback`) is found where it is followed by `:`.
fn locate(text: &str, needle: &str) -> (usize, usize) {
    let field = needle
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || c == '_');
    let at = text
        .match_indices(needle)
        .map(|(i, _)| i)
        .find(|&i| {
            !field
                || (text[..i]
                    .chars()
                    .next_back()
                    .is_none_or(|c| !c.is_ascii_alphanumeric() && c != '_' && c != '/')
                    && text[i + needle.len()..].trim_start().starts_with(':'))
        })
        .unwrap_or(0);
    let before = &text[..at];
    let line = before.matches('\n').count() + 1;
    let column = before.rfind('\n').map_or(at, |n| at - n - 1) + 1;
    (line, column)
}

/// The fallback runs of `cases` (none without a `fallback` field): each case's
/// overrides with the fallback's appended, named `<case>__<label>`. Errors point at
/// the offending entry of the study file.
pub fn fallback_cases(
    spec: &StudySpec,
    file: &str,
    text: &str,
    cases: &[Case],
) -> Result<Vec<Case>, LoadError> {
    let Some(fb) = &spec.fallback else {
        return Ok(Vec::new());
    };
    let error = |needle: &str, field: &str, message: String| {
        let (line, column) = locate(text, needle);
        LoadError {
            line,
            column,
            ..spec_error(file, field, message)
        }
    };
    if fb.label.is_empty() || folder_safe(&fb.label) != fb.label {
        return Err(error(
            &format!("{:?}", fb.label),
            "fallback.label",
            format!(
                "`{}` is not a folder-name suffix: use letters, digits, `.`, `-` and `_`",
                fb.label
            ),
        ));
    }
    if fb.label == fb.base {
        return Err(error(
            &format!("{:?}", fb.label),
            "fallback.label",
            format!(
                "`{}` is also the base scheme's name (fallback.base): give the two schemes different names",
                fb.label
            ),
        ));
    }
    if fb.set.is_empty() {
        return Err(error(
            "fallback",
            "fallback.set",
            "give the overrides of the fallback scheme, e.g. set: [\"pipeline.reinitialise.every=1000000000\"]".into(),
        ));
    }
    let mut extra = Vec::new();
    for s in &fb.set {
        let o = s.parse::<Override>().map_err(|e| {
            // The entry as written in the file (quotes escaped) if it can be found.
            let needle = format!("{s:?}");
            let needle = if text.contains(&needle) {
                needle
            } else {
                "fallback".into()
            };
            error(&needle, "fallback.set", e.to_string())
        })?;
        extra.push(o);
    }
    let runs: Vec<Case> = cases
        .iter()
        .map(|c| {
            let mut overrides = c.overrides.clone();
            overrides.extend(extra.iter().cloned());
            Case {
                name: format!("{}__{}", c.name, fb.label),
                labels: c.labels.clone(),
                overrides,
                scheme: Some(fb.label.clone()),
                fallback: true,
            }
        })
        .collect();
    if let Some(clash) = runs.iter().find(|r| cases.iter().any(|c| c.name == r.name)) {
        return Err(error(
            &format!("{:?}", fb.label),
            "fallback.label",
            format!(
                "the fallback run's folder `{}` is also a case's: choose another label",
                clash.name
            ),
        ));
    }
    Ok(runs)
}

/// The cases of a study, in order: for one-at-a-time, the base case first.
pub fn cases(spec: &StudySpec, file: &str, extra: &[Override]) -> Result<Vec<Case>, LoadError> {
    let parse = |field: &str, s: String| {
        s.parse::<Override>()
            .map_err(|e| spec_error(file, field, e.to_string()))
    };
    if spec.parameters.is_empty() {
        return Err(spec_error(
            file,
            "parameters",
            "give at least one parameter".into(),
        ));
    }
    let mut common = Vec::new();
    for s in &spec.set {
        common.push(parse("set", s.clone())?);
    }
    common.extend(extra.iter().cloned());
    // Per parameter, per value: (label, overrides).
    let mut choices: Vec<Vec<(String, Vec<Override>)>> = Vec::new();
    for p in &spec.parameters {
        let n = p.values.len();
        if n == 0 {
            return Err(spec_error(
                file,
                "values",
                format!("parameter `{}` has no values", p.name),
            ));
        }
        if !p.labels.is_empty() && p.labels.len() != n {
            return Err(spec_error(
                file,
                "labels",
                format!(
                    "parameter `{}`: {} labels for {n} values",
                    p.name,
                    p.labels.len()
                ),
            ));
        }
        let mut list = Vec::new();
        for (k, v) in p.values.iter().enumerate() {
            let mut ov = vec![parse("values", format!("{}={v}", p.path))?];
            for l in &p.linked {
                let Some(lv) = l.values.get(k).filter(|_| l.values.len() == n) else {
                    return Err(spec_error(
                        file,
                        "linked",
                        format!(
                            "parameter `{}`: `{}` has {} values for {n}",
                            p.name,
                            l.path,
                            l.values.len()
                        ),
                    ));
                };
                ov.push(parse("linked", format!("{}={lv}", l.path))?);
            }
            let label = p.labels.get(k).cloned().unwrap_or_else(|| v.clone());
            list.push((label, ov));
        }
        choices.push(list);
    }
    let picks: Vec<Vec<usize>> = match spec.design {
        Design::OneAtATime => {
            let mut out = vec![vec![0; choices.len()]];
            for (i, c) in choices.iter().enumerate() {
                for k in 1..c.len() {
                    let mut pick = vec![0; choices.len()];
                    pick[i] = k;
                    out.push(pick);
                }
            }
            out
        }
        Design::Grid => choices.iter().fold(vec![Vec::new()], |acc, c| {
            acc.iter()
                .flat_map(|pick| {
                    (0..c.len()).map(move |k| {
                        let mut p = pick.clone();
                        p.push(k);
                        p
                    })
                })
                .collect()
        }),
    };
    Ok(picks
        .into_iter()
        .map(|pick| {
            let mut overrides = common.clone();
            let mut labels = Vec::new();
            let mut name = Vec::new();
            for (i, &k) in pick.iter().enumerate() {
                let (label, ov) = &choices[i][k];
                overrides.extend(ov.iter().cloned());
                labels.push(label.clone());
                name.push(format!(
                    "{}_{}",
                    spec.parameters[i].name,
                    folder_safe(label)
                ));
            }
            Case {
                name: name.join("__"),
                labels,
                overrides,
                scheme: spec.fallback.as_ref().map(|f| f.base.clone()),
                fallback: false,
            }
        })
        .collect())
}

/// A label as a folder name: letters, digits, `.`, `-` and `_` kept, the rest `_`.
fn folder_safe(label: &str) -> String {
    label
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// The overrides of a case as written to `<case>/case.txt`, by which a finished case
/// is recognised when the study is run again.
fn case_text(case: &Case) -> String {
    case.overrides
        .iter()
        .map(|o| format!("{}\n", o.raw))
        .collect()
}

/// Whether `dir` holds the finished run of `case` (its overrides and a summary).
pub fn finished(dir: &Path, case: &Case) -> bool {
    std::fs::read_to_string(dir.join("case.txt")).is_ok_and(|t| t == case_text(case))
        && dir.join("summary.json").is_file()
}

/// Runs one case into `dir` on `threads` threads; the fluid positions at the end go to
/// `final_particles.csv` (for the spatter and lost-particle metrics). A run that stops
/// early is not an error here (its summary says why); a scenario that cannot run is.
fn run_case(
    study: &Study,
    case: &Case,
    dir: &Path,
    threads: usize,
    registry: &StageRegistry,
) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    for stale in ["summary.json", "final_particles.csv"] {
        let _ = std::fs::remove_file(dir.join(stale));
    }
    sph_core::atomic::write_atomic(&dir.join("case.txt"), case_text(case).as_bytes())
        .map_err(|e| format!("{}: {e}", dir.display()))?;
    // Who runs the case, for `--status`; removed when the run ends however it ends.
    let marker = dir.join(status::RUNNING);
    sph_core::atomic::write_atomic(&marker, status::marker_text().as_bytes())
        .map_err(|e| format!("{}: {e}", marker.display()))?;
    let result = run_case_marked(study, case, dir, threads, registry);
    let _ = std::fs::remove_file(&marker);
    result
}

fn run_case_marked(
    study: &Study,
    case: &Case,
    dir: &Path,
    threads: usize,
    registry: &StageRegistry,
) -> Result<(), String> {
    let scenario =
        Scenario::load(&study.scenario, &case.overrides, registry).map_err(|e| e.to_string())?;
    let opts = RunOptions::quiet(dir, threads);
    match run_keeping_state(scenario, &opts) {
        Ok((_, sim)) => {
            let mut csv = String::from("x,y\n");
            for (p, _) in sim
                .world
                .query::<(
                    &sph_core::components::Position,
                    &sph_core::components::Fluid,
                )>()
                .iter()
            {
                let _ = writeln!(csv, "{},{}", p.0.x, p.0.y);
            }
            let path = dir.join("final_particles.csv");
            sph_core::atomic::write_atomic(&path, csv.as_bytes())
                .map_err(|e| format!("{}: {e}", path.display()))
        }
        Err(RunError::Step { .. }) => Ok(()),
        Err(e) => Err(e.to_string()),
    }
}

/// The case a `--case K` argument names: its number in the study (1 to the number
/// of cases, as `engine study` and `--status` count them) or its folder name.
pub fn find_case(study: &Study, k: &str) -> Result<usize, String> {
    let n = study.cases.len();
    if let Ok(number) = k.trim().parse::<usize>() {
        return if (1..=n).contains(&number) {
            Ok(number - 1)
        } else {
            Err(format!(
                "--case {k}: study {} has cases 1 to {n}",
                study.spec.name
            ))
        };
    }
    study.cases.iter().position(|c| c.name == k).ok_or_else(|| {
        let names: Vec<&str> = study.cases.iter().map(|c| c.name.as_str()).collect();
        format!(
            "--case {k}: no case of study {} has that number or name; its cases are 1 to {n}: {}",
            study.spec.name,
            names.join(", ")
        )
    })
}

/// Whether `dir` holds a run of `case` that stopped early (its summary's status is
/// not `completed`): the case whose fallback runs.
pub fn stopped_early(dir: &Path, case: &Case) -> bool {
    matches!(
        status::case_state(dir, case),
        status::CaseState::StoppedEarly { .. }
    )
}

/// Whether a case ran now, and why it could not run if it could not.
type Outcome = (bool, Result<(), String>);

/// Runs `case` into `<out_dir>/<case>/` unless that folder holds its finished run
/// (or, with `report_only`, at all: then the row is `not run`).
fn run_or_skip(
    study: &Study,
    case: &Case,
    out_dir: &Path,
    (threads, report_only): (usize, bool),
    registry: &StageRegistry,
    report: &(dyn Fn(&str) + Sync),
) -> Outcome {
    let dir = out_dir.join(&case.name);
    if finished(&dir, case) {
        report(&format!("{}: finished earlier, skipped", case.name));
        return (false, Ok(()));
    }
    if report_only {
        return (false, Err("not run".to_string()));
    }
    (true, run_case(study, case, &dir, threads, registry))
}

/// Case `index` and, if it stopped early and the study has a fallback, its fallback
/// run right after it (in the same worker).
fn run_with_fallback(
    study: &Study,
    index: usize,
    out_dir: &Path,
    how: (usize, bool),
    registry: &StageRegistry,
    report: &(dyn Fn(&str) + Sync),
) -> (Outcome, Option<Outcome>) {
    let case = &study.cases[index];
    let first = run_or_skip(study, case, out_dir, how, registry, report);
    let fallback = study
        .fallbacks
        .get(index)
        .filter(|_| stopped_early(&out_dir.join(&case.name), case))
        .map(|fb| {
            if !finished(&out_dir.join(&fb.name), fb) && !how.1 {
                report(&format!(
                    "{}: stopped early; running it again as {}",
                    case.name, fb.name
                ));
            }
            run_or_skip(study, fb, out_dir, how, registry, report)
        });
    (first, fallback)
}

/// Runs case `index` (0-based) alone, exactly as [`run_study`] runs it: into
/// `<out_dir>/<case>/` with its `case.txt`, skipped if that folder already holds its
/// finished run; then, if it stopped early and the study has a fallback, the fallback
/// run into `<out_dir>/<case>__<label>/` the same way. Writes no study.csv (the report
/// does, e.g. `--report-only`). Returns whether each ran and its row: the case's, then
/// its fallback's if that was due.
pub fn run_one_case(
    study: &Study,
    index: usize,
    out_dir: &Path,
    threads: usize,
    registry: &StageRegistry,
) -> Result<Vec<(bool, Row)>, String> {
    if index >= study.cases.len() {
        return Err(format!(
            "study {} has no case {}",
            study.spec.name,
            index + 1
        ));
    }
    let (first, fallback) =
        run_with_fallback(study, index, out_dir, (threads, false), registry, &|_| ());
    let mut rows = Vec::new();
    for (case, (ran, outcome)) in std::iter::once((&study.cases[index], first))
        .chain(fallback.map(|o| (&study.fallbacks[index], o)))
    {
        outcome?;
        let row = evaluate(study, case, &out_dir.join(&case.name), ran, None, registry);
        rows.push((ran, row));
    }
    Ok(rows)
}

/// How [`run_study`] runs the cases.
#[derive(Clone, Copy, Debug)]
pub struct StudyOptions {
    /// Cases run at the same time.
    pub workers: usize,
    /// Threads per case.
    pub threads: usize,
    /// Run nothing: report the cases that have finished, the others as `not run`.
    pub report_only: bool,
}

/// Runs (or resumes) every case, `workers` at a time on `threads` threads each (a
/// case's fallback run right after it, in the same worker), then writes study.csv, the
/// figures and report.md into `out_dir`. Returns the rows: each case's, followed by
/// its fallback's if it stopped early.
pub fn run_study(
    study: &Study,
    registry: &StageRegistry,
    out_dir: &Path,
    opts: StudyOptions,
    report: &(dyn Fn(&str) + Sync),
) -> Result<Vec<Row>, String> {
    let StudyOptions {
        workers,
        threads,
        report_only,
    } = opts;
    std::fs::create_dir_all(out_dir).map_err(|e| format!("{}: {e}", out_dir.display()))?;
    let n = study.cases.len();
    let outcomes = crate::parallel::run_parallel(&study.cases, workers, |i, _| {
        let numbered = |line: &str| report(&format!("case {}/{n} {line}", i + 1));
        run_with_fallback(
            study,
            i,
            out_dir,
            (threads, report_only),
            registry,
            &numbered,
        )
    });
    let mut rows = Vec::new();
    for (i, (first, fallback)) in outcomes.into_iter().enumerate() {
        for (case, (ran, outcome)) in std::iter::once((&study.cases[i], first))
            .chain(fallback.map(|o| (&study.fallbacks[i], o)))
        {
            let row = evaluate(
                study,
                case,
                &out_dir.join(&case.name),
                ran,
                outcome.err(),
                registry,
            );
            if ran {
                report(&format!(
                    "case {}: {} ({:.1} s wall, {:.3e} particle-steps/s)",
                    case.name, row.status, row.wall_seconds, row.particle_steps_per_second
                ));
            }
            rows.push(row);
        }
    }
    write_csv(&out_dir.join("study.csv"), study, &rows)?;
    let figures = figures::draw(study, out_dir, &rows, registry)?;
    write_report(study, out_dir, &rows, &figures, opts)?;
    Ok(rows)
}

/// The row of a case from its folder: summary.json, probes.csv, energy.csv,
/// final_particles.csv. `failure`: why the case could not run at all.
pub fn evaluate(
    study: &Study,
    case: &Case,
    dir: &Path,
    ran: bool,
    failure: Option<String>,
    registry: &StageRegistry,
) -> Row {
    let summary: serde_json::Value = std::fs::read_to_string(dir.join("summary.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default();
    let num = |k: &str| {
        summary
            .get(k)
            .and_then(serde_json::Value::as_f64)
            .unwrap_or(f64::NAN)
    };
    let status = failure.unwrap_or_else(|| {
        summary
            .get("status")
            .and_then(|s| s.as_str())
            .unwrap_or("no summary.json")
            .to_string()
    });
    let mut row = Row {
        case: case.clone(),
        status,
        fluid_particles: num("fluid_particles"),
        steps: num("steps"),
        simulated_time: num("simulated_time"),
        wall_seconds: num("wall_seconds"),
        particle_steps_per_second: num("particle_steps_per_second"),
        ran,
        metrics: Vec::new(),
    };
    let scenario = Scenario::load(&study.scenario, &case.overrides, registry).ok();
    let reflections = summary
        .get("diagnostics")
        .and_then(|d| d.get("wall_reflections"))
        .and_then(serde_json::Value::as_f64)
        .unwrap_or(0.0);
    for m in &study.spec.metrics {
        row.metrics
            .extend(metric_values(study, m, dir, scenario.as_ref(), reflections));
    }
    row
}

/// Reference data: the first two columns, sorted by the first.
fn reference(path: &Path) -> Vec<(f64, f64)> {
    let mut points: Vec<(f64, f64)> = crate::series::read_table(path)
        .map(|(_, rows)| {
            rows.iter()
                .filter(|r| r.len() >= 2)
                .map(|r| (r[0], r[1]))
                .collect()
        })
        .unwrap_or_default();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    points
}

/// The column's name in study.csv: `P1.*` gives `P1`, `P1.shepard` stays.
fn base(column: &str) -> &str {
    column.strip_suffix(".*").unwrap_or(column)
}

/// Scales of a scenario: (rho_0, |g|, H the fluid top).
fn scales(s: &Scenario) -> (f64, f64, f64) {
    let top = s
        .spec
        .fluid_blocks
        .iter()
        .map(|b| b.min.1 + b.size.1 .0)
        .fold(0.0, f64::max);
    (
        s.spec.fluid.density.0,
        DVec2::from(s.spec.fluid.gravity).length(),
        top,
    )
}

/// The tank's roll (period [s], phase [deg]); NaNs if the scenario has no roll.
fn roll(scenario: Option<&Scenario>) -> (f64, f64) {
    scenario
        .and_then(|s| s.spec.tank.as_ref())
        .and_then(|t| t.motion.as_ref())
        .and_then(|m| m.roll.as_ref())
        .map_or((f64::NAN, f64::NAN), |r| (r.period.0, r.phase))
}

/// The final fluid positions a completed case wrote.
fn final_positions(dir: &Path) -> Option<Vec<DVec2>> {
    let (_, rows) = crate::series::read_table(&dir.join("final_particles.csv")).ok()?;
    Some(rows.iter().map(|r| DVec2::new(r[0], r[1])).collect())
}

fn metric_values(
    study: &Study,
    metric: &Metric,
    dir: &Path,
    scenario: Option<&Scenario>,
    reflections: f64,
) -> Vec<(String, f64)> {
    let probes = |c: &str| read_series(&dir.join("probes.csv"), c).unwrap_or_default();
    let (rho0, g, height) = scenario.map_or((f64::NAN, f64::NAN, f64::NAN), scales);
    let p_scale = rho0 * g * height;
    match metric {
        Metric::SurgeFront {
            reference: r,
            delay,
            from,
            to,
        } => {
            let a = scenario
                .and_then(|s| s.spec.fluid_blocks.first())
                .map_or(f64::NAN, |b| b.size.0 .0);
            let scale = (2.0 * g / a).sqrt();
            let front: Vec<(f64, f64)> = probes("front")
                .iter()
                .map(|&(t, x)| (t * scale + delay, x / a))
                .collect();
            let data = reference(&study.resolve(r));
            vec![(
                "surge_front_error".into(),
                metrics::rms_relative(&front, &data, *from, *to),
            )]
        }
        Metric::Pressure {
            column,
            reference: r,
            from,
            to,
            peak,
            name,
        } => {
            let (p0, p1) = peak.unwrap_or((*from, *to));
            let t_scale = (g / height).sqrt();
            let sim: Vec<(f64, f64)> = probes(column)
                .iter()
                .map(|&(t, p)| (t * t_scale, p / p_scale))
                .collect();
            let data = reference(&study.resolve(r));
            let (ts, ps) = metrics::peak(&sim, p0, p1);
            let (tr, pr) = metrics::peak(&data, p0, p1);
            let b = name.as_deref().unwrap_or(base(column));
            vec![
                (
                    format!("{b}_rms_error"),
                    metrics::rms_difference(&sim, &data, *from, *to),
                ),
                (format!("{b}_peak"), ps),
                (format!("{b}_peak_time"), ts),
                (format!("{b}_peak_error"), ps / pr - 1.0),
                (format!("{b}_peak_time_error"), ts - tr),
            ]
        }
        Metric::WaveGauge {
            column,
            reference: r,
            from,
            to,
        } => {
            let data = reference(&study.resolve(r));
            let height = probes(column);
            let still = height.first().map_or(0.0, |p| p.1);
            let eta: Vec<(f64, f64)> = height.iter().map(|&(t, h)| (t, h - still)).collect();
            vec![(
                format!("{}_rms_error", base(column)),
                metrics::rms_difference(&eta, &data, *from, *to),
            )]
        }
        Metric::Hydrostatic { column, from } => {
            let name = column.split('.').next().unwrap_or(column);
            let y = scenario
                .and_then(|s| s.spec.pressure_sensors.iter().find(|p| p.name == name))
                .map_or(f64::NAN, |p| p.at.1);
            let expected = rho0 * g * (height - y);
            vec![(
                format!("{}_hydrostatic_error", base(column)),
                metrics::mean_abs_error(&probes(column), expected, *from) / p_scale,
            )]
        }
        Metric::NaturalFrequency { column, from, mode } => {
            let omega = metrics::crossing_frequency(&probes(column), *from);
            let theory = scenario.map_or(f64::NAN, |s| {
                let width = s.spec.tank.as_ref().map_or(f64::NAN, |t| t.width.0);
                crate::sweep::linear_tank(s, height / width).natural_frequency(*mode)
            });
            let b = base(column);
            vec![
                (format!("{b}_omega"), omega),
                (format!("{b}_omega_error"), omega / theory - 1.0),
            ]
        }
        Metric::RollHarmonic { column, from } => {
            let (period, phase) = roll(scenario);
            let (a, lag) = metrics::forced_harmonic(&probes(column), period, phase, *from);
            let b = base(column);
            vec![(format!("{b}_amplitude"), a), (format!("{b}_lag_deg"), lag)]
        }
        Metric::PeriodPeaks { column, from } => {
            let (period, _) = roll(scenario);
            let (median, max) = metrics::period_peaks(&probes(column), period, *from);
            let b = base(column);
            vec![
                (format!("{b}_peak_median"), median),
                (format!("{b}_peak_max"), max),
            ]
        }
        Metric::ImpactBand {
            column,
            reference,
            from,
        } => {
            let (period, _) = roll(scenario);
            let peaks = metrics::period_peak_list(&probes(column), period, *from);
            let rows = crate::series::read_table(&study.resolve(reference))
                .map(|(_, rows)| rows)
                .unwrap_or_default();
            let b = base(column);
            let mut out = Vec::new();
            let (mut sum, mut above) = (0.0, 0.0);
            // 1 mbar = 100 Pa; a row without its nine columns gives NaNs.
            let cell = |r: &[f64], k: usize| r.get(k).map_or(f64::NAN, |v| 100.0 * v);
            for (k, row) in rows.iter().enumerate() {
                let p = peaks.get(k).copied().unwrap_or(f64::NAN);
                let d = metrics::band_distance(p, cell(row, 7), cell(row, 8));
                sum += d.abs();
                // A NaN peak or maximum counts as above: it is no measured impact.
                let within = matches!(
                    p.partial_cmp(&cell(row, 5)),
                    Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
                );
                above += f64::from(!within);
                out.push((format!("{b}_impact{}", k + 1), p));
                out.push((format!("{b}_impact{}_band", k + 1), d));
            }
            let mut later: Vec<f64> = peaks.iter().skip(1).take(3).copied().collect();
            let median = match later.len() {
                3 if later.iter().all(|p| p.is_finite()) => {
                    later.sort_by(f64::total_cmp);
                    later[1]
                }
                _ => f64::NAN,
            };
            let error = match rows.len() {
                0 => f64::NAN,
                n => sum / n as f64,
            };
            out.push((format!("{b}_band_error"), error));
            out.push((format!("{b}_impacts_median_2_4"), median));
            out.push((format!("{b}_above_measured_max"), above));
            out
        }
        Metric::EnergyLoss { times } => {
            let e = read_series(&dir.join("energy.csv"), "kinetic+potential").unwrap_or_default();
            times
                .iter()
                .map(|&t| (format!("energy_loss_t{t}"), metrics::energy_loss(&e, t)))
                .collect()
        }
        Metric::DensityFluctuation => vec![(
            "max_density_fluctuation".into(),
            metrics::extreme(&probes("max_density_fluctuation"), 0.0, f64::INFINITY, true),
        )],
        Metric::DensityFluctuationWindow { from, to } => vec![(
            format!("max_density_fluctuation_t{from}-{to}"),
            metrics::extreme(&probes("max_density_fluctuation"), *from, *to, true),
        )],
        Metric::Spatter {
            radius,
            min_neighbours,
        } => {
            let ds = scenario.map_or(f64::NAN, |s| s.spacing);
            let n = final_positions(dir).map_or(f64::NAN, |x| {
                metrics::spattered(&x, radius * ds, *min_neighbours) as f64
            });
            vec![("spattered".into(), n)]
        }
        Metric::Roughness { column, from, to } => vec![(
            format!("{}_total_variation", base(column)),
            metrics::total_variation(&probes(column), *from, *to) / p_scale,
        )],
        Metric::NeighbourRange => vec![
            (
                "neighbours_min".into(),
                metrics::extreme(&probes("neighbours_min"), 0.0, f64::INFINITY, false),
            ),
            (
                "neighbours_max".into(),
                metrics::extreme(&probes("neighbours_max"), 0.0, f64::INFINITY, true),
            ),
        ],
        Metric::Lost => {
            let tank = scenario.and_then(|s| s.spec.tank.as_ref());
            let lost = match (tank, final_positions(dir)) {
                (Some(t), Some(x)) => {
                    let top = if t.open_top {
                        f64::INFINITY
                    } else {
                        t.height.0
                    };
                    metrics::outside(&x, DVec2::ZERO, DVec2::new(t.width.0, top)) as f64
                }
                _ => f64::NAN,
            };
            vec![
                ("lost".into(), lost),
                ("wall_reflections".into(), reflections),
            ]
        }
    }
}

/// The column names of study.csv.
pub fn header(study: &Study, rows: &[Row]) -> Vec<String> {
    let mut h = vec!["case".to_string()];
    h.extend(study.spec.parameters.iter().map(|p| p.name.clone()));
    if study.spec.fallback.is_some() {
        h.push("scheme".into());
    }
    h.extend(
        [
            "status",
            "fluid_particles",
            "steps",
            "simulated_time",
            "wall_seconds",
            "particle_steps_per_second",
        ]
        .map(String::from),
    );
    if let Some(r) = rows.first() {
        h.extend(r.metrics.iter().map(|m| m.0.clone()));
    }
    h
}

fn write_csv(path: &Path, study: &Study, rows: &[Row]) -> Result<(), String> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let err = |e: csv::Error| format!("{}: {e}", path.display());
    w.write_record(header(study, rows)).map_err(err)?;
    for r in rows {
        let rec = r.cells(|v| v.to_string());
        w.write_record(rec).map_err(err)?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| format!("{}: {e}", path.display()))?;
    sph_core::atomic::write_atomic(path, &bytes).map_err(|e| format!("{}: {e}", path.display()))
}

/// A number with four significant digits, or `-` when not finite.
fn short(v: f64) -> String {
    if !v.is_finite() {
        "-".into()
    } else if v.fract() == 0.0 && v.abs() < 1e7 {
        format!("{v:.0}")
    } else if v == 0.0 || (1e-3..1e5).contains(&v.abs()) {
        let digits = (3 - v.abs().log10().floor() as i32).clamp(0, 6) as usize;
        format!("{v:.digits$}")
    } else {
        format!("{v:.3e}")
    }
}

fn write_report(
    study: &Study,
    out_dir: &Path,
    rows: &[Row],
    figures: &[(String, String)],
    opts: StudyOptions,
) -> Result<(), String> {
    let s = &study.spec;
    let StudyOptions {
        workers, threads, ..
    } = opts;
    let mut md = format!("# Study `{}`\n\n", s.name);
    let _ = writeln!(
        md,
        "Base scenario `{}`, {} design, {} cases; common overrides: {}.\n",
        study.scenario.display(),
        match s.design {
            Design::OneAtATime => "one-at-a-time",
            Design::Grid => "full-grid",
        },
        study.cases.len(),
        if s.set.is_empty() {
            "none".into()
        } else {
            format!("`{}`", s.set.join("`, `"))
        }
    );
    let ran = rows.iter().filter(|r| r.ran).count();
    let _ = writeln!(
        md,
        "{ran} case(s) ran now, {workers} at a time on {threads} thread(s) each (independent \
         cases need no synchronisation, while splitting one small case over threads pays a \
         fork-join per stage and step); the others were finished earlier{}. Wall seconds and \
         particle-steps per second are per case, as measured when it ran.\n",
        if opts.report_only {
            " or not run (--report-only)"
        } else {
            ""
        }
    );
    let completed = rows.iter().filter(|r| r.completed()).count();
    match &s.fallback {
        None => {
            let _ = writeln!(md, "{completed} of {} cases completed.\n", rows.len());
        }
        Some(fb) => {
            let base: Vec<&Row> = rows.iter().filter(|r| !r.case.fallback).collect();
            let again: Vec<&Row> = rows.iter().filter(|r| r.case.fallback).collect();
            let done = |v: &[&Row]| v.iter().filter(|r| r.completed()).count();
            // Cases completed by neither scheme.
            let unfinished: Vec<String> = base
                .iter()
                .filter(|r| {
                    let name = format!("{}__{}", r.case.name, fb.label);
                    !r.completed() && !again.iter().any(|f| f.case.name == name && f.completed())
                })
                .map(|r| {
                    if r.status == "not run" {
                        format!("{} (not run)", r.case.name)
                    } else {
                        r.case.name.clone()
                    }
                })
                .collect();
            let _ = writeln!(
                md,
                "{} of {} cases completed with the `{}` scheme. A case that stops early runs \
                 again with the `{}` scheme (the case's overrides, then `{}`), as the row after \
                 it, named `<case>__{}`; the `scheme` column says which scheme each row used. \
                 {} case(s) ran again with `{}`, {} of them completed. {}\n",
                done(&base),
                base.len(),
                fb.base,
                fb.label,
                fb.set.join("`, `"),
                fb.label,
                again.len(),
                fb.label,
                done(&again),
                if unfinished.is_empty() {
                    "Every case completed with one of the two schemes.".to_string()
                } else {
                    format!("Completed by neither scheme: {}.", unfinished.join(", "))
                }
            );
        }
    }
    let head = header(study, rows);
    let _ = writeln!(md, "| {} |", head.join(" | "));
    let _ = writeln!(md, "|{}", "---|".repeat(head.len()));
    for r in rows {
        let cells = r.cells(short);
        let _ = writeln!(md, "| {} |", cells.join(" | "));
    }
    md.push_str("\nMetric definitions: docs/studies.md.\n");
    for (title, file) in figures {
        let _ = writeln!(md, "\n## {title}\n\n![{title}]({file})");
    }
    for t in &s.snapshots {
        let panels: Vec<(String, PathBuf)> = rows
            .iter()
            .map(|r| {
                let file = out_dir
                    .join(&r.case.name)
                    .join(format!("snapshot_t{t:.3}.png"));
                (r.case.legend(), file)
            })
            .collect();
        let file = format!("snapshots_t{t:.3}.png");
        if figures::snapshot_grid(&out_dir.join(&file), &panels)? {
            let _ = writeln!(
                md,
                "\n## Free surface at t = {t} s, per case\n\n![snapshots at t = {t} s]({file})"
            );
        }
    }
    let path = out_dir.join("report.md");
    sph_core::atomic::write_atomic(&path, md.as_bytes())
        .map_err(|e| format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(design: &str, linked: &str) -> StudySpec {
        parse_ron(
            &format!(
                r#"Study(name: "s", scenario: "x.ron", design: {design}, set: ["end_time=1.0"],
                    parameters: [
                        (name: "c0", path: "fluid.sound_speed", values: ["12.0", "25.0", "50.0"]),
                        (name: "k", path: "kernel", values: ["Cubic", "Gaussian"], labels: ["cubic", "gauss"],
                         linked: [(path: "h_over_dx", values: [{linked}])]),
                    ])"#
            ),
            "s.ron",
        )
        .unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn one_at_a_time_varies_each_parameter_from_the_base_case() {
        let cases = cases(&spec("OneAtATime", r#""1.3", "0.9""#), "s.ron", &[]).unwrap();
        let names: Vec<&str> = cases.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "c0_12.0__k_cubic",
                "c0_25.0__k_cubic",
                "c0_50.0__k_cubic",
                "c0_12.0__k_gauss"
            ]
        );
        let raw: Vec<&str> = cases[3].overrides.iter().map(|o| o.raw.as_str()).collect();
        assert_eq!(
            raw,
            [
                "end_time=1.0",
                "fluid.sound_speed=12.0",
                "kernel=Gaussian",
                "h_over_dx=0.9"
            ]
        );
    }

    #[test]
    fn fallback_runs_append_their_overrides_and_name_their_scheme() {
        let text = r#"Study(name: "s", scenario: "x.ron", set: ["end_time=1.0"],
            parameters: [(name: "c0", path: "fluid.sound_speed", values: ["12.0", "25.0"])],
            fallback: (label: "fourtakas", set: ["pipeline.reinitialise.every=1000000000"]))"#;
        let spec: StudySpec = parse_ron(text, "s.ron").unwrap_or_else(|e| panic!("{e}"));
        let cases = cases(&spec, "s.ron", &[]).unwrap();
        assert!(cases.iter().all(|c| c.scheme.as_deref() == Some("paper")));
        let fallbacks = fallback_cases(&spec, "s.ron", text, &cases).unwrap();
        assert_eq!(fallbacks.len(), 2);
        let f = &fallbacks[1];
        assert_eq!(f.name, "c0_25.0__fourtakas");
        assert_eq!(f.legend(), "c0_25.0 (fourtakas)");
        assert_eq!(cases[1].legend(), "c0_25.0");
        assert_eq!((f.scheme.as_deref(), f.fallback), (Some("fourtakas"), true));
        let raw: Vec<&str> = f.overrides.iter().map(|o| o.raw.as_str()).collect();
        assert_eq!(
            raw,
            [
                "end_time=1.0",
                "fluid.sound_speed=25.0",
                "pipeline.reinitialise.every=1000000000"
            ]
        );
        // No fallback field: no scheme, no fallback runs.
        let plain = spec_without_fallback();
        let c = super::cases(&plain, "s.ron", &[]).unwrap();
        assert!(c.iter().all(|c| c.scheme.is_none()));
        assert!(fallback_cases(&plain, "s.ron", "", &c).unwrap().is_empty());
        // The same name for both schemes is refused, at the label.
        let same = text.replace("label: \"fourtakas\"", "label: \"paper\"");
        let spec: StudySpec = parse_ron(&same, "s.ron").unwrap();
        let e = fallback_cases(&spec, "s.ron", &same, &cases).unwrap_err();
        assert_eq!((e.line, e.field.as_deref()), (3, Some("fallback.label")));
    }

    #[test]
    fn a_fallback_folder_that_is_a_case_folder_is_refused() {
        let text = r#"Study(name: "s", scenario: "x.ron",
            parameters: [(name: "a", path: "end_time", values: ["1.0", "2.0"], labels: ["x", "x__f"])],
            fallback: (label: "f", set: ["end_time=3.0"]))"#;
        let spec: StudySpec = parse_ron(text, "s.ron").unwrap_or_else(|e| panic!("{e}"));
        let cases = cases(&spec, "s.ron", &[]).unwrap();
        let e = fallback_cases(&spec, "s.ron", text, &cases).unwrap_err();
        assert!(e.to_string().contains("`a_x__f` is also a case's"), "{e}");
        assert_eq!(e.line, 3);
    }

    fn spec_without_fallback() -> StudySpec {
        spec("OneAtATime", r#""1.3", "0.9""#)
    }

    #[test]
    fn locate_finds_a_field_not_a_path_containing_its_name() {
        let text = "Study(\n  scenario: \"/x/fallback/a.ron\",\n  fallback : (set: [\"a\"]),\n)";
        assert_eq!(locate(text, "fallback"), (3, 3));
        assert_eq!(locate(text, "\"a\""), (3, 21));
        assert_eq!(locate(text, "missing"), (1, 1));
    }

    #[test]
    fn grid_takes_every_combination_and_linked_values_must_match() {
        let cases = cases(&spec("Grid", r#""1.3", "0.9""#), "s.ron", &[]).unwrap();
        assert_eq!(cases.len(), 6);
        assert_eq!(cases[5].name, "c0_50.0__k_gauss");
        let e = super::cases(&spec("Grid", r#""1.3""#), "s.ron", &[]).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("linked"));
        assert!(e.to_string().contains("has 1 values for 2"), "{e}");
    }
}
