//! The optimised paths give the same physics as the straightforward ones: a dam break
//! whose particles are re-sorted by cell every step (`NeighbourGrid(sort_every: 1)`)
//! against one that keeps creation order (`sort_every: 0`); and the continuity
//! equation summed inside the forces loop (`Forces(terms: [..., Continuity()])`, as shipped)
//! against a separate `Continuity()` stage, which must agree bit for bit.
//!
//! Sorting changes only the order in which neighbour terms are summed, so the two runs
//! differ by round-off, which the flow then amplifies a little. Over 0.15 s (the
//! column's first collapse, several hundred steps) the probe series and every
//! particle's final state, matched by `ParticleId`, must agree to 1e-9 relative to
//! their scale (measured: 2e-15 m in position). A permutation applied to one column
//! but not another (leaving out the leapfrog's half-step velocity was tried) moves
//! particles by 0.1 m.

use sph_core::components::{Density, Fluid, ParticleId, Position, Velocity};
use sph_core::world::{archetype, column};
use sph_core::Sim;
use sph_tests::support::{load, nan_max, read_csv, run_completed};

const SCENE: &str = include_str!("../../scenarios/dam_break_paper.ron");

fn run(sort_every: u32) -> (Sim, std::path::PathBuf) {
    run_scene(SCENE, sort_every, &format!("sort{sort_every}"))
}

fn run_scene(scene: &str, sort_every: u32, tag: &str) -> (Sim, std::path::PathBuf) {
    let sort = format!("pipeline.neighbour_grid.sort_every={sort_every}");
    let overrides = [
        "resolution=ParticlesAcross(40)",
        "end_time=0.15",
        "pipeline.vtk_frames.interval=10.0",
        "pipeline.snapshots.times=[]",
        "pipeline.probe.plots=false",
        "pipeline.energy.plots=false",
        &sort,
    ];
    let (summary, sim, out) = run_completed(
        load(scene, "scenarios/dam_break_paper.ron", &overrides),
        tag,
        2,
    );
    assert!(summary.steps > 100, "{} steps", summary.steps);
    assert!(!summary.diagnostics.contains_key("cell_sort_skipped"));
    (sim, out)
}

/// (ParticleId, position, velocity, density) of every fluid particle, by id.
fn state_by_id(sim: &Sim) -> Vec<(u32, glam::DVec2, glam::DVec2, f64)> {
    let fluid = archetype::<Fluid>(&sim.world).expect("fluid");
    let (id, x) = (
        column::<ParticleId>(fluid).unwrap(),
        column::<Position>(fluid).unwrap(),
    );
    let (v, rho) = (
        column::<Velocity>(fluid).unwrap(),
        column::<Density>(fluid).unwrap(),
    );
    let mut out: Vec<_> = (0..id.len())
        .map(|i| (id[i].0, x[i].0, v[i].0, rho[i].0))
        .collect();
    out.sort_by_key(|s| s.0);
    out
}

