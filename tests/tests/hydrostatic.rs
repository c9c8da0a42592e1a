//! Still water (docs/scenes.md `hydrostatic`, docs/analytic.md section 1): after the start-up
//! transient the pressure below the surface layer matches rho_0 g (H - y), no particle
//! crosses a wall over 3 s, and the water stays still.

use sph_core::components::{Position, Pressure};
use sph_core::world::Particles;
use sph_tests::support::{assert_no_wall_reflections, load, nan_max, run_completed, series};

const SCENE: &str = include_str!("../../scenarios/hydrostatic.ron");

/// H/ds = 40 as docs/analytic.md asks; the tank is made 0.99 m wide so 66 whole
/// columns fill it. The shipped bottom and side sensors, and four on the side wall
/// 0.5, 1, 2 and 4 ds above the floor (the corner, issue 27).
const STILL_TANK: &[&str] = &[
    "resolution=Spacing(0.015)",
    "tank.width=0.99",
    "fluid_blocks=[(min: (0.0, 0.0), size: (0.99, 0.6))]",
    "pipeline.vtk_frames.interval=10.0",
    "pressure_sensors=[(name: \"bottom\", wall: \"bottom\", at: (0.495, 0.0)), \
     (name: \"side\", wall: \"left\", at: (0.0, 0.3)), \
     (name: \"c05\", wall: \"left\", at: (0.0, 0.0075)), \
     (name: \"c1\", wall: \"left\", at: (0.0, 0.015)), \
     (name: \"c2\", wall: \"left\", at: (0.0, 0.03)), \
     (name: \"c4\", wall: \"left\", at: (0.0, 0.06))]",
    "pipeline.probe.methods=[Shepard, Nearest, Averaged]",
    "pipeline.probe.plots=false",
    "pipeline.energy.plots=false",
];

/// Asserts that every sensor of [`STILL_TANK`], every method, reads within `bound`
/// (a fraction) of its own rho_0 g (H - y_s) at every sample after `after` seconds,
/// and prints the largest departure (`--nocapture`).
fn every_sensor_within(probes: &std::path::Path, after: f64, bound: f64) {
    let mut largest: f64 = 0.0;
    let (rho0, g, h): (f64, f64, f64) = (1000.0, 9.81, 0.6);
    for (sensor, y) in [
        ("bottom", 0.0),
        ("side", 0.3),
        ("c05", 0.0075),
        ("c1", 0.015),
        ("c2", 0.03),
        ("c4", 0.06),
    ] {
        let local = rho0 * g * (h - y);
        for method in ["shepard", "nearest", "averaged"] {
            let column = format!("{sensor}.{method}");
            let samples = series(probes, &column);
            assert!(samples.len() > 100, "{column}: {} samples", samples.len());
            let mut worst: f64 = 0.0;
            for (t, value) in samples {
                if t > after {
                    worst = nan_max(worst, (value - local).abs() / local);
                }
            }
            assert!(
                worst < bound,
                "{column}: {:.2} % from {local} Pa after {after} s",
                100.0 * worst
            );
            largest = nan_max(largest, worst);
        }
    }
    eprintln!(
        "{}: every sensor within {:.2} % after {after} s",
        probes.display(),
        100.0 * largest
    );
}

