//! The shipped wall-pressure extraction methods, Methods I, II and III
//! (docs/physics.md, "Wall-pressure extraction"), written against the same
//! [`ExtractionMethod`] trait and registry as a plugin's:
//! - Method I (`Shepard`): Shepard interpolation of fluid and ghost pressures at the
//!   sensor point.
//! - Method II (`Nearest`): the nearest fluid particle's pressure, corrected to the
//!   sensor's depth: P = p_n + rho_0 g . (x_s - x_n), so a deeper point reads more.
//! - Method III (`Averaged`, Oger et al. 2005): fluid particles within 1.5 h of the wall
//!   whose projection falls inside the sensor width S, projected onto the wall with the
//!   same hydrostatic correction, sorted along the wall abscissa q and averaged with
//!   weights dS_k = (q_{k+1} - q_{k-1})/2 (the sensor's edges close the ends). In 3D
//!   the face is the S x S square about the sensor, each sample is carried to the
//!   sensor's centre, and their plain mean is taken.
//!
//! A sensor with no fluid within the kernel support reads 0 (dry).

use sph_core::components::{Density, Mass, Position, Pressure};
use sph_core::dim::Vector;
use sph_core::extraction::{ExtractionMethod, Site};
use sph_core::kernel;
use sph_core::sim::Sim;
use sph_core::stage::StepError;
use sph_core::vocab::Neighbours;
use sph_core::world::Particles;
use sph_core::StageRegistry;

/// Registers Methods I, II and III.
pub(crate) fn register(registry: &mut StageRegistry) {
    registry.register_extraction::<Shepard>(
        "Shepard",
        "Method I: Shepard interpolation of fluid and ghost pressures at the sensor point",
    );
    registry.register_extraction::<Nearest>(
        "Nearest",
        "Method II: the nearest fluid particle, hydrostatically corrected",
    );
    registry.register_extraction::<Averaged>(
        "Averaged",
        "Method III: Oger's pseudo-sensor, the average over the sensor width",
    );
}

/// Method I.
#[derive(Default)]
pub struct Shepard;

impl ExtractionMethod for Shepard {
    fn needs_grid(&self) -> bool {
        true
    }
    fn pressure(&mut self, sim: &Sim, particles: Particles, site: &Site) -> Result<f64, StepError> {
        shepard(sim, particles, site.point())
    }
}

/// Shepard interpolation of fluid and ghost pressures at `at`:
/// p(at) = sum_j p_j W_j V_j / sum_j W_j V_j, V_j = m_j / rho_j; 0 without neighbours.
pub(crate) fn shepard(sim: &Sim, particles: Particles, at: Vector) -> Result<f64, StepError> {
    let Some(nb) = sim.resources.get::<Neighbours>() else {
        return Ok(0.0);
    };
    let (x, p) = (
        particles.joined::<Position>()?,
        particles.joined::<Pressure>()?,
    );
    let (rho, m) = (particles.joined::<Density>()?, particles.joined::<Mass>()?);
    let (x, p, rho, m) = (x.view(), p.view(), rho.view(), m.view());
    let c = &sim.constants;
    let (mut num, mut den) = (0.0, 0.0);
    nb.grid.for_each_near(at, |j| {
        let w = kernel::w(c.kernel, c.h, (at - x.get(j).0).length());
        let vol = m.get(j).0 / rho.get(j).0;
        num += p.get(j).0 * w * vol;
        den += w * vol;
    });
    Ok(if den > 0.0 { num / den } else { 0.0 })
}

/// The neighbour grid when it indexes exactly these fluid particles (it is built
/// after the positions of the step a probe reads), for point queries instead of a scan
/// of every particle (two sensors, read every step for their time filters, scanned
/// 21 ns per particle-step at 80k).
fn grid_of(sim: &Sim, n_fluid: usize) -> Option<&Neighbours> {
    sim.resources
        .get::<Neighbours>()
        .filter(|nb| nb.n_fluid == n_fluid && !nb.grid.start.is_empty())
}

/// Method II: the nearest fluid particle within the kernel support (the lowest index
/// among equally near ones).
#[derive(Default)]
pub struct Nearest;

