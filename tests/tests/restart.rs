//! Checkpoint and restart (issue 5): a run stopped with a checkpoint and resumed
//! writes byte-identical probes.csv and energy.csv to a run never stopped, with a
//! moving piston and a rolling tank; a damaged newest checkpoint or a leftover
//! temporary file falls back to the previous checkpoint; an unwritable output folder
//! and absurd sizes are refused before the run with a message naming the culprit.

use sph_core::checkpoint::{read_latest, CheckpointError, LATEST, PREVIOUS, TEMPORARY};
use sph_core::vocab::Neighbours;
use sph_run::runner::{run, run_keeping_state, RunOptions};
use sph_scenario::Scenario;
use sph_tests::support::{load, temp_out};
use std::path::{Path, PathBuf};

const WAVE: &str = include_str!("../../scenarios/wave_maker.ron");
const SLOSHING: &str = include_str!("../../scenarios/sloshing.ron");
const DAM: &str = include_str!("../../scenarios/dam_break.ron");
const DAM_BREAK_DFSPH: &str = include_str!("../../scenarios/dam_break_dfsph.ron");

/// A coarse wave maker: 630 particles, the piston moving from the start, particles
/// sorted every 7 steps (so a checkpoint falls between two sorts).
const WAVE_COARSE: [&str; 7] = [
    "resolution=Spacing(0.08)",
    "pipeline.neighbour_grid.sort_every=7",
    "end_time=0.6",
    "piston.ramp=0.0",
    "pipeline.vtk_frames.interval=0.25",
    "pipeline.probe.plots=false",
    "pipeline.energy.plots=false",
];

/// A coarse rolling tank: 160 particles, particle sorting every 20 steps, Shepard
/// every 20 steps.
const SLOSHING_COARSE: [&str; 6] = [
    "resolution=ParticlesAcross(40)",
    "end_time=0.5",
    "pipeline.vtk_frames.interval=0.2",
    "pipeline.probe.plots=false",
    "pipeline.energy.plots=false",
    "tank.motion.ramp=0.0",
];

/// A coarse dam break: 450 particles to 0.3 s.
const DAM_COARSE: [&str; 5] = [
    "resolution=ParticlesAcross(30)",
    "end_time=0.3",
    "pipeline.vtk_frames.interval=0.1",
    "pipeline.probe.plots=false",
    "pipeline.energy.plots=false",
];

/// The series and frame indexes a resumed run must write as the uninterrupted one.
const EVERY_OUTPUT: [&str; 4] = ["probes.csv", "energy.csv", "frames.pvd", "walls.pvd"];
/// A coarse DFSPH dam break: 800 particles sorted every 7 steps, to the first impact.
const DFSPH_COARSE: [&str; 6] = [
    "resolution=ParticlesAcross(40)",
    "pipeline.neighbour_grid.sort_every=7",
    "end_time=0.6",
    "pipeline.vtk_frames.interval=0.25",
    "pipeline.probe.plots=false",
    "pipeline.snapshots.times=[]",
];

fn dfsph() -> Scenario {
    load(
        DAM_BREAK_DFSPH,
        "scenarios/dam_break_dfsph.ron",
        &DFSPH_COARSE,
    )
}

fn wave() -> Scenario {
    load(WAVE, "scenarios/wave_maker.ron", &WAVE_COARSE)
}

fn sloshing() -> Scenario {
    load(SLOSHING, "scenarios/sloshing.ron", &SLOSHING_COARSE)
}

fn options(out: &Path, threads: usize) -> RunOptions {
    RunOptions::quiet(out, threads)
}

/// Runs to the end; returns the folder.
fn uninterrupted(scenario: Scenario, tag: &str) -> PathBuf {
    let out = temp_out(tag);
    let summary = run(scenario, &options(&out, 2)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(summary.status, "completed");
    out
}

/// Runs with checkpoints every `every` s and stops at `stop` s; returns the folder.
fn stopped(scenario: Scenario, tag: &str, every: Option<f64>, stop: f64) -> PathBuf {
    let out = temp_out(tag);
    let opts = RunOptions {
        checkpoint_every: every,
        stop_at: Some(stop),
        ..options(&out, 2)
    };
    let summary = run(scenario, &opts).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        summary.status.starts_with("paused (--stop-at) at step"),
        "{}",
        summary.status
    );
    assert!(out.join(LATEST).exists());
    out
}