#[test]
fn hydrostatic_tank_holds_its_pressure_and_its_particles() {
    let scenario = load(SCENE, "scenarios/hydrostatic.ron", STILL_TANK);
    let (rho0, g, h): (f64, f64, f64) = (1000.0, 9.81, 0.6);
    let support = scenario.spec.kernel.support_factor() * scenario.h;
    let (summary, sim, out) = run_completed(scenario, "hydrostatic", 2);

    // No particle reached a wall: none was reflected (and none crossed, or the run
    // would have stopped).
    assert_no_wall_reflections(&summary);

    // Every particle below the surface layer (two kernel supports deep) within 2 % of
    // rho_0 g H of the hydrostatic pressure: docs/analytic.md's suggested tolerance for
    // H/ds >= 40. (The kernel's discrete gradient moment, 0.9992 for Wendland at the
    // shipped h/ds = 2.0, 0.997 at 1.5, biases the equilibrium by 0.1-0.3 %; acoustic
    // ringing adds ~1 %.)
    let particles = Particles::of(&sim.world).expect("fluid");
    let (x, p) = (
        particles.fluid::<Position>().unwrap(),
        particles.fluid::<Pressure>().unwrap(),
    );
    let scale = rho0 * g * h;
    let mut worst: f64 = 0.0;
    for (x, p) in x.iter().zip(p.iter()) {
        if x.0.y < h - 2.0 * support {
            // NaN-propagating: a NaN pressure fails the check below.
            worst = nan_max(worst, (p.0 - rho0 * g * (h - x.0.y)).abs() / scale);
        }
    }
    assert!(
        worst < 0.02,
        "worst particle pressure error {:.2} % of rho g H",
        100.0 * worst
    );

    // Every sensor after the first second (start-up transient), every method, within
    // 1 % of its own rho_0 g (H - y_s) at every sample: the acceptance of issues 27 and
    // 28 for the wall pressure of still water, also in the corner. Measured 0.46 % at
    // worst (mean +0.2-0.3 %: the kernel's gradient moment and the column's compression
    // under its weight); Method III at 0.5 ds read -1.1 % before its face was narrowed
    // to end at the floor.
    let probes = out.join("probes.csv");
    every_sensor_within(&probes, 1.0, 0.01);

    // energy.csv starts with the initial state at t = 0: water at rest (no kinetic
    // energy, nothing dissipated), potential M g H / 2 of the uniform column (to 1 %:
    // the initial densities follow the hydrostatic profile, the masses rho_0 ds^2 do not).
    let energy = out.join("energy.csv");
    let first = |name: &str| series(&energy, name)[0];
    let mass = rho0 * 0.99 * h;
    assert_eq!(first("kinetic"), (0.0, 0.0));
    assert_eq!(first("viscous"), (0.0, 0.0));
    let (t0, potential) = first("potential");
    assert_eq!(t0, 0.0);
    assert!(
        (potential / (mass * g * h / 2.0) - 1.0).abs() < 0.01,
        "initial potential energy {potential} J/m, M g H / 2 = {} J/m",
        mass * g * h / 2.0
    );

    // The water stays still: no speed above 1 % of sqrt(g H) (0.024 m/s) at any time.
    let bound = 0.01 * (g * h).sqrt();
    let fastest = series(&probes, "max_speed")
        .iter()
        .map(|s| s.1)
        .fold(0.0, nan_max);
    assert!(
        fastest < bound,
        "max speed {fastest} m/s exceeds {bound} m/s"
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// The still tank with `walls` in place of `GhostWalls(...)` and `before_eos`,
/// `after_eos` (stage lines, or empty) around `Eos()`, run to its end on two threads
/// with no particle reaching a wall; returns the probes file.
fn still_tank_with(
    tag: &str,
    walls: &str,
    before_eos: &str,
    after_eos: &str,
) -> std::path::PathBuf {
    let text = SCENE
        .replace("GhostWalls(slip: FreeSlip, hydrostatic: true),", walls)
        .replace(
            "        Eos(),\n",
            &format!("        {before_eos}\n        Eos(),\n        {after_eos}\n"),
        );
    assert!(text.contains(walls) && text.contains(before_eos) && text.contains(after_eos));
    let scenario = load(&text, "scenarios/hydrostatic.ron", STILL_TANK);
    let (summary, _sim, out) = run_completed(scenario, tag, 2);
    assert_no_wall_reflections(&summary);
    out.join("probes.csv")
}

const MIRRORS: &str = "GhostWalls(slip: FreeSlip, hydrostatic: true),";

/// The still tank on fixed wall particles with extrapolated pressure (`WallParticles()`
/// and `WallPressure()`, Adami et al. 2012) in place of mirrored ghosts: no particle
/// reaches a wall, and every sensor, in the corner too, reads its rho_0 g (H - y_s)
/// within 1 % at every sample after the start-up transient.
#[test]
fn a_still_tank_on_wall_particles_reads_hydrostatic_pressure_at_every_sensor() {
    let probes = still_tank_with(
        "hydrostatic_wall_particles",
        "WallParticles(),",
        "",
        "WallPressure(),",
    );
    // 1 %: the acceptance for still water (issue 27), as for the mirrored walls;
    // measured 0.59 % at worst (0.52-0.59 % at the corner sensors). The fluid's
    // starting lattice is in balance with the mirrors' push, not exactly with the wall
    // particles', and the acoustic ringing this sets off decays over about two seconds
    // (+1.1 % at the bottom at 1-1.5 s, +0.6 % at 2-2.5 s at H/ds 48), hence t > 2 s.
    every_sensor_within(&probes, 2.0, 0.01);
    let _ = std::fs::remove_dir_all(probes.parent().expect("the run's folder"));
}

/// The free-surface density summation every step (`Reinitialise(filter:
/// FreeSurface)`, on the shipped mirrored walls) keeps still water hydrostatic and
/// every particle inside: in a full kernel the sum is the compressed lattice's own
/// density, and at the surface the cut share is put back rather than averaged with the
/// denser water below (the Shepard filter's lift, docs/validation.md).
#[test]
fn a_still_tank_with_the_free_surface_summation_every_step_stays_hydrostatic() {
    let probes = still_tank_with(
        "hydrostatic_free_surface",
        MIRRORS,
        "Reinitialise(filter: FreeSurface),",
        "",
    );
    // 1 %: the still-water acceptance (issue 27); measured 0.44 % at worst, as on the
    // mirrors without the filter (0.46 %).
    every_sensor_within(&probes, 2.0, 0.01);
    let _ = std::fs::remove_dir_all(probes.parent().expect("the run's folder"));
}

/// The same on wall particles, with the one-sided wall pressure (`WallPressure(one_sided:
/// true)`, SPHinXsys's wall): every sensor within 1 % and no particle at a wall. With
/// Adami's two-sided extrapolation the wall particles above the surface read less than
/// the fluid beside them and, with a summed density that carries no compression to push
/// back, the two top-corner particles crept into the walls (1,050 reflections in 3 s).
#[test]
fn a_still_tank_on_one_sided_wall_particles_with_the_free_surface_summation_stays_hydrostatic() {
    let probes = still_tank_with(
        "hydrostatic_one_sided",
        "WallParticles(),",
        "Reinitialise(filter: FreeSurface),",
        "WallPressure(one_sided: true),",
    );
    // 1 %: the still-water acceptance (issue 27); measured 0.89 % at worst (the side
    // sensor, Method I; 0.46-0.66 % elsewhere).
    every_sensor_within(&probes, 2.0, 0.01);
    let _ = std::fs::remove_dir_all(probes.parent().expect("the run's folder"));
}