impl ExtractionMethod for Nearest {
    fn pressure(&mut self, sim: &Sim, particles: Particles, site: &Site) -> Result<f64, StepError> {
        let (x, p) = (
            particles.fluid::<Position>()?,
            particles.fluid::<Pressure>()?,
        );
        let at = site.point();
        let support2 = sim.constants.support().powi(2);
        let mut best: Option<(f64, usize)> = None;
        let mut consider = |i: usize| {
            let d2 = (x[i].0 - at).length_squared();
            if d2 < support2 && best.is_none_or(|b| (d2, i) < b) {
                best = Some((d2, i));
            }
        };
        match grid_of(sim, x.len()) {
            // Every particle within the support of `at` is in the cells around it.
            Some(nb) => nb.grid.for_each_near(at, |j| {
                if (j as usize) < x.len() {
                    consider(j as usize)
                }
            }),
            None => (0..x.len()).for_each(consider),
        }
        Ok(best.map_or(0.0, |(_, i)| site.carry.carry(p[i].0, x[i].0, at)))
    }
}

/// Method III: Oger's pseudo-sensor. Keeps its candidate and sample buffers from
/// reading to reading.
#[derive(Default)]
pub struct Averaged {
    candidates: Vec<u32>,
    samples: Vec<(f64, f64)>,
}

impl ExtractionMethod for Averaged {
    fn pressure(&mut self, sim: &Sim, particles: Particles, site: &Site) -> Result<f64, StepError> {
        let (x, p) = (
            particles.fluid::<Position>()?,
            particles.fluid::<Pressure>()?,
        );
        let (wall, carry) = (site.wall, site.carry);
        let reach = 1.5 * sim.constants.h;
        let centre = site.along;
        // A face cannot reach past the wall's ends: near a corner it is narrowed about
        // its centre to fit (else the fluid-less part past the corner moves the face's
        // mean pressure off the sensor's height: -1.1 % at 0.5 ds above a still floor).
        let face = |centre: f64, length: f64| {
            let fit = (0.5 * site.width).min(centre).min(length - centre);
            let half = if fit > 0.0 { fit } else { 0.5 * site.width };
            (centre - half, centre + half)
        };
        let (lo, hi) = face(centre, wall.length());
        // In 3D the face is the S x S square about the sensor: S across the wall too
        // (else the whole breadth of the wall is averaged), narrowed the same way.
        #[cfg(feature = "dim3")]
        let across = face(site.across, wall.breadth());
        let inside = |q: Vector| {
            #[cfg(feature = "dim3")]
            if !(across.0..=across.1).contains(&wall.abscissa_across(q)) {
                return false;
            }
            (lo..=hi).contains(&wall.abscissa(q))
        };
        let sample = |i: usize| {
            let q = x[i].0;
            let (d, a) = (wall.distance(q), wall.abscissa(q));
            ((0.0..reach).contains(&d) && inside(q)).then(|| {
                // In 3D each is carried on to the sensor's centre: the plain mean then
                // reads the hydrostatic pressure there whichever rows the face's
                // edges take in (a lattice's rows can sit on them).
                #[cfg(not(feature = "dim3"))]
                let to = q - d * wall.normal();
                #[cfg(feature = "dim3")]
                let to = site.point();
                (a, carry.carry(p[i].0, q, to))
            })
        };
        let Self {
            samples,
            candidates,
        } = self;
        samples.clear();
        match grid_of(sim, x.len()) {
            // The cells around points every h/2 along the face hold every particle
            // within 1.5 h of it (a cell is at least a support wide); taken in index
            // order, as the scan of all particles takes them, so the stable sort below
            // gives the same list.
            Some(nb) => {
                candidates.clear();
                let step = 0.5 * sim.constants.h;
                let steps = |lo: f64, hi: f64| ((hi - lo) / step).ceil().clamp(1.0, 1e4) as usize;
                let points = steps(lo, hi);
                // In 3D the points cover the square face, row by row across it.
                #[cfg(not(feature = "dim3"))]
                let rows = [Vector::ZERO];
                #[cfg(feature = "dim3")]
                let rows = {
                    let (c0, c1) = across;
                    let n = steps(c0, c1);
                    (0..=n).map(move |m| {
                        (c0 + (c1 - c0) * m as f64 / n as f64) * wall.tangent_across()
                    })
                };
                for row in rows {
                    for k in 0..=points {
                        let at = wall.point(lo + (hi - lo) * k as f64 / points as f64) + row;
                        nb.grid.for_each_near(at, |j| {
                            if (j as usize) < x.len() {
                                candidates.push(j)
                            }
                        });
                    }
                }
                candidates.sort_unstable();
                candidates.dedup();
                samples.extend(candidates.iter().filter_map(|&i| sample(i as usize)));
            }
            None => samples.extend((0..x.len()).filter_map(sample)),
        }
        let samples = &mut samples[..];
        if samples.is_empty() {
            return Ok(0.0);
        }
        Ok(face_mean(samples, lo, hi))
    }
}