/// Resumes the run in `out` from its newest usable checkpoint; returns the notes.
fn resume(scenario: Scenario, out: &Path, threads: usize) -> Vec<String> {
    let (checkpoint, notes) = read_latest(out).unwrap_or_else(|e| panic!("{e}"));
    let opts = RunOptions {
        resume: Some(checkpoint),
        ..options(out, threads)
    };
    let summary = run(scenario, &opts).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(summary.status, "completed");
    notes
}

/// The two runs' `files` are byte-identical; removes both folders.
fn same_files_then_clean(a: PathBuf, b: PathBuf, files: &[&str]) {
    for &f in files {
        let (x, y) = (std::fs::read(a.join(f)), std::fs::read(b.join(f)));
        let (x, y) = (x.unwrap(), y.unwrap_or_else(|e| panic!("{f}: {e}")));
        assert!(x.len() > 100, "{f} is nearly empty");
        assert!(x == y, "{f} differs between the two runs");
    }
    for dir in [a, b] {
        let _ = std::fs::remove_dir_all(dir);
    }
}

/// With walls that do not slip too: the ghosts' no-slip velocities are mirrored
/// afresh every step, so a resumed run needs nothing more in the checkpoint.
#[test]
fn a_resumed_no_slip_dfsph_run_is_bit_identical() {
    let no_slip = || {
        let mut overrides = DFSPH_COARSE.to_vec();
        overrides.push("pipeline.ghost_walls.slip=NoSlip");
        load(DAM_BREAK_DFSPH, "scenarios/dam_break_dfsph.ron", &overrides)
    };
    let full = uninterrupted(no_slip(), "restart-dfsph-no-slip-full");
    let part = stopped(no_slip(), "restart-dfsph-no-slip-part", Some(0.1), 0.35);
    resume(no_slip(), &part, 1);
    same_files_then_clean(full, part, &["probes.csv", "density_solve.csv"]);
}

/// The DFSPH pipeline keeps its warm start in the checkpointed pressures, and the
/// solves' reports continue: resumed, it writes what an uninterrupted run writes,
/// the solves' iterations and errors included.
#[test]
fn a_resumed_dfsph_run_is_bit_identical() {
    let full = uninterrupted(dfsph(), "restart-dfsph-full");
    let part = stopped(dfsph(), "restart-dfsph-part", Some(0.1), 0.35);
    resume(dfsph(), &part, 1);
    let files = [
        "probes.csv",
        "density_solve.csv",
        "divergence_solve.csv",
        "frames.pvd",
    ];
    same_files_then_clean(full, part, &files);
}

#[test]
fn a_resumed_piston_run_is_bit_identical() {
    let full = uninterrupted(wave(), "restart-wave-full");
    // 0.3 s is not a multiple of Reinitialise(every: 20) x 1 ms: the stop waits for one.
    let part = stopped(wave(), "restart-wave-part", None, 0.29);
    resume(wave(), &part, 1);
    same_files_then_clean(full, part, &EVERY_OUTPUT);
}

#[test]
fn a_resumed_rolling_tank_is_bit_identical_and_a_damaged_checkpoint_falls_back() {
    let full = uninterrupted(sloshing(), "restart-slosh-full");
    let part = stopped(sloshing(), "restart-slosh-part", Some(0.1), 0.25);
    let (newest, _) = read_latest(&part).unwrap();
    // Damage the newest checkpoint as a kill during its write might (truncated), and
    // leave a temporary file behind: the previous checkpoint must take over.
    let bytes = std::fs::read(part.join(LATEST)).unwrap();
    std::fs::write(part.join(LATEST), &bytes[..bytes.len() / 2]).unwrap();
    std::fs::write(part.join(TEMPORARY), b"half a checkpoint").unwrap();
    let (previous, notes) = read_latest(&part).unwrap();
    assert!(previous.time < newest.time, "fell back to an earlier one");
    let text = notes.join("\n");
    assert!(text.contains("interrupted"), "{text}");
    assert!(
        text.contains("falling back") && text.contains(PREVIOUS),
        "{text}"
    );
    assert!(!part.join(TEMPORARY).exists());
    // The moved damaged file no longer masks the previous one.
    let notes = resume(sloshing(), &part, 1);
    assert!(notes.is_empty(), "{notes:?}");
    same_files_then_clean(full, part, &EVERY_OUTPUT);
}

