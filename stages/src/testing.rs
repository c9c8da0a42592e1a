//! Worlds for the stages' unit tests.
#![cfg_attr(feature = "dim3", allow(dead_code, unused_imports))]

use glam::DVec2;
use sph_core::components::{Density, Fluid, Ghost, Mass, Position, Pressure, Velocity, Wall};
use sph_core::dim::{self, Vector};
use sph_core::kernel::KernelKind;
use sph_core::sim::{Clock, Constants, Resources, Sim, Tait};
use sph_core::stage::Stage;

/// A sim over `world`: water (rho_0 1000 kg/m^3, c_0 20 m/s, Tait 7) under vertical
/// gravity, spacing 0.01 m, h 0.013 m (Wendland).
pub(crate) fn sim(world: hecs::World) -> Sim {
    Sim {
        world,
        clock: Clock::default(),
        constants: Constants {
            eos: Tait::new(1000.0, 20.0, 7.0),
            gravity: dim::xy(0.0, -9.81),
            spacing: 0.01,
            h: 0.013,
            kernel: KernelKind::Wendland,
            fluid_height: 0.1,
            domain: (Vector::splat(-1.0), Vector::splat(1.0)),
        },
        resources: Resources::default(),
        out_dir: std::env::temp_dir(),
        name: "unit".into(),
        diagnostics: Default::default(),
    }
}

/// The four walls of a closed `width` x `height` box from the origin, at rest,
/// counter-clockwise so that the fluid is inside.
#[cfg(not(feature = "dim3"))]
pub(crate) fn closed_box(world: &mut hecs::World, width: f64, height: f64) {
    let corners = [(0.0, 0.0), (width, 0.0), (width, height), (0.0, height)];
    closed_polygon(world, &corners, |_| Default::default());
}

/// The walls of a closed polygon through `corners` (counter-clockwise, so that the
/// fluid is inside), wall k from corner k to the next, at rest on the body `body(k)`.
#[cfg(not(feature = "dim3"))]
pub(crate) fn closed_polygon(
    world: &mut hecs::World,
    corners: &[(f64, f64)],
    body: impl Fn(usize) -> sph_core::motion::Pose,
) {
    for k in 0..corners.len() {
        let (a, b) = (corners[k], corners[(k + 1) % corners.len()]);
        let rest = Wall {
            name: format!("w{k}"),
            a: DVec2::new(a.0, a.1),
            b: DVec2::new(b.0, b.1),
            body: body(k),
        };
        let now = rest.at_rest();
        world.spawn((rest, now));
    }
}

/// The six walls of a closed `size` box from the origin, at rest, each with
/// (c - a) x (b - a) pointing inside: bottom, top, left, right, back (z = 0), front.
#[cfg(feature = "dim3")]
pub(crate) fn closed_box_3d(world: &mut hecs::World, size: Vector) {
    let (w, h, d) = (size.x, size.y, size.z);
    let v = Vector::new;
    let walls = [
        ("bottom", v(0.0, 0.0, 0.0), v(w, 0.0, 0.0), v(0.0, 0.0, d)),
        ("top", v(0.0, h, 0.0), v(0.0, h, d), v(w, h, 0.0)),
        ("left", v(0.0, h, 0.0), v(0.0, 0.0, 0.0), v(0.0, h, d)),
        ("right", v(w, 0.0, 0.0), v(w, h, 0.0), v(w, 0.0, d)),
        ("back", v(0.0, 0.0, 0.0), v(0.0, h, 0.0), v(w, 0.0, 0.0)),
        ("front", v(0.0, 0.0, d), v(w, 0.0, d), v(0.0, h, d)),
    ];
    for (name, a, b, c) in walls {
        let rest = Wall {
            name: name.into(),
            a,
            b,
            c,
            body: Default::default(),
        };
        let now = rest.at_rest();
        world.spawn((rest, now));
    }
}

/// The standard stage `name` with its RON parameters, built as a scenario would build
/// it (not set up), or the registry's refusal.
pub(crate) fn built(name: &str, params: &str) -> Result<Box<dyn Stage>, String> {
    let options = sph_core::registry::ron_options();
    let mut de = ron::Deserializer::from_str_with_options(params, &options).unwrap();
    let mut erased = <dyn erased_serde::Deserializer>::erase(&mut de);
    match crate::standard_registry().build(name, &mut erased) {
        Some(Ok(built)) => Ok(built.stage),
        Some(Err(e)) => Err(e.to_string()),
        None => Err(format!("no standard stage {name}")),
    }
}

