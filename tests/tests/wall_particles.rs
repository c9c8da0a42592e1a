//! Fixed wall particles (`WallParticles`, `WallPressure`; docs/physics.md, "Walls: fixed
//! wall particles") in the dam break: with `separation: true` no particle gets through
//! a wall (the acceptance of issue 27 for the walls), where the same walls without it
//! book 32 reflections at this resolution (a spray particle pulled onto the wall
//! particles by its own tension).

use sph_tests::support::{assert_no_wall_reflections, load, run_completed};

const DAM: &str = include_str!("../../scenarios/dam_break.ron");

#[test]
fn a_dam_break_on_wall_particles_that_let_the_fluid_leave_books_no_reflection() {
    let text = DAM
        .replace(
            "GhostWalls(slip: FreeSlip, hydrostatic: true),",
            "WallParticles(),",
        )
        .replace(
            "        Eos(),\n",
            "        Eos(),\n        WallPressure(slip: WallVelocity, separation: true),\n",
        );
    assert!(text.contains("WallParticles()") && text.contains("separation: true"));
    // 1,800 particles, the whole 2 s: the impact at t = 0.62 s, the jet up the right
    // wall and the plunging wave's spray. Measured: 0 reflections (32 without
    // `separation`, 48 with the shipped mirrors at 5,000 particles).
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
    let (summary, _, out) = run_completed(scenario, "dam_wall_particles", 2);
    assert_no_wall_reflections(&summary);
    let _ = std::fs::remove_dir_all(&out);
}