#[test]
fn cell_sorting_changes_results_only_by_round_off() {
    let (plain, plain_out) = run(0);
    let (sorted, sorted_out) = run(1);

    // The sorted run really was reordered.
    let ids = column::<ParticleId>(archetype::<Fluid>(&sorted.world).unwrap())
        .unwrap()
        .iter()
        .map(|p| p.0)
        .collect::<Vec<_>>();
    assert!(
        ids.windows(2).any(|w| w[1] < w[0]),
        "sort_every: 1 left the particles in creation order"
    );

    let (a, b) = (state_by_id(&plain), state_by_id(&sorted));
    assert_eq!(a.len(), b.len());
    let (mut dx, mut dv, mut drho) = (0.0f64, 0.0f64, 0.0f64);
    for (p, q) in a.iter().zip(&b) {
        assert_eq!(p.0, q.0);
        // NaN-propagating: a NaN in either run fails the checks below.
        dx = nan_max(dx, (p.1 - q.1).length());
        dv = nan_max(dv, (p.2 - q.2).length());
        drho = nan_max(drho, (p.3 - q.3).abs());
    }
    // Scales: 1 m (tank), sqrt(2 g H) = 3.4 m/s, rho_0 = 1000 kg/m^3.
    assert!(dx < 1e-9, "positions differ by up to {dx:e} m");
    assert!(dv < 3.4e-9, "velocities differ by up to {dv:e} m/s");
    assert!(drho < 1e-6, "densities differ by up to {drho:e} kg/m^3");

    // Probe series: same rows and columns, values within 1e-9 of each column's scale.
    let (ha, ra) = read_csv(&plain_out.join("probes.csv"));
    let (hb, rb) = read_csv(&sorted_out.join("probes.csv"));
    assert_eq!(ha, hb);
    assert_eq!(ra.len(), rb.len());
    assert!(ra.len() > 20, "{} probe rows", ra.len());
    for (k, name) in ha.iter().enumerate() {
        let scale = ra
            .iter()
            .map(|r| r[k].abs())
            .filter(|v| v.is_finite())
            .fold(0.0, nan_max)
            .max(1e-12);
        for (row_a, row_b) in ra.iter().zip(&rb) {
            let (x, y) = (row_a[k], row_b[k]);
            if x.is_nan() && y.is_nan() {
                continue;
            }
            assert!(
                (x - y).abs() <= 1e-9 * scale,
                "probes.csv `{name}` at t = {}: {x} unsorted, {y} sorted",
                row_a[0]
            );
        }
    }
    for dir in [plain_out, sorted_out] {
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[test]
fn continuity_in_the_forces_loop_is_bit_identical_to_the_separate_stage() {
    // The Continuity() term inside Forces' term list (the line after the Forces line).
    let forces = SCENE.find("        Forces(").expect("a Forces stage");
    let term = forces
        + SCENE[forces..]
            .find("Continuity(),")
            .expect("a Continuity() term");
    let line_end = term + SCENE[term..].find('\n').unwrap() + 1;
    let line_start = SCENE[..term].rfind('\n').unwrap() + 1;
    let separate = format!(
        "{}        Continuity(),\n{}{}",
        &SCENE[..forces],
        &SCENE[forces..line_start],
        &SCENE[line_end..]
    );
    let (a, a_out) = run_scene(SCENE, 20, "fused");
    let (b, b_out) = run_scene(&separate, 20, "separate");
    // Same terms summed in the same order: every bit equal.
    let (sa, sb) = (state_by_id(&a), state_by_id(&b));
    assert!(sa.len() > 100);
    for (p, q) in sa.iter().zip(&sb) {
        assert_eq!(p, q, "particle state differs");
    }
    let read = |d: &std::path::Path| std::fs::read_to_string(d.join("probes.csv")).unwrap();
    assert_eq!(read(&a_out), read(&b_out), "probes.csv differs");
    for dir in [a_out, b_out] {
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[test]
fn continuity_written_twice_is_refused_at_load_in_either_order() {
    // A Continuity() stage beside the Continuity() term of Forces: two writers of the
    // density rate, refused by the declared contracts before anything runs, whether
    // Continuity comes before Forces or after it.
    let forces = SCENE.find("        Forces(").expect("a Forces stage");
    let probe = SCENE.find("        Probe(").expect("a Probe stage");
    for (at, second) in [(forces, "Forces"), (probe, "Continuity")] {
        let both = format!("{}        Continuity(),\n{}", &SCENE[..at], &SCENE[at..]);
        let registry = sph_stages::standard_registry();
        let err = sph_scenario::Scenario::from_str(&both, "both.ron", &[], &registry)
            .expect_err("both write the density rate");
        let shown = err.to_string();
        assert!(shown.contains("remove one of them"), "{shown}");
        assert!(
            shown.contains(&format!("{second} writes `DensityRate`")),
            "{shown}"
        );
    }
}