/// The mean of the samples' pressures.
fn mean(samples: &[(f64, f64)]) -> f64 {
    samples.iter().map(|s| s.1).sum::<f64>() / samples.len() as f64
}

/// The face's mean pressure in 3D: Oger's weights along one edge do not measure a
/// face's area (particles of one column across the face tie in q and all but two get
/// none), while the lattice gives each particle about the same share of the face: the
/// plain mean. The abscissae go unused.
#[cfg(feature = "dim3")]
fn face_mean(samples: &mut [(f64, f64)], _lo: f64, _hi: f64) -> f64 {
    mean(samples)
}

/// The face's mean pressure in 2D: Oger's weighted mean of the samples (abscissa,
/// pressure) over the face [lo, hi], sorted along it, each weighted by half the gap
/// between its neighbours.
#[cfg(not(feature = "dim3"))]
fn face_mean(samples: &mut [(f64, f64)], lo: f64, hi: f64) -> f64 {
    samples.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let q = |k: isize| -> f64 {
        if k < 0 {
            lo
        } else if k as usize >= samples.len() {
            hi
        } else {
            samples[k as usize].0
        }
    };
    let (mut num, mut den) = (0.0, 0.0);
    for (k, &(_, pk)) in samples.iter().enumerate() {
        let k = k as isize;
        let ds = 0.5 * (q(k + 1) - q(k - 1));
        num += pk * ds;
        den += ds;
    }
    if den > 0.0 {
        num / den
    } else {
        mean(samples)
    }
}

