//! A run's results do not depend on the number of worker threads, and a run repeated
//! gives the same results: every shipped scenario (scenarios/*.ron), at a coarse
//! resolution and for a fraction of a second, run on one thread, on two, on two
//! again, on three and on four, ends with bit-identical particles (positions, velocities, densities by
//! particle id) and writes byte-identical probes.csv and energy.csv (and, for the DFSPH
//! scenarios, the solves' density_solve.csv and divergence_solve.csv). A scenario file
//! added to scenarios/ without an entry here fails `every_shipped_scenario_is_covered`.

use sph_core::components::{Density, ParticleId, Position, Velocity};
use sph_core::vocab::Neighbours;
use sph_core::world::Particles;
use sph_run::runner::{run_keeping_state, RunOptions};
use sph_tests::stability::quiet;
use sph_tests::support::{load, temp_out};
use std::path::{Path, PathBuf};

/// One test per shipped scenario: `name: "file.ron", [coarse overrides];`. Moving
/// tanks and pistons get a short ramp so that they move within the run.
macro_rules! shipped {
    ($($test:ident: $file:literal, [$($o:literal),* $(,)?];)*) => {
        /// The scenario files with an entry.
        const COVERED: &[&str] = &[$($file),*];
        $(
            #[test]
            fn $test() {
                let text = include_str!(concat!("../../scenarios/", $file));
                // The real path, so a piston or tank series beside the file is found.
                let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenarios/", $file);
                check_deterministic(text, path, &[$($o),*]);
            }
        )*
    };
}