/// The shipped studies switch the Shepard filter off as `every: 10^9`. The filter keeps
/// nothing between its calls, so such a run still checkpoints and stops where asked
/// (it used to hold every checkpoint back to step 10^9), and it resumes bit for bit.
#[test]
fn a_run_with_the_filter_switched_off_still_checkpoints_and_resumes() {
    let off = || {
        let mut set = WAVE_COARSE.to_vec();
        set.push("pipeline.reinitialise.every=1000000000");
        load(WAVE, "scenarios/wave_maker.ron", &set)
    };
    let full = uninterrupted(off(), "restart-nofilter-full");
    let part = stopped(off(), "restart-nofilter-part", None, 0.25);
    let notes = resume(off(), &part, 1);
    assert!(notes.is_empty(), "{notes:?}");
    same_files_then_clean(full, part, &EVERY_OUTPUT);
}

#[test]
fn garbled_or_missing_checkpoints_are_reported() {
    let out = temp_out("restart-garbled");
    std::fs::create_dir_all(&out).unwrap();
    let err = read_latest(&out).unwrap_err();
    assert!(
        matches!(&err, CheckpointError::None { dir } if dir == &out),
        "{err}"
    );
    assert!(err.to_string().contains("no checkpoint in"), "{err}");
    std::fs::write(out.join(LATEST), b"SPHCKPT\0 garbage garbage garbage").unwrap();
    let err = read_latest(&out).unwrap_err();
    let CheckpointError::NoFallback(inner) = &err else {
        panic!("{err}");
    };
    assert!(
        matches!(&**inner, CheckpointError::File { path, message }
            if path == &out.join(LATEST) && message.contains("checksum")),
        "{err}"
    );
    assert!(err.to_string().contains("no previous checkpoint"), "{err}");
    let _ = std::fs::remove_dir_all(out);
}

#[test]
fn a_checkpoint_of_another_scenario_is_refused() {
    let part = stopped(wave(), "restart-other", None, 0.05);
    let (checkpoint, _) = read_latest(&part).unwrap();
    let other = load(
        WAVE,
        "scenarios/wave_maker.ron",
        &[&WAVE_COARSE[..], &["piston.stroke=0.1"]].concat(),
    );
    let opts = RunOptions {
        resume: Some(checkpoint),
        ..options(&part, 1)
    };
    let err = run(other, &opts).unwrap_err().to_string();
    assert!(err.contains("another scenario"), "{err}");
    let _ = std::fs::remove_dir_all(part);
}

#[test]
fn an_unwritable_output_folder_is_reported_before_the_run() {
    // A folder under a regular file cannot be created (even by root).
    let base = temp_out("restart-unwritable");
    std::fs::create_dir_all(&base).unwrap();
    let file = base.join("a_file");
    std::fs::write(&file, b"x").unwrap();
    let err = run(wave(), &options(&file.join("out"), 1))
        .unwrap_err()
        .to_string();
    assert!(err.contains("cannot create the output folder"), "{err}");
    assert!(err.contains("a_file"), "{err}");
    // A folder that exists but takes no files (even for root).
    if cfg!(target_os = "linux") {
        let err = run(wave(), &options(Path::new("/proc/self"), 1))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("not writable") && err.contains("/proc/self"),
            "{err}"
        );
    }
    let _ = std::fs::remove_dir_all(base);
}

