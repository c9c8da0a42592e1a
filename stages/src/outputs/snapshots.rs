//! PNG pictures of the particles coloured by pressure at listed times
//! (`snapshot_t1.400.png`), e.g. the paper's t = 1.4, 1.5, 1.7 s for the dam break.
//! In 3D a picture is the x-y section at one z: the particles within one spacing of
//! it, and the walls where they cut its plane.

use glam::DVec2;
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::{Position, Pressure};
use sph_core::contract::Access;
use sph_core::dim::Vector;
use sph_core::sim::Sim;
use sph_core::stage::{Stage, StepError};
use sph_core::vocab::{WallPose, Walls};
use sph_core::world::Particles;
use sph_core::StageRegistry;
use sph_output::png::{pressure_colour_range, write_snapshot, Snapshot};

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Simulated times [s] to draw; each is drawn at the first step at or after it,
    /// named by the requested time (the title gives the actual time).
    pub times: Vec<f64>,
    /// Colour scale [Pa]; default per picture: 0 (or the 1st percentile if negative) to
    /// the 99th percentile of the drawn pressures (`pressure_colour_range`), falling
    /// back to (0, rho_0 |g| H), H the tallest initial fluid block.
    pub pressure_range: Option<(f64, f64)>,
    /// Image width [px]. Default 1200.
    pub width: u32,
    /// Draw only this rectangle ((x0, y0), (x1, y1)) [m], e.g. a plunging tip. Default:
    /// the walls and all particles.
    pub region: Option<((f64, f64), (f64, f64))>,
    /// 3D: the z [m] of the x-y section drawn: the fluid particles with
    /// z0 - ds <= z < z0 + ds (a layer of the initial lattice and those that have
    /// drifted into its neighbours' places: one spacing thin leaves holes where the
    /// layer has moved), and the walls' lines in that plane. Default: the
    /// middle of the fluid's z range at the time drawn. Refused in 2D.
    pub slice: Option<f64>,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            times: Vec::new(),
            pressure_range: None,
            width: 1200,
            region: None,
            slice: None,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "snapshots",
        "PNG pictures of the particles coloured by pressure",
        |mut p: Params| {
            use sph_core::ParamError;
            if let Some(t) = p.times.iter().find(|t| !t.is_finite() || **t < 0.0) {
                return Err(ParamError::new("times", t, "times in seconds >= 0"));
            }
            if !(100..=8000).contains(&p.width) {
                return Err(ParamError::new("width", p.width, "100 to 8000 pixels"));
            }
            if let Some(((x0, y0), (x1, y1))) = p.region {
                if !(x1 > x0 && y1 > y0 && [x0, y0, x1, y1].iter().all(|v| v.is_finite())) {
                    return Err(ParamError::new(
                        "region",
                        format!("(({x0}, {y0}), ({x1}, {y1}))"),
                        "((x0, y0), (x1, y1)) with x1 > x0, y1 > y0 [m]",
                    ));
                }
            }
            if let Some(z) = p.slice {
                if sph_core::dim::DIM == 2 {
                    return Err(ParamError::new(
                        "slice",
                        z,
                        "no `slice` in 2D: the picture is the scene's plane",
                    ));
                }
                if !z.is_finite() {
                    return Err(ParamError::new("slice", z, "a z in metres"));
                }
            }
            p.times.sort_by(f64::total_cmp);
            Ok(Snapshots {
                params: p,
                taken: 0,
            })
        },
    );
}

pub struct Snapshots {
    params: Params,
    taken: usize,
}

