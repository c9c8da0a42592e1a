//! Fixed wall particles (`WallParticles`, `WallPressure`; docs/physics.md, "Walls: fixed
//! wall particles") in the dam break: with `separation: true` no particle gets through
//! a wall (the acceptance of issue 27 for the walls), where the same walls without it
//! book 32 reflections at this resolution (a spray particle pulled onto the wall
//! particles by its own tension). The same holds with the mirror's kinematics on the
//! wall particles (`mirror: true`) and the free-surface summation, where the one-sided
//! wall pressure and the summation alone book 337.

use sph_tests::support::{assert_no_wall_reflections, load, run_completed};

const DAM: &str = include_str!("../../scenarios/dam_break.ron");

/// The dam break on wall particles, with `Eos(),` replaced by `eos_and_walls`, at 1,800
/// particles over the whole 2 s (the impact at t = 0.62 s, the jet up the right wall and
/// the plunging wave's spray): it must finish without a single wall reflection.
fn dam_on_wall_particles_books_no_reflection(eos_and_walls: &str, tag: &str) {
    let text = DAM
        .replace(
            "GhostWalls(slip: FreeSlip, hydrostatic: true),",
            "WallParticles(),",
        )
        .replace("        Eos(),\n", eos_and_walls);
    assert!(text.contains("WallParticles()") && text.contains(eos_and_walls));
    let scenario = load(
        &text,
        "scenarios/dam_break.ron",
        &[
            "resolution=ParticlesAcross(60)",
            "pipeline.vtk_frames.interval=10.0",
            "pipeline.snapshots.times=[]",
            "pipeline.probe.plots=false",
            "pipeline.energy.plots=false",
        ],
    );
    let (summary, _, out) = run_completed(scenario, tag, 2);
    assert_no_wall_reflections(&summary);
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn a_dam_break_on_wall_particles_that_let_the_fluid_leave_books_no_reflection() {
    // Measured: 0 reflections (32 without `separation`, 48 with the shipped mirrors at
    // 5,000 particles).
    dam_on_wall_particles_books_no_reflection(
        "        Eos(),\n        WallPressure(slip: WallVelocity, separation: true),\n",
        "dam_wall_particles",
    );
}

#[test]
fn a_dam_break_on_wall_particles_that_mirror_the_fluid_books_no_reflection() {
    // Measured 2026-12-04: 0 reflections; without `mirror: true` (the wall particles at
    // the wall's own velocity in continuity) 337, 45 of them by t = 1 s, in the jet up
    // the right wall.
    dam_on_wall_particles_books_no_reflection(
        "        Reinitialise(filter: FreeSurface),\n        Eos(),\n        \
         WallPressure(slip: FreeSlip, one_sided: true, mirror: true),\n",
        "dam_wall_particles_mirror",
    );
}
