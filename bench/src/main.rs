//! `sph-bench`: `engine bench` plus a side-by-side run of the peer salva2d (DFSPH).
//!
//!   cargo run --release -p sph-bench -- bench [engine bench options]
//!   cargo run --release -p sph-bench -- peer [--sizes 5k,20k] [--threads 2] [--end-time 0.62]
//!
//! `peer` runs Martin & Moyce's n^2 = 2 column (a = 0.3 m wide, 0.6 m high, in the dam
//! break's 3.22 m tank; the geometry of tests/tests/dam_break.rs) in both engines at
//! the same particle spacing and to the same physical end time, and prints wall time
//! to solution and the surge-front error against Martin & Moyce (a = 2.25 in series,
//! tests/data), for our WCSPH and DFSPH pipelines. What is not like for like is listed in `peer.md` and
//! docs/performance.md.

use clap::{Parser, Subcommand};
use engine::bench::{parse_count, run_child, BenchArgs, Case, Measurement};
use engine::BenchError;
use salva2d::kernel::CubicSplineKernel;
use salva2d::math::Vector;
use salva2d::object::interaction_groups::InteractionGroups;
use salva2d::object::{Boundary, Fluid};
use salva2d::solver::{ArtificialViscosity, DFSPHSolver};
use salva2d::LiquidWorld;
use sph_tests::support::{interpolate, reference};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

/// Counts heap bytes for the benchmark (engine::bench::CountingAlloc).
#[global_allocator]
static ALLOC: engine::bench::CountingAlloc = engine::bench::CountingAlloc;

#[derive(Parser)]
#[command(name = "sph-bench")]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// The engine's own benchmark (same options as `engine bench`).
    Bench(BenchArgs),
    /// Our engine against salva2d on Martin & Moyce's column.
    Peer(PeerArgs),
}

#[derive(clap::Args, Clone)]
struct PeerArgs {
    /// Fluid particle counts; the column is twice as high as wide, so N particles
    /// means ParticlesAcross(sqrt(N/2)).
    #[arg(long, value_delimiter = ',', default_value = "5k,20k")]
    sizes: Vec<String>,
    /// Worker threads for both engines.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Physical end time [s].
    #[arg(long, default_value_t = 0.62)]
    end_time: f64,
    /// The scenario our engine runs (the column is set by overrides).
    #[arg(long, default_value = "scenarios/dam_break.ron")]
    scenario: PathBuf,
    /// The same with our DFSPH pipeline (a third row).
    #[arg(long, default_value = "scenarios/dam_break_dfsph.ron")]
    dfsph_scenario: PathBuf,
    /// Overrides for the DFSPH row (as `engine --set`, separated by ';'). Default: the
    /// density solve's tolerance at 0.5 % mean compression instead of the scenario's
    /// 0.1 % (salva2d's default is 5 %): the front error against Martin & Moyce does not
    /// grow with it (docs/performance.md, "DFSPH"), while Buchner's P1 after the impact
    /// does, so the scenario keeps 0.1 %. Pass an empty string for the scenario as is.
    #[arg(
        long,
        value_delimiter = ';',
        default_value = "pipeline.density_solve.tolerance=0.005"
    )]
    dfsph_set: Vec<String>,
    /// salva2d's density tolerance: the mean compression max(rho*/rho_0 - 1, 0) at which
    /// its density solve stops (`DFSPHSolver::max_density_error`). Default: salva2d's own
    /// default, 5 %; 0.005 gives it the DFSPH row's 0.5 %.
    #[arg(long, default_value_t = 0.05)]
    salva_tolerance: f64,
    /// Folder for peer.md.
    #[arg(long, default_value = "out/bench")]
    out: PathBuf,
}

