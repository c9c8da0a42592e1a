//! `engine bench`: the dam break at several sizes and thread counts, each run in a
//! child process of its own (so its peak memory is its own), reported as `bench.csv`
//! and `bench.md` (docs/performance.md explains the columns).
//!
//! A run either takes a fixed number of steps (a `BenchStop` stage appended to the
//! pipeline ends it after `--steps` steps) or runs to a fixed physical time
//! (`--time-sizes`, `--end-time`). Outputs are on at the scenario's default rates, so
//! their cost is part of the figures; a run's output folder is deleted afterwards.
//! Benchmarks report; they never assert times.

mod report;
use report::*;

use crate::BenchError;
use serde::{Deserialize, Serialize};
use sph_core::components::{Fluid, Position};
use sph_core::pair::Isa;
use sph_core::sim::Sim;
use sph_core::stage::{Stage, StepError};
use sph_core::vocab::Neighbours;
use sph_core::world::{count, Particles};
use sph_run::runner::{run_keeping_state, RunOptions};
use sph_scenario::overrides::Override;
use sph_scenario::Scenario;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};

pub use sph_alloc::{heap_bytes, CountingAlloc};

/// Options of `engine bench`.
#[derive(clap::Args, Debug, Clone)]
pub struct BenchArgs {
    /// Fluid particle counts, with k/M suffixes. The dam break's column is 2:1, so
    /// N particles means ParticlesAcross(sqrt(2 N)).
    #[arg(long, value_delimiter = ',', default_value = "5k,20k,80k,320k,1.28M")]
    pub sizes: Vec<String>,
    /// Worker-thread counts.
    #[arg(long, value_delimiter = ',', default_value = "1,2", allow_negative_numbers = true,
          value_parser = crate::count("--threads"))]
    pub threads: Vec<usize>,
    /// Steps per fixed-step run. 400, so the first steps (the neighbour lists and
    /// buffers reaching their size, first touch of new memory) weigh little: at 80k on
    /// 2 threads, 100 steps measured 30 % below the steady rate.
    #[arg(long, default_value_t = 400)]
    pub steps: u64,
    /// Runs per size and thread count; the table shows the median wall time.
    #[arg(long, default_value_t = 1)]
    pub repeats: usize,
    /// Sizes also run to `--end-time` on the largest thread count ("none" for none).
    #[arg(long, value_delimiter = ',', default_value = "5k,20k")]
    pub time_sizes: Vec<String>,
    /// Physical end time of the `--time-sizes` runs [s].
    #[arg(long, default_value_t = 0.62)]
    pub end_time: f64,
    /// The scenario to run.
    #[arg(long, default_value = "scenarios/dam_break.ron")]
    pub scenario: PathBuf,
    /// Extra overrides for every run, as for a normal run (e.g. --set
    /// pipeline.neighbour_grid.sort_every=0).
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub sets: Vec<String>,
    /// Folder for bench.csv and bench.md.
    #[arg(long, default_value = "out/bench")]
    pub out: PathBuf,
    /// Instruction sets to run every fixed-step case on, interleaved within each
    /// repeat (so a noisy host loads them alike): `auto`, every SIMD set this
    /// processor has, widest first (AVX-512 and AVX2 on a host with both, so one bench
    /// compares them); or a list of `avx512`, `avx2`, `scalar`. The fixed-time runs use
    /// the first.
    #[arg(long, value_delimiter = ',', default_value = "auto")]
    pub isa: Vec<String>,
    /// Internal: run one case in this process and print its result as JSON.
    #[arg(long, hide = true)]
    pub child: Option<String>,
}

/// The instruction sets `--isa` asks for, checked against this processor's.
fn requested_isas(asked: &[String]) -> Result<Vec<&'static str>, BenchError> {
    let available: Vec<&'static str> = Isa::available().iter().map(|i| i.name()).collect();
    let mut isas: Vec<&'static str> = Vec::new();
    for name in asked.iter().map(|s| s.trim()) {
        let found = match name {
            "auto" if available.is_empty() => vec!["scalar"],
            "auto" => available.clone(),
            "scalar" => vec!["scalar"],
            _ => match available.iter().find(|a| **a == name) {
                Some(a) => vec![*a],
                None => {
                    return Err(BenchError::UnknownIsa {
                        name: name.to_string(),
                        available,
                    })
                }
            },
        };
        for isa in found {
            if !isas.contains(&isa) {
                isas.push(isa);
            }
        }
    }
    if isas.is_empty() {
        return Err(BenchError::NoIsa);
    }
    Ok(isas)
}