#[test]
fn absurd_sizes_are_refused_before_allocation() {
    let registry = sph_stages::standard_registry();
    let try_run = |sets: &[&str]| -> String {
        let overrides: Vec<_> = WAVE_COARSE
            .iter()
            .chain(sets)
            .map(|o| o.parse().unwrap())
            .collect();
        let out = temp_out("restart-absurd");
        let result = Scenario::from_str(WAVE, "wave_maker.ron", &overrides, &registry)
            .map_err(|e| e.to_string())
            .and_then(|s| run(s, &options(&out, 1)).map_err(|e| e.to_string()));
        let _ = std::fs::remove_dir_all(out);
        result.expect_err("refused")
    };
    // Too many particles: the loader names `resolution`.
    let err = try_run(&["resolution=Spacing(0.0001)"]);
    assert!(
        err.contains("resolution") && err.contains("would not fit"),
        "{err}"
    );
    // A vast tank around a little water: too many grid cells.
    let err = try_run(&["tank.width=50000.0", "tank.height=50000.0"]);
    assert!(
        err.contains("neighbour_grid") && err.contains("grid cells"),
        "{err}"
    );
    // A sampling interval giving billions of rows, and of frames.
    let err = try_run(&["end_time=1000.0", "pipeline.probe.interval=1e-7"]);
    assert!(err.contains("probe") && err.contains("`interval`"), "{err}");
    let err = try_run(&["pipeline.vtk_frames.interval=1e-6"]);
    assert!(
        err.contains("vtk_frames") && err.contains("frames"),
        "{err}"
    );
}

/// A full disk, simulated with /dev/full (every write fails with ENOSPC): the error
/// names the file, the run does not panic, and earlier checkpoints are untouched.
/// Where /dev/full is missing that half is skipped, and says so on stderr; the other
/// half, a folder in the way of the file (the write fails with EISDIR), runs anywhere.
#[cfg(unix)]
#[test]
fn a_full_disk_is_reported_with_the_file_name() {
    let full = Path::new("/dev/full");
    if full.exists() {
        unwritable_outputs_are_reported_with_the_file_name(
            "full",
            |at| std::os::unix::fs::symlink(full, at).unwrap(),
            "No space left",
        );
    } else {
        eprintln!(
            "SKIPPED (in part): a_full_disk_is_reported_with_the_file_name found no /dev/full; \
             the full-disk (ENOSPC) case did not run, only the folder-in-the-way case"
        );
    }
    unwritable_outputs_are_reported_with_the_file_name(
        "folder",
        |at| std::fs::create_dir(at).unwrap(),
        "directory",
    );
}

/// Runs with energy.csv, then with the checkpoint's temporary file, made unwritable by
/// `block` (called with the file's path): each run stops with an error naming the file
/// and containing `reason`, and no checkpoint is left.
fn unwritable_outputs_are_reported_with_the_file_name(
    tag: &str,
    block: impl Fn(&Path),
    reason: &str,
) {
    // A CSV series: refused at setup.
    let out = temp_out(&format!("restart-{tag}-csv"));
    std::fs::create_dir_all(&out).unwrap();
    block(&out.join("energy.csv"));
    let err = run(wave(), &options(&out, 1)).unwrap_err().to_string();
    assert!(err.contains("energy.csv") && err.contains(reason), "{err}");
    let _ = std::fs::remove_dir_all(&out);

    // A checkpoint: the run stops with the file named.
    let out = temp_out(&format!("restart-{tag}-checkpoint"));
    std::fs::create_dir_all(&out).unwrap();
    block(&out.join(TEMPORARY));
    let opts = RunOptions {
        stop_at: Some(0.05),
        ..options(&out, 1)
    };
    let err = run(wave(), &opts).unwrap_err().to_string();
    assert!(err.contains(TEMPORARY) && err.contains(reason), "{err}");
    assert!(!out.join(LATEST).exists());
    let _ = std::fs::remove_dir_all(&out);
}

/// A dam break whose neighbour lists last several steps (the skin), stopped while a
/// list is in use and resumed: the resumed run rebuilds the same lists from the
/// checkpoint and keeps them as long, so its outputs are byte-identical.
#[test]
fn a_dam_break_resumed_in_the_middle_of_a_neighbour_list_is_bit_identical() {
    let dam = || load(DAM, "scenarios/dam_break.ron", &DAM_COARSE);
    let full = uninterrupted(dam(), "restart-dam-full");
    let part = temp_out("restart-dam-part");
    let opts = RunOptions {
        stop_at: Some(0.13),
        ..options(&part, 2)
    };
    let (summary, sim) = run_keeping_state(dam(), &opts).unwrap_or_else(|e| panic!("{e}"));
    assert!(summary.status.starts_with("paused"), "{}", summary.status);
    let nb = sim.resources.get::<Neighbours>().expect("neighbour lists");
    assert!(nb.skin > 0.0);
    assert!(
        nb.calls > 3 * nb.builds,
        "the lists should last several steps: {} steps, {} builds",
        nb.calls,
        nb.builds
    );
    assert!(
        nb.age > 0,
        "the stop should fall in the middle of a list's life"
    );
    drop(sim);
    resume(dam(), &part, 1);
    // A fixed tank writes no walls.pvd.
    same_files_then_clean(full, part, &EVERY_OUTPUT[..3]);
}

