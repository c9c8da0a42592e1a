//! A study's cases: the base scenario with each combination of parameter values as
//! `--set` overrides, and the fallback cases.

use super::*;

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

pub(crate) fn spec_error(file: &str, field: &str, message: String) -> LoadError {
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
pub(crate) fn locate(text: &str, needle: &str) -> (usize, usize) {
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
pub(crate) fn folder_safe(label: &str) -> String {
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
pub(crate) fn case_text(case: &Case) -> String {
    case.overrides
        .iter()
        .map(|o| format!("{}\n", o.raw))
        .collect()
}