/// The instruction set this process runs its pair sums on (the environment's choice:
/// `SPH_NO_SIMD`, `SPH_SIMD`).
pub fn detected_isa() -> &'static str {
    Isa::detect().name()
}

/// The processor's model name (from /proc/cpuinfo), or "unknown processor".
fn processor() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|info| {
            info.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| "unknown processor".into())
}

/// One run's measurements (what a child process prints).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Measurement {
    pub particles: usize,
    pub threads: usize,
    pub steps: u64,
    pub simulated_time: f64,
    pub wall_seconds: f64,
    pub ghosts_mean: f64,
    /// Neighbour pairs at the last step times the steps: pair interactions per sweep.
    pub interactions: f64,
    /// Steps per build of the neighbour lists (their mean age; 1 without a skin).
    #[serde(default)]
    pub rebuild_interval: f64,
    /// Of the pairs in the lists at the end, the fraction within the kernel support
    /// (the rest is the lists' skin, tested and skipped in every pair loop).
    #[serde(default)]
    pub pairs_kept: f64,
    /// (stage, seconds).
    pub stages: Vec<(String, f64)>,
    /// Peak resident memory of the process (VmHWM) [bytes].
    pub peak_bytes: u64,
    /// Resident memory before the scenario was loaded [bytes].
    pub base_bytes: u64,
    /// Resident memory at the end of the run, the state still held (VmRSS) [bytes].
    pub end_bytes: u64,
    /// Live heap at the end of the last step, every stage's buffers included, minus
    /// before loading (counting allocator).
    pub heap_end: u64,
    /// Peak live heap during the run (setup included), minus before loading.
    pub heap_peak: u64,
    pub status: String,
    /// The run's probes.csv `front` column, (time, x), when the scenario writes it.
    pub front: Vec<(f64, f64)>,
    /// summary.json's diagnostics (the DFSPH solves' iteration counts among them).
    #[serde(default)]
    pub diagnostics: std::collections::BTreeMap<String, f64>,
    /// The instruction set the pair sums ran on (`scalar`, `avx2`, `avx512`).
    #[serde(default)]
    pub isa: String,
}

impl Measurement {
    pub fn particle_steps_per_second(&self) -> f64 {
        self.particles as f64 * self.steps as f64 / self.wall_seconds.max(1e-12)
    }
    /// Peak memory above the process's starting footprint, per fluid particle.
    pub fn bytes_per_particle(&self) -> f64 {
        self.peak_bytes.saturating_sub(self.base_bytes) as f64 / self.particles.max(1) as f64
    }
    /// Live heap while stepping (at the end of the last step) per fluid particle: the
    /// state, lists and stage buffers the run holds, without the transient peak of
    /// setup.
    pub fn steady_bytes_per_particle(&self) -> f64 {
        self.heap_end as f64 / self.particles.max(1) as f64
    }
    fn share(&self, stage: &str) -> f64 {
        let total: f64 = self.stages.iter().map(|s| s.1).sum();
        let s: f64 = self
            .stages
            .iter()
            .filter(|s| s.0 == stage)
            // From +0: an empty f64 sum is -0, which the tables would print as "-0.0".
            .fold(0.0, |sum, s| sum + s.1);
        100.0 * s / total.max(1e-300)
    }
}

/// Placed last in the pipeline, after `Integrate`: records the live heap at the end
/// of every step (while every stage still holds its buffers) and, with `steps > 0`,
/// ends the run after that many steps, so the last step is an ordinary one.
struct BenchStop {
    steps: u64,
}

/// Live heap at the end of the last step, recorded by [`BenchStop`].
static LIVE_WHILE_STEPPING: AtomicUsize = AtomicUsize::new(0);

#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct StopParams {
    steps: u64,
}

impl Stage for BenchStop {
    fn name(&self) -> &'static str {
        "bench_stop"
    }
    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        LIVE_WHILE_STEPPING.store(heap_bytes().0, Ordering::Relaxed);
        if self.steps > 0 && sim.clock.step >= self.steps {
            sim.clock.end_time = sim.clock.time;
        }
        Ok(())
    }
}

