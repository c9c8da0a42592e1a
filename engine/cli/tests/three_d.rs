//! The 3D engine through the `engine` command, as a user runs it: a scenario with
//! `dimensions: 3` runs the 3D build (docs/architecture.md, "Two and three
//! dimensions"). Still water against hydrostatics, results for any thread count and
//! on resume, and SPHERIC Test 2 against its measurements (docs/validation.md, "3D").

use sph_study::series::read_series;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const ENGINE: &str = env!("CARGO_BIN_EXE_engine");

fn scenario(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenarios")
        .join(name)
        .display()
        .to_string()
}

fn temp(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("engine-3d-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn engine(args: &[&str]) -> Output {
    Command::new(ENGINE)
        .args(args)
        .output()
        .expect("the engine binary runs")
}

/// `engine args`, which must succeed.
fn run(args: &[&str]) -> String {
    let o = engine(args);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(o.status.success(), "engine {args:?} failed:\n{text}");
    text
}

/// Outputs off that the checks do not read.
const QUIET: [&str; 6] = [
    "--set",
    "pipeline.vtk_frames.interval=10.0",
    "--set",
    "pipeline.probe.plots=false",
    "--set",
    "pipeline.energy.plots=false",
];

/// Still water in the 3D box tank (scenarios/3d/hydrostatic.ron at H/ds = 10, 1,500
/// particles) for the full 3 s: the pressure below the surface layer within 1 % of
/// rho_0 g (H - y) at every sample of the last 0.1 s (the bound; measured
/// +0.20 % on the floor and +0.45 % at mid-depth), and the largest speed decaying
/// (1.5 mm/s at 0.5 s, 0.4 mm/s at 3 s: below a third of it over the last half
/// second).
#[test]
fn still_water_in_3d_holds_hydrostatic_pressure_for_three_seconds() {
    let out = temp("still");
    let o = out.display().to_string();
    let mut args = vec![
        scenario("3d/hydrostatic.ron"),
        "--out".into(),
        o.clone(),
        "-q".into(),
        "--set".into(),
        "resolution=Spacing(0.02)".into(),
    ];
    args.extend(QUIET.iter().map(|s| s.to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    run(&args);
    let probes = out.join("probes.csv");
    let (rho, g, depth) = (1000.0, 9.81, 0.2);
    for (column, y) in [("bottom.shepard", 0.0), ("side.shepard", 0.1)] {
        let p = read_series(&probes, column).unwrap();
        let expected = rho * g * (depth - y);
        let late: Vec<f64> = p.iter().filter(|s| s.0 >= 2.9).map(|s| s.1).collect();
        assert!(
            late.len() >= 10,
            "{column}: {} samples after 2.9 s",
            late.len()
        );
        for v in late {
            assert!(
                (v / expected - 1.0).abs() < 0.01,
                "{column}: {v:.1} Pa against rho g (H - y) = {expected:.1} Pa"
            );
        }
    }
    let speed = read_series(&probes, "max_speed").unwrap();
    let largest = |from: f64, to: f64| {
        speed
            .iter()
            .filter(|s| s.0 >= from && s.0 <= to)
            .map(|s| s.1)
            .fold(0.0, f64::max)
    };
    let (early, late) = (largest(0.4, 0.6), largest(2.5, 3.0));
    assert!(
        early > 0.0 && late < early / 3.0,
        "speeds do not decay: {early} m/s early, {late} m/s late"
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// The coarse SPHERIC Test 2 of `scene` (a file of scenarios/3d/) to `end` (ds =
/// 0.05 m, 5,280 particles) into `out`, with extra arguments.
fn coarse_test2(scene: &str, out: &Path, end: &str, extra: &[&str]) -> String {
    let o = out.display().to_string();
    let end = format!("end_time={end}");
    let scene = scenario(&format!("3d/{scene}"));
    let mut args = vec![
        scene.as_str(),
        "--out",
        &o,
        "-q",
        "--set",
        "resolution=Spacing(0.05)",
        "--set",
        &end,
        "--set",
        "pipeline.vtk_frames.interval=0.05",
    ];
    args.extend(QUIET[2..].iter());
    args.extend(extra);
    run(&args)
}

/// 3D results are bit-identical on one thread and on two, and a run stopped with a
/// checkpoint and resumed writes what the uninterrupted run writes (probes, energy,
/// the last ParaView frame): the weakly-compressible and the DFSPH Test 2.
#[test]
fn three_d_results_do_not_depend_on_threads_or_on_resuming() {
    for scene in TEST2 {
        let (one, two, part) = (temp("one"), temp("two"), temp("part"));
        coarse_test2(scene, &one, "0.12", &["--threads", "1"]);
        coarse_test2(scene, &two, "0.12", &["--threads", "2"]);
        coarse_test2(
            scene,
            &part,
            "0.12",
            &["--threads", "2", "--stop-at", "0.05"],
        );
        let p = part.display().to_string();
        run(&["resume", &p, "--threads", "1", "-q"]);
        for file in ["probes.csv", "energy.csv", "frames/frame_00002.vtp"] {
            let a = std::fs::read(one.join(file)).unwrap();
            assert!(a.len() > 1000, "{scene}: {file} is nearly empty");
            assert!(
                a == std::fs::read(two.join(file)).unwrap(),
                "{scene}: {file}: 1 and 2 threads differ"
            );
            assert!(
                a == std::fs::read(part.join(file)).unwrap(),
                "{scene}: {file}: the resumed run differs"
            );
        }
        for dir in [one, two, part] {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}

/// SPHERIC Test 2 with the weakly-compressible pipeline and with DFSPH.
const TEST2: [&str; 2] = ["dam_break_obstacle.ron", "dam_break_obstacle_dfsph.ron"];

/// A scene of the other dimension is refused by name: `dimensions: 3` on a 2D file
/// reaches the 3D build, which says which field does not fit it.
#[test]
fn a_scene_of_the_other_dimension_is_refused_with_the_field() {
    let o = engine(&[
        &scenario("dam_break.ron"),
        "--set",
        "dimensions=3",
        "--out",
        &temp("other").display().to_string(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("dam_break.ron:") && err.contains("field `"),
        "{err}"
    );
    let o = engine(&[
        &scenario("3d/hydrostatic.ron"),
        "--set",
        "dimensions=4",
        "--out",
        &temp("four").display().to_string(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("field `dimensions`") && err.contains("accepted: 2 or 3"),
        "{err}"
    );
}

/// SPHERIC Test 2 at the coarse resolution CI affords (ds = 0.05 m, 5,280 particles,
/// 2 s) against the measured record, through the run's own comparison
/// (`reference.md`, the scenario's `reference`), with both pipelines: the water
/// heights H2 (in front of the box) and H4 (in the reservoir) within the 10 %
/// normalised mean absolute error over 0-2 s (measured 5.5 % and 1.1 %
/// weakly-compressible on wall particles, 4.3 % and 1.3 % DFSPH on mirrors), and P1's
/// arrival (its first 1 kPa) within the 10 % (measured +8.1 % and +5.5 %: the
/// coarse front reaches the sensor late, +3.7 % at 0.025 m). On wall particles P1's
/// first peak (the largest 1 ms mean within 0.1 s of arrival) is within the 25
/// % here (measured -11.9 %; on mirrors +633 %), and the wall safeguard acts at most 50
/// times in 2 s (measured 2; 31,070 on mirrors). The peak does not hold at finer
/// resolution (+45 % at 0.025 m, +119 % at 0.02 m, +59 % at 0.015 m), so this holds the
/// coarse run, not the acceptance; DFSPH's peak is a one-step pulse, several times the
/// measured one at every resolution, and is not held (docs/validation.md, "3D", has
/// both per resolution).
#[test]
fn spheric_test2_coarse_heights_and_arrival_match_the_measurements() {
    for scene in TEST2 {
        let out = temp("test2");
        let text = coarse_test2(scene, &out, "2.0", &[]);
        assert!(text.contains("(reference.md)"), "{scene}: {text}");
        let md = std::fs::read_to_string(out.join("reference.md")).unwrap();
        // The table's rows: | probe | reference | NMAE | arrival | error | peak | error |
        let row = |probe: &str| -> Vec<String> {
            md.lines()
                .find(|l| l.starts_with(&format!("| {probe} |")))
                .unwrap_or_else(|| panic!("{scene}: no row for {probe} in\n{md}"))
                .split('|')
                .map(|c| c.trim().to_string())
                .collect()
        };
        let percent = |cell: &str| -> f64 {
            cell.trim_end_matches('%')
                .trim()
                .parse()
                .unwrap_or(f64::NAN)
        };
        for probe in ["H2", "H4"] {
            let nmae = percent(&row(probe)[3]);
            assert!(
                nmae <= 10.0,
                "{scene}: {probe}: NMAE {nmae} % over 0-2 s\n{md}"
            );
        }
        let arrival = percent(&row("P1.shepard.transducer")[5]);
        assert!(
            arrival.abs() <= 10.0,
            "{scene}: P1 arrives {arrival} % off\n{md}"
        );
        if scene == "dam_break_obstacle.ron" {
            let peak = percent(&row("P1.shepard.transducer")[7]);
            assert!(
                peak.abs() <= 25.0,
                "{scene}: P1's first peak {peak} % off\n{md}"
            );
            let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
            let json: serde_json::Value = serde_json::from_str(&summary).unwrap();
            // The diagnostics name only the guards that acted.
            let reflections = json["diagnostics"]["wall_reflections"]
                .as_f64()
                .unwrap_or(0.0);
            assert!(
                reflections <= 50.0,
                "{scene}: {reflections} wall reflections\n{summary}"
            );
        }
        let _ = std::fs::remove_dir_all(&out);
    }
}

/// Runs scenarios/3d/wave_maker.ron on 2 threads with the `--set` overrides `sets`
/// and the unread outputs off; returns its output folder.
fn run_flume(tag: &str, sets: &[&str]) -> PathBuf {
    let out = temp(tag);
    let o = out.display().to_string();
    let scene = scenario("3d/wave_maker.ron");
    let mut args = vec![scene.as_str(), "--out", &o, "-q", "--threads", "2"];
    for s in sets {
        args.extend(["--set", s]);
    }
    args.extend(QUIET);
    run(&args);
    out
}

/// The piston flume in 3D (scenarios/3d/wave_maker.ron: the 2D flume 0.12 m broad,
/// d/ds = 12.5, 3 particles across, free-slip side walls) against linear theory over
/// the last four periods, 6-12 s, with the 2D test's bounds (tests/tests/wave_maker.rs):
/// the first-harmonic height within 10 % of Biesel's at each gauge (first-order theory
/// is good to about 0.4 % at this steepness, so the bound measures the SPH) and the
/// phase lag between G1 and G3 (half a wavelength apart) giving k within 3 % of the
/// dispersion relation. Measured: +2.1 / +2.2 / -1.7 %, k from the gauge fit -0.4 %;
/// the 2D flume at the same ds +2.7 / +2.6 / -1.8 %, k +0.0 %. With nothing across
/// the flume to make it 3D, a paddle that did not push, or pushed the wrong way, would
/// make no wave or one of the wrong phase.
#[test]
fn a_3d_piston_makes_biesels_wave() {
    let out = run_flume("wave-maker", &[]);
    let (d, g, stroke, period) = (0.5, 9.81, 0.05, 1.5);
    let omega = 2.0 * std::f64::consts::PI / period;
    let k = sph_core::piston::wavenumber(omega, d, g);
    let biesel = stroke * sph_core::piston::biesel_height_over_stroke(k * d);
    let probes = out.join("probes.csv");
    let mut phases = Vec::new();
    for gauge in ["G1", "G2", "G3"] {
        let eta = read_series(&probes, gauge).unwrap();
        let (t, eta): (Vec<f64>, Vec<f64>) = eta.into_iter().unzip();
        let (a, phase) = sph_study::waves::harmonic(&t, &eta, omega, 6.0, 12.0).unwrap();
        assert!(
            (2.0 * a / biesel - 1.0).abs() < 0.10,
            "{gauge}: H = {:.4} m against Biesel {biesel:.4} m",
            2.0 * a
        );
        phases.push(phase);
    }
    let k_measured = sph_study::waves::wavenumber_from_phases(phases[0], phases[2], 1.415);
    assert!(
        (k_measured / k - 1.0).abs() < 0.03,
        "k = {k_measured:.4} 1/m against {k:.4} 1/m"
    );
    let _ = std::fs::remove_dir_all(out);
}

/// The 3D paddle at rest (stroke 0) feels the hydrostatic force of the water in front
/// of it over the flume's breadth, -rho_0 g d^2 B / 2 = -147.15 N, at the first sample:
/// `piston_force` integrates the Method I pressure over the paddle in cells of ds
/// (docs/scenario.md, `Probe`). The 2D test's bound and reason
/// (tests/tests/wave_maker.rs): the surface layer's cut Shepard sums and the 1 %
/// compression at c_0 = 20 m/s give errors of order ds/d of the top cell's share,
/// 1-2 % in all, more with h = 2 ds; 3 %. Measured at d/ds = 25 (ds 0.02 m, 6
/// particles across): +1.5 % (2D at d/ds 20: +2.4 %; both +7.8 % at d/ds 12.5). A
/// force summed along the paddle only, or over its cells without their breadth, is
/// off by the number of cells across or by 1/ds.
#[test]
fn a_3d_paddle_at_rest_feels_the_hydrostatic_force() {
    let out = run_flume(
        "paddle-rest",
        &[
            "piston.stroke=0.0",
            "end_time=0.01",
            "resolution=Spacing(0.02)",
        ],
    );
    let force = read_series(&out.join("probes.csv"), "piston_force").unwrap();
    let expected = -1000.0 * 9.81 * 0.5 * 0.5 / 2.0 * 0.12;
    let first = force[0].1;
    assert!(
        (first / expected - 1.0).abs() < 0.03,
        "force at rest {first:.2} N, expected {expected:.2} N"
    );
    let _ = std::fs::remove_dir_all(out);
}

/// A pitched tank at rest (scenarios/3d/pitching_tank.ron: the 2D tilted-tank test's
/// 0.5 m x 0.2 m section laid across z, 5 particles long in x, at its ds = 12.5 mm),
/// held at 6 degrees of pitch: the 2D test's claims and bounds
/// (tests/tests/sloshing.rs), averaged over the last natural period T1 (the pitch is
/// complete at 2.6 s = 3 T1; the mean over T1 removes the first mode's residue).
/// The surface stays level in the world: the gauges 0.46 m apart across the tank
/// differ by 0.46 tan 6 deg = 48 mm, within 5 % (a fifth of ds: the gauge reads the
/// top particle); every sensor by every method reads rho_0 g times its depth below
/// the level surface within 3 % (2 % of hydrostatics, as the 2D test, and 1 % of
/// residual sloshing). Measured: +1.0 %; sensors +0.2 to +0.3 %. A pose that did not
/// pitch leaves the surface square to the tank (rise 0), one pitched the other way
/// gives -48 mm, and Method III averaged over a wall's whole breadth read the bottom
/// 10 % low.
#[test]
fn a_pitched_3d_tank_at_rest_has_a_level_surface_and_hydrostatic_sensors() {
    let out = temp("pitched");
    let o = out.display().to_string();
    let scene = scenario("3d/pitching_tank.ron");
    let mut args = vec![scene.as_str(), "--out", &o, "-q", "--threads", "2"];
    // Pitch held at 6 deg: a harmonic of a 1,000 s period starting at its crest
    // (6 cos(2 pi t / 1000 s): within 0.03 % of 6 deg over the 4 s), brought in by
    // the ramp.
    for s in [
        "end_time=4.0",
        "tank.motion.pitch.amplitude=6.0",
        "tank.motion.pitch.period=1000.0",
        "tank.motion.pitch.phase=90.0",
        "tank.motion.ramp=2.6",
    ] {
        args.extend(["--set", s]);
    }
    args.extend(QUIET);
    let said = run(&args);
    let probes = out.join("probes.csv");
    let t1 = 2.0 * std::f64::consts::PI
        / sph_study::linear_sloshing::RectangularTank {
            breadth: 0.5,
            depth: 0.2,
            density: 1000.0,
            gravity: 9.81,
            viscosity: 0.0,
        }
        .natural_frequency(1);
    let avg = |column: &str| {
        let v: Vec<f64> = read_series(&probes, column)
            .unwrap()
            .into_iter()
            .filter(|s| s.0 >= 4.0 - t1 && s.0 <= 4.0)
            .map(|s| s.1)
            .collect();
        assert!(v.len() > 100, "{column}: {} samples", v.len());
        v.iter().sum::<f64>() / v.len() as f64
    };
    // At the first sample the water is still on its lattice at hydrostatic densities:
    // every reading within 1 % of rho_0 g (0.2 m - y) (measured within 0.01 %). Method
    // III carrying each pressure only to its own projection read the side sensors
    // +4 % here: the face's edges sit on lattice rows, and round-off took in one.
    for (sensor, y) in [("back", 0.05), ("bottom", 0.0), ("front", 0.05)] {
        for method in ["shepard", "nearest", "averaged"] {
            let column = format!("{sensor}.{method}");
            let first = read_series(&probes, &column).unwrap()[0].1;
            let exact = 1000.0 * 9.81 * (0.2 - y);
            assert!(
                (first / exact - 1.0).abs() < 0.01,
                "{column} at the start: {first:.1} Pa against {exact:.1} Pa"
            );
        }
    }
    let phi = 6f64.to_radians() * (2.0 * std::f64::consts::PI * 4.0 / 1000.0).cos();
    let rise = avg("eta_front") - avg("eta_back");
    let level_rise = 0.46 * 6f64.to_radians().tan();
    assert!(
        (rise / level_rise - 1.0).abs() < 0.05,
        "surface rise across the tank {rise:.4} m, a level surface needs {level_rise:.4} m"
    );
    // Heights in the world about the pivot (the bottom's middle, z = 0.25 m): a tank
    // point (y, z) is at c y - s (z - 0.25); the level surface through the middle of
    // the 0.2 m of water (volume kept) is at c 0.2.
    let (s, c) = phi.sin_cos();
    let level = c * 0.2;
    for (sensor, y, z) in [
        ("back", 0.05, 0.0),
        ("bottom", 0.0, 0.25),
        ("front", 0.05, 0.5),
    ] {
        let exact = 1000.0 * 9.81 * (level - (c * y - s * (z - 0.25)));
        for method in ["shepard", "nearest", "averaged"] {
            let p = avg(&format!("{sensor}.{method}"));
            assert!(
                (p / exact - 1.0).abs() < 0.03,
                "{sensor} by {method}: {p:.1} Pa against rho g depth = {exact:.1} Pa"
            );
        }
    }
    // The static pitch moment against the exact moment of the tilted liquid (the 2D
    // test's per metre, times the liquid's length: its n ds^3 over the section's
    // area), within the 2D test's 2 %: an integral of the weight's lever arm, so
    // what is left is the residual sloshing (and the hydrostatic start densities'
    // +0.25 % of mass). Measured +0.01 % (1.3119 N m against 1.3118).
    let n: f64 = said
        .split(" fluid particles")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .expect("the run says its particle count");
    let (l, h, ds) = (0.5, 0.2, 0.0125);
    let exact = sph_study::linear_sloshing::tilted_tank_moment(l, h, phi, 0.0, 1000.0, 9.81)
        * n
        * ds
        * ds
        * ds
        / (l * h);
    let moment = avg("pitch_moment");
    assert!(
        (moment / exact - 1.0).abs() < 0.02,
        "pitch moment {moment:.4} N m against the static {exact:.4} N m"
    );
    assert!((avg("pitch_angle") - 6.0).abs() < 0.01);
    let _ = std::fs::remove_dir_all(out);
}

/// Every 3D scenario, coarse and short (moving tanks with a 0.1 s ramp, so that they
/// move): probes and energy byte-identical on 1 thread and on 2. A file added to
/// scenarios/3d/ without an entry here fails.
#[test]
fn every_3d_scenario_gives_the_same_results_on_one_and_two_threads() {
    let cases: &[(&str, &[&str])] = &[
        (
            "dam_break_obstacle.ron",
            &["resolution=Spacing(0.06)", "end_time=0.1"],
        ),
        (
            "dam_break_obstacle_dfsph.ron",
            &["resolution=Spacing(0.06)", "end_time=0.1"],
        ),
        (
            "hydrostatic.ron",
            &["resolution=Spacing(0.025)", "end_time=0.1"],
        ),
        (
            "sloshing.ron",
            &[
                "resolution=ParticlesAcross(45)",
                "end_time=0.3",
                "tank.motion.ramp=0.1",
                "tank.motion.roll.period=0.4",
            ],
        ),
        (
            "dam_break_dualsphysics.ron",
            &["resolution=Spacing(0.03)", "end_time=0.05"],
        ),
        ("wave_maker.ron", &["end_time=0.3", "piston.ramp=0.1"]),
        (
            "pitching_tank.ron",
            &[
                "resolution=Spacing(0.025)",
                "end_time=0.3",
                "tank.motion.ramp=0.1",
                "tank.motion.pitch.period=0.4",
            ],
        ),
    ];
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/3d");
    for entry in std::fs::read_dir(&dir).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        assert!(
            !name.ends_with(".ron") || cases.iter().any(|c| c.0 == name),
            "scenarios/3d/{name} has no entry in this test"
        );
    }
    for (file, sets) in cases {
        let outs = [temp(&format!("t1-{file}")), temp(&format!("t2-{file}"))];
        for (out, threads) in outs.iter().zip(["1", "2"]) {
            let scene = scenario(&format!("3d/{file}"));
            let o = out.display().to_string();
            let mut args = vec![scene.as_str(), "--out", &o, "-q", "--threads", threads];
            for s in sets.iter() {
                args.extend(["--set", s]);
            }
            args.extend(QUIET.iter());
            run(&args);
        }
        for f in ["probes.csv", "energy.csv"] {
            let a = std::fs::read(outs[0].join(f)).unwrap();
            assert!(a.len() > 200, "{file}: {f} is nearly empty");
            assert!(
                a == std::fs::read(outs[1].join(f)).unwrap(),
                "{file}: {f} differs between 1 and 2 threads"
            );
        }
        for out in outs {
            let _ = std::fs::remove_dir_all(out);
        }
    }
}