/// Why `sph-bench` failed.
#[derive(Debug, thiserror::Error)]
enum PeerError {
    /// `engine bench`, or one of the engine's runs of `peer`, failed.
    #[error(transparent)]
    Bench(#[from] BenchError),
    /// `--salva-tolerance` is not a fraction between 0 and 1.
    #[error("--salva-tolerance {tolerance}: expected a fraction of rho_0 between 0 and 1 (salva2d's default 0.05)")]
    Tolerance { tolerance: f64 },
    /// salva2d's thread pool could not be built.
    #[error(transparent)]
    ThreadPool(#[from] rayon::ThreadPoolBuildError),
    /// The output folder could not be created.
    #[error("{source}")]
    CreateDir {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// `peer.md` could not be written.
    #[error("{source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Column width a [m] and height 2a: Martin & Moyce's n^2 = 2.
const A: f64 = 0.3;
const TANK: (f64, f64) = (3.22, 1.8);
const G: f64 = 9.81;
const RHO0: f64 = 1000.0;

/// Martin & Moyce (1952), n^2 = 2, a = 2.25 in: (T, Z) with T = t sqrt(2g/a), Z = z/a.
fn martin_moyce() -> Vec<(f64, f64)> {
    reference("martin_moyce_1952_surge_n2-2_a2.25in_pysph.csv")
}

/// The experiment's gate-opening delay in T units (Lethe's value), applied as in
/// tests/tests/dam_break.rs: the simulated Z at T - GATE_DELAY is compared with the
/// data at T.
const GATE_DELAY: f64 = 0.175;

/// Front error against the data over 1 <= T <= T(end): (mean |Z/Z_data - 1|, T of the
/// last data point, the signed error there), with `front` given as (t [s], x [m]) and
/// the simulation delayed by `delay` (T units).
fn front_error(front: &[(f64, f64)], end_time: f64, delay: f64) -> (f64, f64, f64) {
    let scale = (2.0 * G / A).sqrt();
    let sim: Vec<(f64, f64)> = front.iter().map(|&(t, x)| (t * scale, x / A)).collect();
    let t_end = end_time * scale;
    let errs: Vec<(f64, f64)> = martin_moyce()
        .into_iter()
        .filter(|p| p.0 >= 1.0 && p.0 <= t_end)
        .map(|(t, z)| (t, interpolate(&sim, t - delay) / z - 1.0))
        .collect();
    let mean = errs.iter().map(|e| e.1.abs()).sum::<f64>() / errs.len().max(1) as f64;
    let last = errs.last().copied().unwrap_or((f64::NAN, f64::NAN));
    (mean, last.0, last.1)
}

struct PeerResult {
    particles: usize,
    wall: f64,
    steps: u64,
    front: Vec<(f64, f64)>,
}

/// How salva2d's step is chosen. salva2d 0.11 takes one substep per `LiquidWorld::step`
/// call: its CFL substepping is disabled (`TimestepManager::compute_substep` returns the
/// whole frame, marked FIXME), so the caller's frame is its time step.
#[derive(Clone, Copy, PartialEq)]
enum SalvaStep {
    /// Fixed frames of 10 x 0.4 ds / (7 m/s): the bench's set-up before it was known that
    /// salva2d does not substep; particles then move up to about 2.8 ds per step.
    Fixed,
    /// dt = CFL x ds / max|v|, at most `MAX_DT`: the rule of our DFSPH pipeline
    /// (stages/src/solvers/density_solve.rs) and the one salva2d's own disabled
    /// `TimestepManager::max_substep` computes (0.4 x particle diameter / max speed).
    Cfl,
}

/// The CFL number and step cap shared by both DFSPH codes when stepped by [`SalvaStep::Cfl`]
/// (the defaults of our `DensitySolve`: courant 0.4, max_dt 5 ms).
const CFL: f64 = 0.4;
const MAX_DT: f64 = 5e-3;

/// salva2d on the same column: DFSPH, particles of radius ds/2 on the same lattice,
/// three layers of boundary particles (Akinci) along floor and side walls, artificial
/// viscosity. Front = largest x of fluid with y < ds, plus ds/2 (our probe's rule).
fn run_salva(
    across: usize,
    threads: usize,
    end_time: f64,
    rule: SalvaStep,
    tolerance: f64,
) -> Result<PeerResult, PeerError> {
    let ds = A / across as f64;
    let r = (ds / 2.0) as f32;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    pool.install(|| {
        let mut solver = DFSPHSolver::<CubicSplineKernel, CubicSplineKernel>::new();
        solver.max_density_error = tolerance as f32;
        let mut world = LiquidWorld::new(solver, r, 2.0, 1.0);
        let rows = 2 * across;
        let mut fluid_points = Vec::with_capacity(across * rows);
        for j in 0..rows {
            for i in 0..across {
                fluid_points.push(Vector::new(
                    ((i as f64 + 0.5) * ds) as f32,
                    ((j as f64 + 0.5) * ds) as f32,
                ));
            }
        }
        let particles = fluid_points.len();
        let mut fluid = Fluid::new(fluid_points, r, RHO0 as f32, InteractionGroups::default());
        fluid
            .nonpressure_forces
            .push(Box::new(ArtificialViscosity::new(0.03, 0.0)));
        world.add_fluid(fluid);
        let mut wall = Vec::new();
        let (nx, ny) = ((TANK.0 / ds).ceil() as i64, (TANK.1 / ds).ceil() as i64);
        for layer in 0..3 {
            let off = (layer as f64 + 0.5) * ds;
            for i in -3..nx + 3 {
                wall.push(Vector::new(((i as f64 + 0.5) * ds) as f32, (-off) as f32));
            }
            for j in 0..ny {
                let y = ((j as f64 + 0.5) * ds) as f32;
                wall.push(Vector::new((-off) as f32, y));
                wall.push(Vector::new((TANK.0 + off) as f32, y));
            }
        }
        world.add_boundary(Boundary::new(wall, InteractionGroups::default()));
        let gravity = Vector::new(0.0, -G as f32);
        // v <= 2 sqrt(2 g 0.6) ~ 7 m/s
        let frame = (0.4 * ds / 7.0 * 10.0).min(0.005);
        let start = Instant::now();
        let (mut t, mut steps, mut front) = (0.0, 0u64, Vec::new());
        while t < end_time - 1e-12 {
            let step = match rule {
                SalvaStep::Fixed => frame,
                SalvaStep::Cfl => {
                    let v_max = world
                        .fluids()
                        .iter()
                        .flat_map(|(_, f)| f.velocities.iter())
                        .map(|v| v.norm() as f64)
                        .fold(0.0, f64::max);
                    match v_max > 0.0 {
                        true => (CFL * ds / v_max).min(MAX_DT),
                        false => MAX_DT,
                    }
                }
            };
            let dt = step.min(end_time - t);
            world.step(dt as f32, &gravity);
            steps += world.counters.nsubsteps as u64;
            t += dt;
            let x_front = world
                .fluids()
                .iter()
                .flat_map(|(_, f)| f.positions.iter())
                .filter(|p| (p.y as f64) < ds)
                .map(|p| p.x as f64)
                .fold(f64::NEG_INFINITY, f64::max);
            front.push((t, x_front + 0.5 * ds));
        }
        Ok(PeerResult {
            particles,
            wall: start.elapsed().as_secs_f64(),
            steps,
            front,
        })
    })
}

fn peer(args: &PeerArgs) -> Result<(), PeerError> {
    let tolerance = args.salva_tolerance;
    if !(tolerance > 0.0 && tolerance < 1.0) {
        return Err(PeerError::Tolerance { tolerance });
    }
    std::fs::create_dir_all(&args.out).map_err(|source| PeerError::CreateDir {
        path: args.out.clone(),
        source,
    })?;
    let bench = BenchArgs {
        sizes: Vec::new(),
        threads: vec![args.threads],
        steps: 0,
        repeats: 1,
        time_sizes: Vec::new(),
        end_time: args.end_time,
        scenario: args.scenario.clone(),
        sets: Vec::new(),
        out: args.out.clone(),
        isa: Vec::new(),
        child: None,
    };
    // The instruction set this process would use (the environment's choice).
    let isa = engine::bench::detected_isa();
    let mut table = format!(
        "| particles | ds [mm] | engine | steps | solver iterations per step (density + divergence) | wall to t [s] | wall ratio (salva2d / ours) | mean front error | at the last data point | mean front error, gate delay {GATE_DELAY} | at the last data point, gate delay |\n|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for size in &args.sizes {
        let n = parse_count(size)?;
        let across = ((n / 2) as f64).sqrt().round() as usize;
        let ds = A / across as f64;
        let blocks = format!("fluid_blocks=[(min: (0.0, 0.0), size: ({A}, {}))]", 2.0 * A);
        let res = format!("resolution=ParticlesAcross({across})");
        let overrides = [blocks.as_str(), res.as_str(), "pipeline.snapshots.times=[]"];
        let case = Case {
            particles: n,
            threads: args.threads,
            steps: 0,
            end_time: args.end_time,
        };
        let ours: Measurement = run_child(case, &bench, &overrides, isa, &format!("peer-{size}"))?;
        eprintln!(
            "ours: {} particles to t = {} s in {:.2} s ({} steps)",
            ours.particles, ours.simulated_time, ours.wall_seconds, ours.steps
        );
        let dfsph_bench = BenchArgs {
            scenario: args.dfsph_scenario.clone(),
            sets: args
                .dfsph_set
                .iter()
                .filter(|s| !s.is_empty())
                .cloned()
                .collect(),
            ..bench.clone()
        };
        let dfsph: Measurement = run_child(
            case,
            &dfsph_bench,
            &overrides,
            isa,
            &format!("peer-dfsph-{size}"),
        )?;
        eprintln!(
            "ours (DFSPH): {} particles to t = {} s in {:.2} s ({} steps)",
            dfsph.particles, dfsph.simulated_time, dfsph.wall_seconds, dfsph.steps
        );
        let fixed = run_salva(
            across,
            args.threads,
            args.end_time,
            SalvaStep::Fixed,
            args.salva_tolerance,
        )?;
        let theirs = run_salva(
            across,
            args.threads,
            args.end_time,
            SalvaStep::Cfl,
            args.salva_tolerance,
        )?;
        for (r, how) in [(&fixed, "fixed frames"), (&theirs, "CFL steps")] {
            eprintln!(
                "salva2d ({how}): {} particles to t = {} s in {:.2} s ({} substeps)",
                r.particles, args.end_time, r.wall, r.steps
            );
        }
        for (m, engine) in [(&ours, "ours (WCSPH, f64)"), (&dfsph, "ours (DFSPH, f64)")] {
            let (e, t_last, last) = front_error(&m.front, args.end_time, 0.0);
            let (d, _, dlast) = front_error(&m.front, args.end_time, GATE_DELAY);
            let ratio = theirs.wall / m.wall_seconds;
            let per_step =
                |k: &str| m.diagnostics.get(k).copied().unwrap_or(0.0) / m.steps.max(1) as f64;
            let iterations = match m.diagnostics.contains_key("density_solve_iterations") {
                true => format!(
                    "{:.1} + {:.1}",
                    per_step("density_solve_iterations"),
                    per_step("divergence_solve_iterations")
                ),
                false => "".into(),
            };
            let _ = writeln!(
                table,
                "| {} | {:.2} | {engine} | {} | {iterations} | {:.2} | {ratio:.2} | {:.1} % | {:+.1} % (T = {t_last:.2}) | {:.1} % | {:+.1} % |",
                m.particles,
                1e3 * ds,
                m.steps,
                m.wall_seconds,
                100.0 * e,
                100.0 * last,
                100.0 * d,
                100.0 * dlast
            );
        }
        for (r, how) in [
            (&theirs, "CFL 0.4 ds/v, as ours"),
            (&fixed, "fixed frames, 10x CFL at 7 m/s"),
        ] {
            let (e, _, last) = front_error(&r.front, args.end_time, 0.0);
            let (d, _, dlast) = front_error(&r.front, args.end_time, GATE_DELAY);
            let _ = writeln!(
                table,
                "| {} | {:.2} | salva2d 0.11 (DFSPH, f32; {how}) | {} | | {:.2} | | {:.1} % | {:+.1} % | {:.1} % | {:+.1} % |",
                r.particles,
                1e3 * ds,
                r.steps,
                r.wall,
                100.0 * e,
                100.0 * last,
                100.0 * d,
                100.0 * dlast
            );
        }
    }
    let md = format!(
        "# Peer comparison: salva2d\n\nMartin & Moyce column (a = {A} m, n^2 = 2) in the {} m x {} m tank, to t = {} s on {} thread(s). Front error: |Z/Z_data - 1| averaged over the data points with 1 <= T <= T(t_end) (a = 2.25 in series; T = t sqrt(2g/a)), without a start delay and with the simulation delayed by the gate's {GATE_DELAY} (T units; the delay tests/tests/dam_break.rs applies, after Lethe).\n\n{table}\nNot like for like: salva2d is DFSPH (incompressible, larger steps; 'steps' counts its substeps: one per frame, since salva2d 0.11's CFL substepping is disabled, TimestepManager::compute_substep; the wall ratio is against the row stepped by the same CFL rule as ours, dt = {CFL} ds / max|v| at most {MAX_DT} s, which is also salva2d's own disabled rule; the fixed-frame row is the bench's earlier set-up), f32 only, stopping its density solve at {:.1} % mean compression (its default 5 %; ours: 0.1 % in the scenario), with Akinci boundary particles and its own artificial viscosity (coefficient 0.03, not the same formula); ours is WCSPH in f64 with mirrored ghosts and density diffusion (scenarios/dam_break.ron), or DFSPH in f64 with mirrored ghosts and a Jacobi solve (scenarios/dam_break_dfsph.ron with {}), and its time includes probes and outputs at default rates.\n",
        TANK.0,
        TANK.1,
        args.end_time,
        args.threads,
        100.0 * args.salva_tolerance,
        match args.dfsph_set.iter().any(|s| !s.is_empty()) {
            true => format!("--set {}", args.dfsph_set.join(" --set ")),
            false => "no overrides".into(),
        }
    );
    let path = args.out.join("peer.md");
    if let Err(source) = std::fs::write(&path, &md) {
        return Err(PeerError::Write { path, source });
    }
    println!("{md}");
    Ok(())
}

fn main() -> ExitCode {
    let result = match Cli::parse().command {
        Cmd::Bench(args) => engine::bench::main(&args).map_err(PeerError::from),
        Cmd::Peer(args) => peer(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