shipped! {
    anti_roll_tank_is_deterministic: "anti_roll_tank.ron",
        ["resolution=Spacing(0.02)", "end_time=0.3", "tank.motion.ramp=0.1"];
    eagre_wavemaker_is_deterministic: "eagre_wavemaker.ron",
        ["resolution=Spacing(0.1)", "end_time=0.3", "tank.width=4.0", "fluid_blocks=[(min: (0.1, 0.0), size: (3.9, 1.0))]", "wave_gauges=[(name: \"G10\", x: 2.0)]", "pipeline.damping_zone.from=3.0", "pipeline.damping_zone.to=4.0"];
    dam_break_is_deterministic: "dam_break.ron",
        ["resolution=ParticlesAcross(40)", "end_time=0.3"];
    dam_break_paper_is_deterministic: "dam_break_paper.ron",
        ["resolution=ParticlesAcross(40)", "end_time=0.3"];
    dam_break_dfsph_is_deterministic: "dam_break_dfsph.ron",
        ["resolution=ParticlesAcross(40)", "end_time=0.6"];
    hydrostatic_dfsph_is_deterministic: "hydrostatic_dfsph.ron",
        ["resolution=Spacing(0.05)", "end_time=0.6"];
    hydrostatic_is_deterministic: "hydrostatic.ron",
        ["resolution=Spacing(0.05)", "end_time=0.3"];
    sloshing_dfsph_is_deterministic: "sloshing_dfsph.ron",
        ["resolution=ParticlesAcross(60)", "end_time=0.6", "tank.motion.ramp=0.1"];
    // Walls that do not slip: the ghosts' no-slip velocities (a resource carried
    // through the solves), on fixed and on rolling walls.
    dam_break_dfsph_no_slip_is_deterministic: "dam_break_dfsph.ron",
        ["resolution=ParticlesAcross(40)", "end_time=0.6", "pipeline.ghost_walls.slip=NoSlip"];
    sloshing_dfsph_no_slip_is_deterministic: "sloshing_dfsph.ron",
        ["resolution=ParticlesAcross(60)", "end_time=0.6", "tank.motion.ramp=0.1", "pipeline.ghost_walls.slip=NoSlip"];
    // Each pair once for both particles (the scalar path's default): the phases of
    // non-overlapping chunks add the shares in an order the thread count cannot change.
    dam_break_pairs_once_is_deterministic: "dam_break.ron",
        ["resolution=ParticlesAcross(40)", "end_time=0.3", "pipeline.forces.pairs=Once"];
    dam_break_paper_pairs_once_is_deterministic: "dam_break_paper.ron",
        ["resolution=ParticlesAcross(40)", "end_time=0.3", "pipeline.forces.pairs=Once"];
    sloshing_pairs_once_is_deterministic: "sloshing.ron",
        ["resolution=ParticlesAcross(60)", "end_time=0.4", "tank.motion.ramp=0.1", "pipeline.forces.pairs=Once"];
    dam_break_no_slip_is_deterministic: "dam_break.ron",
        ["resolution=ParticlesAcross(40)", "end_time=0.3", "pipeline.ghost_walls.slip=NoSlip"];
    // Fixed wall particles with the extrapolated pressure (its sums run on one thread
    // in fluid order) and the free-surface density summation, on fixed and rolling walls.
    dam_break_wall_particles_is_deterministic: "dam_break.ron",
        ["resolution=ParticlesAcross(40)", "end_time=0.3", "pipeline=[WallParticles(), NeighbourGrid(), Reinitialise(filter: FreeSurface), Eos(), WallPressure(slip: WallVelocity, separation: true), Forces(terms: [RiemannPressure(), Continuity(), RiemannDiffusion()]), Probe(interval: 0.005, methods: [Shepard, Nearest, Averaged]), Integrate(courant: 0.25), Energy(interval: 0.01), VtkFrames(), Snapshots(times: [])]"];
    sloshing_wall_particles_is_deterministic: "sloshing.ron",
        ["resolution=ParticlesAcross(60)", "end_time=0.4", "tank.motion.ramp=0.1", "pipeline=[WallParticles(), NeighbourGrid(), Reinitialise(filter: FreeSurface), Eos(), WallPressure(slip: NoSlip, one_sided: true), Forces(terms: [RiemannPressure(), Continuity(), RiemannDiffusion()]), Probe(interval: 0.002, methods: [Shepard, Nearest, Averaged], roll_moment: true), Integrate(courant: 0.25), Energy(interval: 0.01), VtkFrames(), Snapshots(times: [])]"];
    sloshing_is_deterministic: "sloshing.ron",
        ["resolution=ParticlesAcross(60)", "end_time=0.4", "tank.motion.ramp=0.1"];
    sloshing_paper_is_deterministic: "sloshing_paper.ron",
        ["resolution=ParticlesAcross(60)", "end_time=0.4", "tank.motion.ramp=0.1"];
    sloshing_high_is_deterministic: "sloshing_high.ron",
        ["resolution=ParticlesAcross(27)", "end_time=0.3", "tank.motion.ramp=0.1"];
    wave_breaking_is_deterministic: "wave_breaking.ron",
        ["resolution=Spacing(0.05)", "end_time=0.3", "piston.ramp=0.1"];
    wave_maker_is_deterministic: "wave_maker.ron",
        ["resolution=Spacing(0.05)", "end_time=0.3", "piston.ramp=0.1", "pipeline.energy.interval=0.01"];
}

#[test]
fn every_shipped_scenario_is_covered() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
    let mut missing = Vec::new();
    for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let name = entry.expect("directory entry").file_name();
        let name = name.to_string_lossy();
        if name.ends_with(".ron") && !COVERED.contains(&name.as_ref()) {
            missing.push(name.into_owned());
        }
    }
    assert!(
        missing.is_empty(),
        "scenarios without a determinism test in tests/tests/threads.rs: {missing:?}"
    );
}

/// The final fluid state by particle id, as bits.
type State = Vec<(u32, [u64; 5])>;

