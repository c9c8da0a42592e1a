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
//!   weights dS_k = (q_{k+1} - q_{k-1})/2 (the sensor's edges close the ends).
//!
//! A sensor with no fluid within the kernel support reads 0 (dry).

use glam::DVec2;
use sph_core::components::{Density, Mass, Position, Pressure};
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
pub(crate) fn shepard(sim: &Sim, particles: Particles, at: DVec2) -> Result<f64, StepError> {
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
        let fit = (0.5 * site.width).min(centre).min(wall.length() - centre);
        let half = if fit > 0.0 { fit } else { 0.5 * site.width };
        let (lo, hi) = (centre - half, centre + half);
        let sample = |i: usize| {
            let q = x[i].0;
            let (d, a) = (wall.distance(q), wall.abscissa(q));
            ((0.0..reach).contains(&d) && (lo..=hi).contains(&a)).then(|| {
                let on_wall = q - d * wall.normal();
                (a, carry.carry(p[i].0, q, on_wall))
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
                let points = ((hi - lo) / (0.5 * sim.constants.h)).ceil().clamp(1.0, 1e4) as usize;
                for k in 0..=points {
                    let at = wall.point(lo + (hi - lo) * k as f64 / points as f64);
                    nb.grid.for_each_near(at, |j| {
                        if (j as usize) < x.len() {
                            candidates.push(j)
                        }
                    });
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
        Ok(if den > 0.0 {
            num / den
        } else {
            samples.iter().map(|s| s.1).sum::<f64>() / samples.len() as f64
        })
    }
}
