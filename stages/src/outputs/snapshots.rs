//! PNG pictures of the particles coloured by pressure at listed times
//! (`snapshot_t1.400.png`), e.g. the paper's t = 1.4, 1.5, 1.7 s for the dam break.

use glam::DVec2;
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::{Position, Pressure};
use sph_core::contract::Access;
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
}

impl Default for Params {
    fn default() -> Self {
        Self {
            times: Vec::new(),
            pressure_range: None,
            width: 1200,
            region: None,
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
        let (positions, values): (Vec<DVec2>, Vec<f64>) = x
            .iter()
            .zip(p.iter())
            .map(|(q, p)| (q.0, p.0))
            .filter(|(q, _)| inside(q))
            .unzip();
        // Walls where the world has them now (a rolling tank's walls move).
        let walls: Vec<(DVec2, DVec2)> = Walls::of(&sim.world)
            .now()
            .iter()
            .map(|w| (w.a, w.b))
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
        let title = format!("{}  t = {:.3} s", sim.name, sim.clock.time);
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