/// Runs on `threads` threads; returns the output folder and the final state.
fn run_on(text: &str, file: &str, coarse: &[&str], threads: usize) -> (PathBuf, State) {
    let mut overrides = coarse.to_vec();
    overrides.extend(quiet(text));
    let out = temp_out(&format!("threads{threads}"));
    let opts = RunOptions::quiet(&out, threads);
    let (summary, sim) = run_keeping_state(load(text, file, &overrides), &opts)
        .unwrap_or_else(|e| panic!("{file}, {threads} threads: {e}"));
    assert_eq!(summary.status, "completed");
    assert_eq!(summary.threads, threads);
    assert!(summary.steps > 100, "{file}: {} steps", summary.steps);
    // The dam break's neighbour lists outlive several steps (their skin), so the
    // comparison covers lists kept from step to step.
    if file.ends_with("/dam_break.ron") {
        let nb = sim.resources.get::<Neighbours>().expect("neighbour lists");
        assert!(
            nb.calls > 3 * nb.builds,
            "{file}: {} steps, {} list builds",
            nb.calls,
            nb.builds
        );
    }
    let p = Particles::of(&sim.world).expect("fluid particles");
    let (id, x, v, rho) = (
        p.fluid::<ParticleId>().expect("ids"),
        p.fluid::<Position>().expect("positions"),
        p.fluid::<Velocity>().expect("velocities"),
        p.fluid::<Density>().expect("densities"),
    );
    let mut state: State = (0..id.len())
        .map(|i| {
            let (x, v) = (x[i].0, v[i].0);
            let bits = [x.x, x.y, v.x, v.y, rho[i].0].map(f64::to_bits);
            (id[i].0, bits)
        })
        .collect();
    state.sort_unstable_by_key(|s| s.0);
    (out, state)
}

/// One thread, two threads, two threads again, three and four give identical results
/// (three and four oversubscribe a 2-core machine, which changes how rayon splits the
/// chunks between workers, not what each chunk sums).
fn check_deterministic(text: &str, file: &str, coarse: &[&str]) {
    let (one, s1) = run_on(text, file, coarse, 1);
    let (two, s2) = run_on(text, file, coarse, 2);
    let (again, s3) = run_on(text, file, coarse, 2);
    let (three, s4) = run_on(text, file, coarse, 3);
    let (four, s5) = run_on(text, file, coarse, 4);
    for (what, dir, state) in [
        ("2 threads", &two, &s2),
        ("a repeated run", &again, &s3),
        ("3 threads", &three, &s4),
        ("4 threads", &four, &s5),
    ] {
        if let Some(k) = (0..s1.len()).find(|&k| s1[k] != state[k]) {
            panic!(
                "{file}: particle {} ends differently on 1 thread and {what} (outputs in {} and {})",
                s1[k].0,
                one.display(),
                dir.display()
            );
        }
        assert_eq!(s1.len(), state.len(), "{file}: particle count, {what}");
        compare_outputs(file, &one, dir, what);
    }
    for dir in [one, two, again, three, four] {
        let _ = std::fs::remove_dir_all(dir);
    }
}

/// probes.csv, energy.csv and the DFSPH solves' iterations and errors (those the
/// scenario writes; at least one) are identical.
fn compare_outputs(file: &str, one: &Path, other: &Path, what: &str) {
    let mut compared = 0;
    for name in [
        "probes.csv",
        "energy.csv",
        "density_solve.csv",
        "divergence_solve.csv",
    ] {
        let (Ok(a), Ok(b)) = (
            std::fs::read_to_string(one.join(name)),
            std::fs::read_to_string(other.join(name)),
        ) else {
            continue;
        };
        assert!(a.lines().count() > 10, "{file}: {name} has rows:\n{a}");
        if a != b {
            let (n, (la, lb)) = a
                .lines()
                .zip(b.lines())
                .enumerate()
                .find(|(_, (la, lb))| la != lb)
                .unwrap_or((0, ("(length differs)", "")));
            panic!(
                "{file}: {name} differs between 1 thread and {what}, first at line {}:\n  1: {la}\n  2: {lb}",
                n + 1
            );
        }
        compared += 1;
    }
    assert!(
        compared > 0,
        "{file}: neither probes.csv nor energy.csv was written"
    );
}