/// [`built`], which must succeed.
pub(crate) fn stage(name: &str, params: &str) -> Box<dyn Stage> {
    built(name, params).unwrap_or_else(|e| panic!("{name}: {params} refused: {e}"))
}

/// The standard stages `(name, RON parameters)`, built as [`stage`] builds them and set
/// up on `sim` in order.
pub(crate) fn pipeline(sim: &mut Sim, stages: &[(&str, &str)]) -> Vec<Box<dyn Stage>> {
    let mut built: Vec<Box<dyn Stage>> = stages
        .iter()
        .map(|(name, params)| stage(name, params))
        .collect();
    for stage in &mut built {
        stage.setup(sim).unwrap();
    }
    built
}

/// A sim over `world` after the standard stages `stages` (as [`pipeline`] builds them)
/// have been set up and then run once, in order.
pub(crate) fn after_one_step(world: hecs::World, stages: &[(&str, &str)]) -> Sim {
    let mut sim = sim(world);
    let mut built = pipeline(&mut sim, stages);
    for stage in &mut built {
        stage.run(&mut sim).unwrap();
    }
    sim
}

/// Every particle of the world, fluid then ghosts: position, velocity, mass, density,
/// pressure (for the tests' brute-force sums over every particle).
pub(crate) fn everyone(sim: &Sim) -> Vec<(Vector, Vector, f64, f64, f64)> {
    use sph_core::world::{archetype, column};
    let mut all = Vec::new();
    for a in [
        archetype::<Fluid>(&sim.world),
        archetype::<Ghost>(&sim.world),
    ]
    .into_iter()
    .flatten()
    {
        let (x, v, m) = (
            column::<Position>(a).unwrap(),
            column::<Velocity>(a).unwrap(),
            column::<Mass>(a).unwrap(),
        );
        let (rho, p) = (
            column::<Density>(a).unwrap(),
            column::<Pressure>(a).unwrap(),
        );
        for k in 0..x.len() {
            all.push((x[k].0, v[k].0, m[k].0, rho[k].0, p[k].0));
        }
    }
    all
}

/// A fresh, empty output folder for the test `name` (in the system's temporary
/// folder, apart for each test process).
pub(crate) fn out_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("sph_unit_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The sites of an `nx` x `ny` block of particles at spacing 0.01 m from a box's
/// bottom left corner (the first at (0.005, 0.005)), with their column and row.
#[cfg(not(feature = "dim3"))]
pub(crate) fn lattice(nx: usize, ny: usize) -> impl Iterator<Item = (usize, usize, DVec2)> {
    (0..nx).flat_map(move |a| {
        (0..ny).map(move |b| {
            (
                a,
                b,
                DVec2::new(0.005 + 0.01 * a as f64, 0.005 + 0.01 * b as f64),
            )
        })
    })
}

/// The fluid's column `T`, each value read through `f` (e.g. `|p: &Position| p.0`).
pub(crate) fn fluid_column<T: hecs::Component, U>(sim: &Sim, f: impl Fn(&T) -> U) -> Vec<U> {
    let fluid = sph_core::world::archetype::<Fluid>(&sim.world).unwrap();
    sph_core::world::column::<T>(fluid)
        .unwrap()
        .iter()
        .map(f)
        .collect()
}

/// Each ghost's source (its fluid particle's index), in the ghosts' order; none
/// without ghosts.
pub(crate) fn ghost_sources(sim: &Sim) -> Vec<usize> {
    use sph_core::world::{archetype, column};
    archetype::<Ghost>(&sim.world)
        .map(|g| {
            column::<Ghost>(g)
                .unwrap()
                .iter()
                .map(|g| g.source as usize)
                .collect()
        })
        .unwrap_or_default()
}

/// D rho_i/Dt = sum_j m_j (v_i - v_j) . grad_i W_ij (the `Continuity` term) of particle
/// `i` of `all` ([`everyone`]), summed over every particle within the support of the
/// test sim's kernel (Wendland, h 0.013 m), not the neighbour lists.
pub(crate) fn continuity_by_hand(all: &[(Vector, Vector, f64, f64, f64)], i: usize) -> f64 {
    use sph_core::kernel::{Kernel, Wendland};
    let kernel = Wendland::new(0.013);
    let (xi, vi) = (all[i].0, all[i].1);
    let mut rate = 0.0;
    for (j, &(xj, vj, mj, _, _)) in all.iter().enumerate() {
        let d = xi - xj;
        if j != i && d.length() < kernel.support() {
            rate += mj * (vi - vj).dot(kernel.grad(d, d.length()));
        }
    }
    rate
}