// 2D set-ups; the 3D build's own tests are in `tests3d` modules.
#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use crate::outputs::probe::tests::{all, scene, shepard_sum, wall, N_FLUID};
    use glam::DVec2;
    use sph_core::components::{Fluid, Velocity, WallPose};
    use sph_core::extraction::Carry;

    /// The effective gravity of the carry: an accelerating frame's, not straight down.
    const G_EFF: DVec2 = DVec2::new(0.3, -9.81);

    fn site(wall: &WallPose, along: f64, width: f64) -> Site<'_> {
        Site {
            wall,
            along,
            width,
            carry: Carry {
                rho0: 1000.0,
                g: G_EFF,
            },
        }
    }

    fn read(method: &mut dyn ExtractionMethod, sim: &Sim, site: &Site) -> f64 {
        let particles = Particles::of(&sim.world).unwrap();
        method.pressure(sim, particles, site).unwrap()
    }

    /// Method I is sum_j p_j W_j V_j / sum_j W_j V_j over the fluid and the ghosts
    /// (`shepard_sum`, over every particle); 0 where nothing is within the support,
    /// and without the grid. Bound: round-off.
    #[test]
    fn shepard_interpolates_fluid_and_ghost_pressures() {
        let mut sim = scene();
        let floor = wall(&sim, 0);
        let left = wall(&sim, 3);
        for (wall, along) in [
            (&floor, 0.005),
            (&floor, 0.0625),
            (&floor, 0.118),
            (&left, 0.17),
        ] {
            let e = shepard_sum(&sim, wall.point(along));
            let got = read(&mut Shepard, &sim, &site(wall, along, 0.0));
            assert!((got - e).abs() < 1e-9, "{along}: {got} against {e}");
        }
        // The left wall's top is dry.
        assert_eq!(read(&mut Shepard, &sim, &site(&left, 0.01, 0.0)), 0.0);
        assert!(Shepard.needs_grid());
        sim.resources.take::<Neighbours>();
        assert_eq!(read(&mut Shepard, &sim, &site(&floor, 0.0625, 0.0)), 0.0);
    }

    /// Method II takes the nearest fluid particle within the support (ghosts do not
    /// count), its pressure carried to the sensor, p_n + rho_0 g_eff . (x_s - x_n);
    /// with the grid and by a scan of every particle alike; 0 when dry.
    #[test]
    fn nearest_takes_the_nearest_fluid_particle_carried_to_the_sensor() {
        let mut sim = scene();
        let (floor, left) = (wall(&sim, 0), wall(&sim, 3));
        let fluid: Vec<_> = all(&sim).into_iter().take(N_FLUID).collect();
        let cases = [
            (&floor, 0.0625),
            (&floor, 0.1149),
            (&left, 0.171),
            (&left, 0.01),
        ];
        let expected: Vec<f64> = cases
            .iter()
            .map(|(wall, along)| {
                let at = wall.point(*along);
                let near = (0..fluid.len())
                    .map(|i| ((fluid[i].0 - at).length_squared(), i))
                    .filter(|(d2, _)| *d2 < 0.026 * 0.026)
                    .min_by(|a, b| a.partial_cmp(b).unwrap());
                near.map_or(0.0, |(_, i)| {
                    fluid[i].1 + 1000.0 * G_EFF.dot(at - fluid[i].0)
                })
            })
            .collect();
        assert_eq!(expected[3], 0.0, "the left wall's top is dry");
        for grid in [true, false] {
            if !grid {
                sim.resources.take::<Neighbours>();
            }
            for ((wall, along), e) in cases.iter().zip(&expected) {
                let got = read(&mut Nearest, &sim, &site(wall, *along, 0.0));
                assert!(
                    (got - e).abs() < 1e-9,
                    "grid {grid}, {along}: {got} against {e}"
                );
            }
        }
        assert!(!Nearest.needs_grid());
    }

    /// Of two fluid particles equally near the sensor, the lower index is read, with
    /// the grid and without.
    #[test]
    fn nearest_breaks_ties_by_index() {
        for first in [100.0, 200.0] {
            let mut world = hecs::World::new();
            crate::testing::closed_box(&mut world, 0.5, 0.5);
            // Both 0.0125 from the floor's point at 0.25 (exact in binary).
            for (x, p) in [(0.2375, first), (0.2625, 300.0 - first)] {
                world.spawn((
                    Fluid,
                    Position(DVec2::new(x, 0.0)),
                    Velocity(DVec2::ZERO),
                    Density(1000.0),
                    Pressure(p),
                    Mass(0.1),
                ));
            }
            let mut sim = crate::testing::sim(world);
            let stages = [("neighbour_grid", "(sort_every: 0, skin: 0.0)")];
            for mut stage in crate::testing::pipeline(&mut sim, &stages) {
                stage.run(&mut sim).unwrap();
            }
            let floor = wall(&sim, 0);
            let at = floor.point(0.25);
            let e = first + 1000.0 * G_EFF.dot(at - DVec2::new(0.2375, 0.0));
            for grid in [true, false] {
                if !grid {
                    sim.resources.take::<Neighbours>();
                }
                let got = read(&mut Nearest, &sim, &site(&floor, 0.25, 0.0));
                assert!((got - e).abs() < 1e-9, "grid {grid}: {got} against {e}");
            }
        }
    }

    /// Method III from its formula: the fluid particles within 1.5 h of the wall whose
    /// abscissa a lies on the face [lo, hi] (the face narrowed about its centre to fit
    /// on the wall), carried to their foot on the wall, sorted by a, weighted by
    /// (a_{k+1} - a_{k-1})/2 with lo and hi closing the ends; with a face of no width,
    /// the plain mean of the particles on its abscissa.
    fn oger(sim: &Sim, wall: &WallPose, along: f64, width: f64) -> f64 {
        let fit = (0.5 * width).min(along).min(wall.length() - along);
        let half = if fit > 0.0 { fit } else { 0.5 * width };
        let (lo, hi) = (along - half, along + half);
        let mut samples: Vec<(f64, f64)> = all(sim)
            .into_iter()
            .take(sph_core::world::count::<sph_core::components::Fluid>(
                &sim.world,
            ))
            .filter_map(|(x, p, _, _)| {
                let (d, a) = (wall.distance(x), wall.abscissa(x));
                ((0.0..1.5 * 0.013).contains(&d) && a >= lo && a <= hi)
                    .then(|| (a, p + 1000.0 * G_EFF.dot(-d * wall.normal())))
            })
            .collect();
        if samples.is_empty() {
            return 0.0;
        }
        samples.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let n = samples.len();
        let q = |k: usize| samples[k].0;
        let (mut num, mut den) = (0.0, 0.0);
        for (k, &(_, p)) in samples.iter().enumerate() {
            let before = if k == 0 { lo } else { q(k - 1) };
            let after = if k + 1 == n { hi } else { q(k + 1) };
            num += p * 0.5 * (after - before);
            den += 0.5 * (after - before);
        }
        if den > 0.0 {
            num / den
        } else {
            samples.iter().map(|s| s.1).sum::<f64>() / n as f64
        }
    }

    /// Method III against [`oger`], with the grid and by a scan alike: mid-floor, a
    /// face narrowed at the floor's start and at the left wall's end (both by the
    /// corner), the left wall, a face of no width on a column of particles, the dry
    /// top, and a face centred on the floor's end.
    #[test]
    fn averaged_is_oger_s_weighted_mean_over_the_face() {
        let mut sim = scene();
        let (floor, left, top) = (wall(&sim, 0), wall(&sim, 3), wall(&sim, 2));
        // A particle's own abscissa, for the face of no width.
        let column_x = all(&sim)[8 * 5].0.x;
        let cases = [
            (&floor, 0.0625, 0.03),
            (&floor, 0.005, 0.03),
            (&left, 0.196, 0.03),
            (&left, 0.17, 0.02),
            (&floor, column_x, 0.0),
            (&top, 0.15, 0.03),
            // At the wall's very end there is nothing to narrow about: the whole face.
            (&floor, 0.0, 0.03),
            // A face four supports wide (narrowed by the corner to 0.0125-0.1125 m):
            // the grid's candidates must come from all along it.
            (&floor, 0.0625, 0.1),
        ];
        let expected: Vec<f64> = cases
            .iter()
            .map(|(w, a, s)| oger(&sim, w, *a, *s))
            .collect();
        assert_eq!(expected[5], 0.0, "the top is dry");
        for grid in [true, false] {
            if !grid {
                sim.resources.take::<Neighbours>();
            }
            let mut method = Averaged::default();
            for ((wall, along, width), e) in cases.iter().zip(&expected) {
                let got = read(&mut method, &sim, &site(wall, *along, *width));
                assert!(
                    (got - e).abs() < 1e-9,
                    "grid {grid}, {along} {width}: {got} against {e}"
                );
            }
        }
    }

    /// The grid serves only when it indexes the fluid as it is: with a particle added
    /// since it was built, or a grid not built yet (no cells), the methods scan every
    /// particle and find what a current grid would.
    #[test]
    fn a_stale_or_empty_grid_is_not_used() {
        use sph_core::components::{Acceleration, NeighbourCount};
        use sph_core::vocab::Guarded;
        let mut sim = scene();
        let floor = wall(&sim, 0);
        // A particle close to the floor's point 0.0625, pressed, added after the grid.
        let x = DVec2::new(0.0625, 0.002);
        sim.world.spawn((
            Fluid,
            Position(x),
            Velocity(DVec2::ZERO),
            Density(1000.0),
            Pressure(5000.0),
            Mass(0.1),
            Acceleration(DVec2::ZERO),
            Guarded(0),
            NeighbourCount(0),
        ));
        let at = floor.point(0.0625);
        let e = 5000.0 + 1000.0 * G_EFF.dot(at - x);
        let got = read(&mut Nearest, &sim, &site(&floor, 0.0625, 0.0));
        assert!((got - e).abs() < 1e-9, "{got} against {e}");
        let mut averaged = Averaged::default();
        let face = read(&mut averaged, &sim, &site(&floor, 0.0625, 0.03));
        let e = oger(&sim, &floor, 0.0625, 0.03);
        assert!((face - e).abs() < 1e-9, "{face} against {e}");
        // A grid that covers the fluid's count but has no cells yet.
        let sim = {
            let mut sim = scene();
            sim.resources.insert(Neighbours {
                n_fluid: N_FLUID,
                ..Default::default()
            });
            sim
        };
        let e = oger(&sim, &floor, 0.0625, 0.03);
        let got = read(&mut Averaged::default(), &sim, &site(&floor, 0.0625, 0.03));
        assert!(e != 0.0 && (got - e).abs() < 1e-9, "{got} against {e}");
        assert!(read(&mut Nearest, &sim, &site(&floor, 0.0625, 0.0)) != 0.0);
    }
}