/// Parses 5k, 20k, 1.28M, 5000.
pub fn parse_count(s: &str) -> Result<usize, BenchError> {
    let s = s.trim();
    let (num, scale) = match s.chars().last() {
        Some('k' | 'K') => (&s[..s.len() - 1], 1e3),
        Some('M' | 'm') => (&s[..s.len() - 1], 1e6),
        _ => (s, 1.0),
    };
    num.parse::<f64>()
        .ok()
        .filter(|v| *v > 0.0)
        .map(|v| (v * scale).round() as usize)
        .ok_or_else(|| BenchError::NotACount {
            text: s.to_string(),
        })
}

fn label(n: usize) -> String {
    if n >= 1_000_000 {
        format!("{}M", n as f64 / 1e6)
    } else if n >= 1000 {
        format!("{}k", n as f64 / 1e3)
    } else {
        n.to_string()
    }
}

/// Resident-memory figures from /proc/self/status [bytes] (0 where unavailable).
fn proc_status(field: &str) -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(field))
                .and_then(|l| l.split_whitespace().nth(1).map(str::to_string))
        })
        .and_then(|kb| kb.parse::<u64>().ok())
        .map_or(0, |kb| kb * 1024)
}

/// A case: particles, threads, steps (0: run to `end_time`), end time.
#[derive(Clone, Copy, Debug)]
pub struct Case {
    pub particles: usize,
    pub threads: usize,
    pub steps: u64,
    pub end_time: f64,
}

impl Case {
    fn encode(&self) -> String {
        format!(
            "{},{},{},{}",
            self.particles, self.threads, self.steps, self.end_time
        )
    }
    fn decode(s: &str) -> Result<Self, BenchError> {
        let v: Vec<&str> = s.split(',').collect();
        let bad = || BenchError::BadChild {
            spec: s.to_string(),
        };
        if v.len() != 4 {
            return Err(bad());
        }
        Ok(Self {
            particles: v[0].parse().map_err(|_| bad())?,
            threads: v[1].parse().map_err(|_| bad())?,
            steps: v[2].parse().map_err(|_| bad())?,
            end_time: v[3].parse().map_err(|_| bad())?,
        })
    }
}

/// Runs one case in this process.
pub fn run_case(
    case: Case,
    scenario: &Path,
    sets: &[String],
    extra: &[&str],
    out: &Path,
) -> Result<Measurement, BenchError> {
    let base_bytes = proc_status("VmRSS:");
    let heap_base = heap_bytes().0;
    let mut text = std::fs::read_to_string(scenario).map_err(|source| BenchError::Read {
        path: scenario.to_path_buf(),
        source,
    })?;
    let mut registry = sph_stages::standard_registry();
    registry.register_checked(
        "bench_stop",
        "ends a benchmark run after a fixed number of steps",
        |p: StopParams| Ok(BenchStop { steps: p.steps }),
    );
    #[cfg(not(feature = "dim3"))]
    let across = ((2 * case.particles) as f64).sqrt().round() as usize;
    // 3D: n across the first block's width gives n^3 (height/width)(breadth/width).
    #[cfg(feature = "dim3")]
    let across = {
        let sets = crate::parse_sets(sets)?;
        let probe = Scenario::from_str(&text, &scenario.display().to_string(), &sets, &registry)?;
        let size = probe.spec.fluid_blocks[0].size;
        let shape = size.1 .0 * size.2 .0 / (size.0 .0 * size.0 .0);
        (case.particles as f64 / shape).cbrt().round().max(2.0) as usize
    };
    let mut overrides: Vec<String> = vec![format!("resolution=ParticlesAcross({across})")];
    // Append BenchStop as the pipeline's last entry: before the file's last `]`.
    let at = text.rfind(']').ok_or(BenchError::NoPipeline)?;
    text.insert_str(at, &format!("BenchStop(steps: {}),\n", case.steps));
    if case.steps > 0 {
        // BenchStop ends the run; the end time only has to lie beyond the steps (a few
        // hundred at dt ~ 1e-4 s) and keep the probes' and frames' row counts inside
        // the engine's size limits, which an unbounded end time would break.
        overrides.push("end_time=10.0".into());
    } else {
        overrides.push(format!("end_time={}", case.end_time));
    }
    overrides.extend(extra.iter().map(|s| s.to_string()));
    overrides.extend(sets.iter().cloned());
    let overrides = overrides
        .iter()
        .map(|s| s.parse::<Override>())
        .collect::<Result<Vec<_>, _>>()?;
    let scenario = Scenario::from_str(
        &text,
        &scenario.display().to_string(),
        &overrides,
        &registry,
    )?;
    if scenario.spec.pipeline.last().map(|e| e.name.as_str()) != Some("bench_stop") {
        return Err(BenchError::StopNotLast);
    }
    // Profiled for the per-stage shares.
    let opts = RunOptions {
        profile: true,
        ..RunOptions::quiet(out, case.threads)
    };
    let (summary, sim) = run_keeping_state(scenario, &opts)?;
    let end_bytes = proc_status("VmRSS:");
    let heap_peak = heap_bytes().1;
    let heap_end = LIVE_WHILE_STEPPING.load(Ordering::Relaxed);
    let (pairs, pairs_kept, rebuild_interval) =
        sim.resources
            .get::<Neighbours>()
            .map_or((0, 0.0, 0.0), |nb| {
                let pairs = nb.interactions();
                (
                    pairs,
                    within_support(&sim, nb) as f64 / pairs.max(1) as f64,
                    nb.calls as f64 / nb.builds.max(1) as f64,
                )
            });
    let front = front_series(&out.join("probes.csv"));
    Ok(Measurement {
        particles: count::<Fluid>(&sim.world),
        threads: summary.threads,
        steps: summary.steps,
        simulated_time: summary.simulated_time,
        wall_seconds: summary.wall_seconds,
        ghosts_mean: summary.ghost_particles_mean,
        interactions: pairs as f64 * summary.steps as f64,
        rebuild_interval,
        pairs_kept,
        isa: detected_isa().into(),
        stages: summary
            .stages
            .iter()
            .map(|s| (s.stage.clone(), s.seconds))
            .collect(),
        peak_bytes: proc_status("VmHWM:"),
        base_bytes,
        end_bytes,
        heap_end: heap_end.saturating_sub(heap_base) as u64,
        heap_peak: heap_peak.saturating_sub(heap_base) as u64,
        status: summary.status,
        front,
        diagnostics: summary.diagnostics,
    })
}

