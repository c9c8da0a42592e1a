//! The bench's tables: `bench.csv`, and `bench.md` with each instruction set's speed
//! over the first's.

use super::*;

/// Parallel efficiency of `m`: its throughput over (threads x the 1-thread
/// throughput at the same size), if that run exists.
pub(crate) fn efficiency(m: &Measurement, all: &[Measurement]) -> Option<f64> {
    let one = all
        .iter()
        .find(|o| o.particles == m.particles && o.threads == 1 && o.isa == m.isa)?;
    Some(m.particle_steps_per_second() / (m.threads as f64 * one.particle_steps_per_second()))
}

pub(crate) fn csv_table(fixed: &[Measurement], timed: &[Measurement]) -> String {
    let mut out = String::from("kind,particles,threads,steps,simulated_time_s,wall_s,particle_steps_per_s,interactions_per_s,ghosts_mean,peak_rss_mib,rss_bytes_per_particle_peak,heap_bytes_per_particle_peak,heap_bytes_per_particle_steady,parallel_efficiency,rebuild_interval_steps,pairs_kept_per_tested,isa");
    for s in SHOWN.iter().chain(OUTPUTS.iter()) {
        let _ = write!(out, ",{s}_pct");
    }
    out.push('\n');
    for (kind, set) in [("steps", fixed), ("to_time", timed)] {
        for m in set {
            let eff = efficiency(m, fixed).map_or(String::new(), |e| format!("{e:.3}"));
            let _ = write!(
                out,
                "{kind},{},{},{},{:.6},{:.3},{:.4e},{:.4e},{:.0},{:.1},{:.0},{:.1},{:.1},{eff},{:.2},{:.3}",
                m.particles,
                m.threads,
                m.steps,
                m.simulated_time,
                m.wall_seconds,
                m.particle_steps_per_second(),
                m.interactions / m.wall_seconds.max(1e-12),
                m.ghosts_mean,
                m.peak_bytes as f64 / 1048576.0,
                m.bytes_per_particle(),
                m.heap_peak as f64 / m.particles.max(1) as f64,
                m.steady_bytes_per_particle(),
                m.rebuild_interval,
                m.pairs_kept,
            );
            let _ = write!(out, ",{}", m.isa);
            for s in SHOWN.iter().chain(OUTPUTS.iter()) {
                let _ = write!(out, ",{:.2}", m.share(s));
            }
            out.push('\n');
        }
    }
    out
}

pub(crate) fn markdown(fixed: &[Measurement], timed: &[Measurement], args: &BenchArgs) -> String {
    let mut out = format!(
        "# engine bench\n\n`{}`, {} steps per fixed-step run, median of {} run(s); outputs at the scenario's default rates. Machine: {}, {} logical CPUs; instruction sets available: {}.\n\n",
        args.scenario.display(),
        args.steps,
        args.repeats.max(1),
        processor(),
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        Isa::available()
            .iter()
            .map(|i| i.name())
            .chain(["scalar"])
            .collect::<Vec<_>>()
            .join(", ")
    );
    out += "| particles | threads | instruction set | steps | wall [s] | particle-steps/s | interactions/s | peak RSS [MiB] | B/particle: peak RSS | peak heap | heap while stepping | parallel eff. | list rebuild interval [steps] | pairs kept / tested |\n|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
    for m in fixed {
        let eff = efficiency(m, fixed).map_or("-".into(), |e| format!("{:.0} %", 100.0 * e));
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {:.2} | {:.3e} | {:.3e} | {:.0} | {:.0} | {:.0} | {:.0} | {eff} | {:.1} | {:.2} |",
            m.particles,
            m.threads,
            m.isa,
            m.steps,
            m.wall_seconds,
            m.particle_steps_per_second(),
            m.interactions / m.wall_seconds.max(1e-12),
            m.peak_bytes as f64 / 1048576.0,
            m.bytes_per_particle(),
            m.heap_peak as f64 / m.particles.max(1) as f64,
            m.steady_bytes_per_particle(),
            m.rebuild_interval,
            m.pairs_kept
        );
    }
    out += &isa_ratios(fixed);
    out += &stage_shares(fixed.iter().chain(timed));
    if !timed.is_empty() {
        out += "\nTo a fixed physical time:\n\n| particles | threads | end time [s] | steps | wall [s] | particle-steps/s |\n|---:|---:|---:|---:|---:|---:|\n";
        for m in timed {
            let _ = writeln!(
                out,
                "| {} | {} | {:.3} | {} | {:.2} | {:.3e} |",
                m.particles,
                m.threads,
                m.simulated_time,
                m.steps,
                m.wall_seconds,
                m.particle_steps_per_second()
            );
        }
    }
    out
}

/// The per-stage table: each stage of `SHOWN` in a column, the outputs summed in one,
/// and what is left of the step ("other": the DFSPH solves, shifting, a plugin's).
pub(crate) fn stage_shares<'a>(runs: impl Iterator<Item = &'a Measurement>) -> String {
    let mut out = String::from(
        "\nPer-stage share of the step time [%]:\n\n| particles | threads | instruction set |",
    );
    for s in SHOWN {
        let _ = write!(out, " {s} |");
    }
    out += " probes+outputs | other |\n|---:|---:|---|";
    for _ in 0..SHOWN.len() + 2 {
        out += "---:|";
    }
    out.push('\n');
    for m in runs {
        let _ = write!(out, "| {} | {} | {} |", m.particles, m.threads, m.isa);
        for s in SHOWN {
            let _ = write!(out, " {:.1} |", m.share(s));
        }
        let outputs: f64 = OUTPUTS.iter().map(|s| m.share(s)).sum();
        let shown: f64 = SHOWN.iter().map(|s| m.share(s)).sum();
        let other = (100.0 - shown - outputs).max(0.0);
        let _ = writeln!(out, " {outputs:.2} | {other:.1} |");
    }
    out
}

/// With more than one instruction set, each one's speed over the first's at every
/// size and thread count (medians of runs interleaved in time); empty otherwise.
pub(crate) fn isa_ratios(fixed: &[Measurement]) -> String {
    let mut isas: Vec<&str> = Vec::new();
    for m in fixed {
        if !isas.contains(&m.isa.as_str()) {
            isas.push(&m.isa);
        }
    }
    if isas.len() < 2 {
        return String::new();
    }
    let mut out = format!(
        "\nSpeed against {} (particle-steps/s, medians of interleaved runs):\n\n| particles | threads |",
        isas[0]
    );
    for isa in &isas[1..] {
        let _ = write!(out, " {isa} / {} |", isas[0]);
    }
    out += "\n|---:|---:|";
    out += &"---:|".repeat(isas.len() - 1);
    out.push('\n');
    for first in fixed.iter().filter(|m| m.isa == isas[0]) {
        let _ = write!(out, "| {} | {} |", first.particles, first.threads);
        for isa in &isas[1..] {
            let other = fixed.iter().find(|m| {
                m.isa == *isa && m.particles == first.particles && m.threads == first.threads
            });
            match other {
                Some(o) => {
                    let r = o.particle_steps_per_second() / first.particle_steps_per_second();
                    let _ = write!(out, " {r:.2} |");
                }
                None => out += " - |",
            }
        }
        out.push('\n');
    }
    out
}