impl Stage for Snapshots {
    fn name(&self) -> &'static str {
        "snapshots"
    }

    /// How many of the listed times are taken.
    fn save_state(&mut self, _sim: &Sim) -> Result<Vec<u8>, StepError> {
        let mut e = Enc::default();
        e.u64(self.taken as u64);
        Ok(e.into_bytes())
    }

    fn load_state(&mut self, _sim: &mut Sim, state: &[u8]) -> Result<(), sph_core::StateError> {
        let mut d = Dec::new(state);
        self.taken = d.u64()? as usize;
        d.end()
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let Some(&t) = self.params.times.get(self.taken) else {
            return Ok(());
        };
        if sim.clock.time + 1e-12 < t {
            return Ok(());
        }
        while self
            .params
            .times
            .get(self.taken)
            .is_some_and(|&u| u <= sim.clock.time + 1e-12)
        {
            self.taken += 1;
        }
        let _span = tracing::info_span!("write_png").entered();
        let Some(particles) = Particles::of(&sim.world) else {
            return Ok(());
        };
        let (x, p) = (
            particles.fluid::<Position>()?,
            particles.fluid::<Pressure>()?,
        );
        let inside = |q: &DVec2| {
            self.params.region.is_none_or(|((x0, y0), (x1, y1))| {
                (x0..=x1).contains(&q.x) && (y0..=y1).contains(&q.y)
            })
        };
        let fluid: Vec<(Vector, f64)> = x.iter().zip(p.iter()).map(|(q, p)| (q.0, p.0)).collect();
        let (slice, drawn) = section(&fluid, self.params.slice, sim.constants.spacing);
        let (positions, values): (Vec<DVec2>, Vec<f64>) =
            drawn.into_iter().filter(|(q, _)| inside(q)).unzip();
        // Walls where the world has them now (a rolling tank's walls move).
        let walls: Vec<(DVec2, DVec2)> = Walls::of(&sim.world)
            .now()
            .iter()
            .filter_map(|w| wall_line(w, slice))
            .collect();
        // The requested region, or everything: walls and particles.
        let (lo, hi) = match self.params.region {
            Some(((x0, y0), (x1, y1))) => (DVec2::new(x0, y0), DVec2::new(x1, y1)),
            None => walls
                .iter()
                .flat_map(|&(a, b)| [a, b])
                .chain(positions.iter().copied())
                .fold(
                    (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
                    |(lo, hi), q| (lo.min(q), hi.max(q)),
                ),
        };
        let c = &sim.constants;
        let range = self.params.pressure_range.unwrap_or_else(|| {
            let fallback = (0.0, c.eos.rho0 * c.gravity.length() * c.fluid_height);
            pressure_colour_range(&values, fallback)
        });
        let path = sim.out_dir.join(format!("snapshot_t{t:.3}.png"));
        let title = match sph_core::dim::DIM {
            2 => format!("{}  t = {:.3} s", sim.name, sim.clock.time),
            _ => format!(
                "{}  t = {:.3} s  z = {slice:.3} m",
                sim.name, sim.clock.time
            ),
        };
        let snapshot = Snapshot {
            positions: &positions,
            values: &values,
            value_range: range,
            bounds: (lo, hi),
            walls: &walls,
            title: &title,
            colorbar_label: "pressure [Pa]",
            width_px: self.params.width,
        };
        write_snapshot(&path, &snapshot).map_err(|e| StepError::output(&path, e))
    }

    /// Draws the fluid's pressures and the walls where the world has them.
    fn access(&self) -> Access {
        Access::new()
            .reads::<Position>()
            .reads::<Pressure>()
            .reads::<WallPose>()
    }
}

/// The particles drawn, as (x, y) and value, and the z of the section: in 2D every
/// particle (z 0); in 3D those with z0 - ds <= z < z0 + ds, z0 = `slice` or the
/// middle of the particles' z range (0 with none).
fn section(fluid: &[(Vector, f64)], slice: Option<f64>, ds: f64) -> (f64, Vec<(DVec2, f64)>) {
    #[cfg(not(feature = "dim3"))]
    {
        let _ = (slice, ds);
        (0.0, fluid.to_vec())
    }
    #[cfg(feature = "dim3")]
    {
        let z0 = slice.unwrap_or_else(|| {
            let (lo, hi) = fluid
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| {
                    (lo.min(q.0.z), hi.max(q.0.z))
                });
            if lo <= hi {
                0.5 * (lo + hi)
            } else {
                0.0
            }
        });
        let layer = |z: f64| z >= z0 - ds && z < z0 + ds;
        let drawn = fluid
            .iter()
            .filter(|(q, _)| layer(q.z))
            .map(|&(q, v)| (q.truncate(), v))
            .collect();
        (z0, drawn)
    }
}