/// The pairs of the lists within the kernel support at the current positions.
fn within_support(sim: &Sim, nb: &Neighbours) -> usize {
    let Some(x) = Particles::of(&sim.world).and_then(|p| p.joined::<Position>().ok()) else {
        return 0;
    };
    let x = x.view();
    if x.len() < nb.n_fluid + nb.n_ghost {
        return 0;
    }
    let r2 = nb.support * nb.support;
    (0..nb.n_fluid)
        .map(|i| {
            let xi = x.get(i as u32).0;
            nb.of(i)
                .iter()
                .filter(|&&j| xi.distance_squared(x.get(j).0) < r2)
                .count()
        })
        .sum()
}

/// The `front` column of a probes.csv, if any.
fn front_series(path: &Path) -> Vec<(f64, f64)> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Vec::new();
    };
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let Some(k) = lines
        .next()
        .and_then(|h| h.split(',').position(|c| c.trim() == "front"))
    else {
        return Vec::new();
    };
    lines
        .filter_map(|l| {
            let v: Vec<&str> = l.split(',').collect();
            Some((
                v.first()?.trim().parse().ok()?,
                v.get(k)?.trim().parse().ok()?,
            ))
        })
        .collect()
}

/// Runs one case in a child process (the current executable with `bench --child`),
/// with `extra` overrides after `args.sets`, on instruction set `isa` (`avx512`,
/// `avx2` or `scalar`; [`detected_isa`] for the one this process would use).
pub fn run_child(
    case: Case,
    args: &BenchArgs,
    extra: &[&str],
    isa: &str,
    tag: &str,
) -> Result<Measurement, BenchError> {
    let exe = std::env::current_exe().map_err(BenchError::CurrentExe)?;
    let out = args.out.join("runs").join(tag);
    let mut cmd = Command::new(exe);
    cmd.arg("bench")
        .arg("--child")
        .arg(case.encode())
        .arg("--scenario")
        .arg(&args.scenario)
        .arg("--out")
        .arg(&out);
    for s in args
        .sets
        .iter()
        .map(String::as_str)
        .chain(extra.iter().copied())
    {
        cmd.arg(format!("--set={s}"));
    }
    // The child picks its instruction set from these (`Isa::detect`).
    cmd.env_remove("SPH_SIMD").env_remove("SPH_NO_SIMD");
    match isa {
        "avx2" => cmd.env("SPH_SIMD", "avx2"),
        "scalar" => cmd.env("SPH_NO_SIMD", "1"),
        _ => &mut cmd,
    };
    let output = cmd.output().map_err(BenchError::Spawn)?;
    let _ = std::fs::remove_dir_all(&out);
    let stdout = String::from_utf8_lossy(&output.stdout);
    let line = stdout.lines().rev().find(|l| l.starts_with('{'));
    match (output.status.success(), line) {
        (true, Some(line)) => {
            let m: Measurement = serde_json::from_str(line)?;
            match m.isa == isa {
                true => Ok(m),
                false => Err(BenchError::WrongIsa {
                    tag: tag.to_string(),
                    asked: isa.to_string(),
                    used: m.isa,
                }),
            }
        }
        _ => Err(BenchError::ChildFailed {
            tag: tag.to_string(),
            stderr: String::from_utf8_lossy(&output.stderr).trim().to_string(),
        }),
    }
}

