//! The study's table (`study.csv`) and report (`report.md`).

use super::*;

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

pub(crate) fn write_csv(path: &Path, study: &Study, rows: &[Row]) -> Result<(), StudyError> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let err = |e: csv::Error| StudyError::file(path, e);
    w.write_record(header(study, rows)).map_err(err)?;
    for r in rows {
        let rec = r.cells(|v| v.to_string());
        w.write_record(rec).map_err(err)?;
    }
    let bytes = w.into_inner().map_err(|e| StudyError::file(path, e))?;
    sph_core::atomic::write_atomic(path, &bytes).map_err(|e| StudyError::file(path, e))
}

/// A number with four significant digits, or `-` when not finite.
pub(crate) fn short(v: f64) -> String {
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

pub(crate) fn write_report(
    study: &Study,
    out_dir: &Path,
    rows: &[Row],
    figures: &[(String, String)],
    opts: StudyOptions,
) -> Result<(), StudyError> {
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
    sph_core::atomic::write_atomic(&path, md.as_bytes()).map_err(|e| StudyError::file(&path, e))
}