/// The line a wall draws in the picture: in 2D the wall itself; in 3D where its
/// rectangle cuts the plane z = `z0` (none for a wall lying in such a plane or not
/// reaching it).
fn wall_line(w: &WallPose, z0: f64) -> Option<(DVec2, DVec2)> {
    #[cfg(not(feature = "dim3"))]
    {
        let _ = z0;
        Some((w.a, w.b))
    }
    #[cfg(feature = "dim3")]
    {
        // The rectangle's edges in order round it; each that crosses the plane gives a
        // point (an edge lying in the plane gives none: its wall is drawn by its
        // neighbours' crossings, or not at all if it lies flat in the plane).
        let d = w.b + w.c - w.a;
        let corners = [w.a, w.b, d, w.c];
        let mut cut = Vec::with_capacity(2);
        for k in 0..4 {
            let (p, q) = (corners[k], corners[(k + 1) % 4]);
            let (sp, sq) = (p.z - z0, q.z - z0);
            if (sp <= 0.0 && sq > 0.0) || (sp > 0.0 && sq <= 0.0) {
                let s = sp / (sp - sq);
                cut.push((p + s * (q - p)).truncate());
            }
        }
        (cut.len() == 2).then(|| (cut[0], cut[1]))
    }
}

#[cfg(all(test, feature = "dim3"))]
mod tests {
    use super::*;
    use sph_core::motion::Pose;

    fn wall(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> WallPose {
        WallPose {
            a: Vector::from(a),
            b: Vector::from(b),
            c: Vector::from(c),
            body: Pose::default(),
        }
    }

    /// A 1 x 0.5 x 0.4 m box cut at z = 0.1: its left wall and floor draw their lines
    /// in the x-y plane, the back wall (lying in a plane z = 0) and any wall cut
    /// outside its breadth draw none.
    #[test]
    fn a_wall_draws_where_it_cuts_the_plane() {
        let left = wall([0.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.4]);
        let floor = wall([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.4]);
        let back = wall([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.5, 0.0]);
        let line = |w: &WallPose, z: f64| wall_line(w, z).map(|(p, q)| [p, q]);
        let near = |l: Option<[DVec2; 2]>, want: [[f64; 2]; 2]| {
            let l = l.expect("a line");
            let same = |p: DVec2, q: [f64; 2]| (p - DVec2::from(q)).length() < 1e-12;
            (same(l[0], want[0]) && same(l[1], want[1]))
                || (same(l[0], want[1]) && same(l[1], want[0]))
        };
        assert!(near(line(&left, 0.1), [[0.0, 0.0], [0.0, 0.5]]));
        assert!(near(line(&floor, 0.1), [[0.0, 0.0], [1.0, 0.0]]));
        assert_eq!(line(&back, 0.1), None);
        assert_eq!(line(&left, 0.5), None);
        // A tilted wall (rolled about x by its plane's slope) cuts where its z is z0.
        let tilted = wall([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.3, 0.4]);
        assert!(near(line(&tilted, 0.2), [[0.0, 0.15], [1.0, 0.15]]));
    }

    /// The section holds the particles within ds of its plane: of three layers ds
    /// apart, nudged 1 mm out of the lattice so that none lies on the section's
    /// bounds, the middle one by default, the one at `slice` when given, each drawn
    /// at its (x, y) with its value.
    #[test]
    fn the_section_is_the_particles_within_a_spacing() {
        let ds = 0.01;
        let fluid: Vec<(Vector, f64)> = [0.004, 0.015, 0.026]
            .into_iter()
            .enumerate()
            .flat_map(|(k, z)| {
                (0..4).map(move |i| {
                    (
                        Vector::new(i as f64 * ds, 0.02, z),
                        100.0 * k as f64 + i as f64,
                    )
                })
            })
            .collect();
        let (z0, drawn) = section(&fluid, None, ds);
        assert!((z0 - 0.015).abs() < 1e-12, "{z0}");
        assert_eq!(drawn.len(), 4);
        assert!(
            drawn.iter().all(|(_, v)| (100.0..104.0).contains(v)),
            "{drawn:?}"
        );
        assert_eq!(drawn[2].0, DVec2::new(0.02, 0.02));
        let (_, first) = section(&fluid, Some(0.0), ds);
        assert!(
            first.iter().all(|(_, v)| *v < 4.0) && first.len() == 4,
            "{first:?}"
        );
        let (_, none) = section(&fluid, Some(0.5), ds);
        assert!(none.is_empty());
        assert_eq!(section(&[], None, ds).0, 0.0);
    }
}