/// The child side: run the case given by `--child` and print its measurement.
fn child_main(spec: &str, args: &BenchArgs) -> Result<(), BenchError> {
    let case = Case::decode(spec)?;
    let m = run_case(case, &args.scenario, &args.sets, &[], &args.out)?;
    println!("{}", serde_json::to_string(&m)?);
    Ok(())
}

fn median(mut v: Vec<Measurement>) -> Measurement {
    v.sort_by(|a, b| a.wall_seconds.total_cmp(&b.wall_seconds));
    v.swap_remove(v.len() / 2)
}

/// Stages reported in their own column; the outputs are summed in one, and the rest
/// (the DFSPH solves, shifting, a plugin's) as "other".
const SHOWN: [&str; 9] = [
    "ghost_walls",
    "wall_particles",
    "wall_pressure",
    "neighbour_grid",
    "reinitialise",
    "continuity",
    "forces",
    "integrate",
    "eos",
];
const OUTPUTS: [&str; 4] = ["probe", "energy", "vtk_frames", "snapshots"];

/// Runs the whole benchmark; returns the fixed-step and fixed-time measurements.
pub fn bench(args: &BenchArgs) -> Result<(Vec<Measurement>, Vec<Measurement>), BenchError> {
    if let Some(spec) = &args.child {
        child_main(spec, args)?;
        return Ok((Vec::new(), Vec::new()));
    }
    let sizes = args
        .sizes
        .iter()
        .map(|s| parse_count(s))
        .collect::<Result<Vec<_>, _>>()?;
    let time_sizes = args
        .time_sizes
        .iter()
        .filter(|s| !matches!(s.trim(), "" | "none"))
        .map(|s| parse_count(s))
        .collect::<Result<Vec<_>, _>>()?;
    if args.threads.contains(&0) || args.threads.is_empty() {
        return Err(BenchError::NoThreads);
    }
    let isas = requested_isas(&args.isa)?;
    std::fs::create_dir_all(&args.out).map_err(|source| BenchError::CreateDir {
        path: args.out.clone(),
        source,
    })?;
    let mut fixed = Vec::new();
    for &n in &sizes {
        for &t in &args.threads {
            let mut runs: Vec<Vec<Measurement>> = vec![Vec::new(); isas.len()];
            for r in 0..args.repeats.max(1) {
                let case = Case {
                    particles: n,
                    threads: t,
                    steps: args.steps,
                    end_time: 0.0,
                };
                for (k, isa) in isas.iter().enumerate() {
                    let tag = format!("{}-{t}t-{isa}-{r}", label(n));
                    let m = run_child(case, args, &[], isa, &tag)?;
                    eprintln!(
                        "{:>6} particles, {t} thread(s), {isa}, run {}: {:.2} s, {:.3e} particle-steps/s",
                        m.particles,
                        r + 1,
                        m.wall_seconds,
                        m.particle_steps_per_second()
                    );
                    runs[k].push(m);
                }
            }
            fixed.extend(runs.into_iter().map(median));
        }
    }
    let mut timed = Vec::new();
    let t_max = args.threads.iter().copied().max().unwrap_or(1);
    for &n in &time_sizes {
        let case = Case {
            particles: n,
            threads: t_max,
            steps: 0,
            end_time: args.end_time,
        };
        let m = run_child(case, args, &[], isas[0], &format!("{}-to-t", label(n)))?;
        eprintln!(
            "{:>6} particles to t = {} s: {:.2} s wall, {} steps",
            m.particles, m.simulated_time, m.wall_seconds, m.steps
        );
        timed.push(m);
    }
    let (csv, md) = (csv_table(&fixed, &timed), markdown(&fixed, &timed, args));
    for (name, text) in [("bench.csv", &csv), ("bench.md", &md)] {
        let path = args.out.join(name);
        if let Err(source) = std::fs::write(&path, text) {
            return Err(BenchError::Write { path, source });
        }
    }
    let _ = std::fs::remove_dir_all(args.out.join("runs"));
    println!("{md}");
    println!(
        "written: {}, {}",
        args.out.join("bench.csv").display(),
        args.out.join("bench.md").display()
    );
    Ok((fixed, timed))
}