/// Every pair-term scheme resumes bit for bit (issue 28): the coarse dam break of the
/// test above with each density diffusion, Riemann-solver SPH (the shipped terms), the
/// laminar viscosity, particle shifting, and fixed wall particles with the free-surface
/// density summation every third step (so a stop falls between two), stopped at
/// 0.13 s and resumed on one thread, writes the probes and energy of the run never
/// stopped.
#[test]
fn every_scheme_resumes_bit_identical() {
    let schemes: [(&str, &[&str]); 7] = [
        ("riemann", &[]),
        (
            "fourtakas",
            &["pipeline.forces.terms=[PressureGradient(), ArtificialViscosity(), Continuity(), Fourtakas()]"],
        ),
        (
            "molteni-colagrossi",
            &["pipeline.forces.terms=[PressureGradient(), ArtificialViscosity(), Continuity(), MolteniColagrossi()]"],
        ),
        (
            "delta-sph",
            &["pipeline.forces.terms=[PressureGradient(), ArtificialViscosity(), Continuity(), DeltaSph()]"],
        ),
        (
            "laminar",
            &["pipeline.forces.terms=[PressureGradient(), ArtificialViscosity(), LaminarViscosity(nu: 1e-6), Continuity(), Fourtakas()]"],
        ),
        (
            "shifting",
            &["pipeline=[GhostWalls(slip: FreeSlip, hydrostatic: true), NeighbourGrid(), Eos(), \
               Forces(terms: [RiemannPressure(), Continuity(), RiemannDiffusion()]), \
               Probe(interval: 0.005, methods: [Shepard], plots: false), Integrate(courant: 0.25), \
               Shifting(), Energy(interval: 0.01, plots: false)]"],
        ),
        (
            "wall-particles",
            &["pipeline=[WallParticles(), NeighbourGrid(), Reinitialise(filter: FreeSurface, every: 3), Eos(), \
               WallPressure(slip: WallVelocity, separation: true, one_sided: true), \
               Forces(terms: [RiemannPressure(), Continuity(), RiemannDiffusion()]), \
               Probe(interval: 0.005, methods: [Shepard], plots: false), Integrate(courant: 0.25), \
               Energy(interval: 0.01, plots: false)]"],
        ),
    ];
    for (name, sets) in schemes {
        let dam = || {
            let mut overrides = DAM_COARSE.to_vec();
            overrides.extend_from_slice(sets);
            load(DAM, "scenarios/dam_break.ron", &overrides)
        };
        let full = uninterrupted(dam(), &format!("restart-{name}-full"));
        let part = stopped(dam(), &format!("restart-{name}-part"), None, 0.13);
        resume(dam(), &part, 1);
        same_files_then_clean(full, part, &["probes.csv", "energy.csv"]);
    }
}

/// DFSPH in a rolling tank (moving walls, the solves' warm start and the tank's
/// motion in the checkpoint) resumes bit for bit.
#[test]
fn a_resumed_dfsph_rolling_tank_is_bit_identical() {
    let tank = || {
        load(
            include_str!("../../scenarios/sloshing_dfsph.ron"),
            "scenarios/sloshing_dfsph.ron",
            &[
                "resolution=ParticlesAcross(40)",
                "end_time=0.5",
                "tank.motion.ramp=0.0",
                "pipeline.vtk_frames.interval=0.2",
                "pipeline.probe.plots=false",
                "pipeline.snapshots.times=[]",
            ],
        )
    };
    let full = uninterrupted(tank(), "restart-dfsph-tank-full");
    let part = stopped(tank(), "restart-dfsph-tank-part", Some(0.1), 0.25);
    resume(tank(), &part, 1);
    same_files_then_clean(full, part, &["probes.csv", "density_solve.csv"]);
}