/// Entry point of `engine bench`.
pub fn main(args: &BenchArgs) -> Result<(), BenchError> {
    bench(args).map(|_| ())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `auto` is every SIMD set, widest first (or scalar); names are checked and
    /// repeats dropped.
    #[test]
    fn instruction_sets_are_checked() {
        let auto = requested_isas(&["auto".into()]).unwrap();
        let available: Vec<_> = Isa::available().iter().map(|i| i.name()).collect();
        match available.is_empty() {
            true => assert_eq!(auto, ["scalar"]),
            false => assert_eq!(auto, available),
        }
        let two = requested_isas(&["scalar".into(), "scalar".into()]).unwrap();
        assert_eq!(two, ["scalar"]);
        let err = requested_isas(&["sse".into()]).unwrap_err().to_string();
        assert!(err.contains("`sse`") && err.contains("scalar"), "{err}");
        assert!(requested_isas(&[]).is_err());
    }

    /// The ratio table divides each set's speed by the first's, at the same size and
    /// thread count.
    #[test]
    fn instruction_sets_are_compared_as_ratios() {
        let m = |isa: &str, threads: usize, wall: f64| Measurement {
            particles: 1000,
            threads,
            steps: 100,
            wall_seconds: wall,
            isa: isa.into(),
            ..Default::default()
        };
        let fixed = [m("avx512", 1, 1.0), m("avx2", 1, 2.0), m("avx512", 2, 1.0)];
        // A stage the run did not have takes no share, printed as 0.0, not -0.0.
        assert_eq!(fixed[0].share("reinitialise").to_bits(), 0f64.to_bits());
        let table = isa_ratios(&fixed);
        assert!(table.contains("| avx2 / avx512 |"), "{table}");
        assert!(table.contains("| 1000 | 1 | 0.50 |"), "{table}");
        assert!(table.contains("| 1000 | 2 | - |"), "{table}");
        assert_eq!(isa_ratios(&fixed[..1]), "");
    }

    /// Each shown stage has its column, the outputs one, and the stages without a
    /// column (a DFSPH solve here) are summed as "other", so a row adds up to 100.
    #[test]
    fn stage_shares_add_up_to_the_step() {
        let m = Measurement {
            particles: 1000,
            threads: 1,
            isa: "avx2".into(),
            stages: [
                ("forces", 5.0),
                ("wall_pressure", 2.0),
                ("density_solve", 2.0),
                ("probe", 1.0),
            ]
            .map(|(s, t)| (s.to_string(), t))
            .to_vec(),
            ..Default::default()
        };
        let table = report::stage_shares([&m].into_iter());
        let header = table.lines().find(|l| l.contains("| forces |")).unwrap();
        let row = table.lines().find(|l| l.starts_with("| 1000 |")).unwrap();
        let cell = |name: &str| {
            let k = header.split('|').position(|c| c.trim() == name).unwrap();
            row.split('|').nth(k).unwrap().trim().to_string()
        };
        assert_eq!(cell("forces"), "50.0", "{table}");
        assert_eq!(cell("wall_pressure"), "20.0", "{table}");
        assert_eq!(cell("probes+outputs"), "10.00", "{table}");
        assert_eq!(cell("other"), "20.0", "{table}");
    }

    #[test]
    fn counts_parse_with_suffixes() {
        assert_eq!(parse_count("5k").ok(), Some(5000));
        assert_eq!(parse_count("1.28M").ok(), Some(1_280_000));
        assert_eq!(parse_count("320").ok(), Some(320));
        assert!(parse_count("lots").is_err());
        assert_eq!(label(1_280_000), "1.28M");
    }
}
