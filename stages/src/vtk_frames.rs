//! Particle frames for ParaView: `frames/frame_NNNNN.vtp` every `interval` seconds of
//! simulated time, indexed by `frames.pvd` (open that file in ParaView).

use serde::{Deserialize, Serialize};
use sph_core::frame::write_fluid_frame;
use sph_core::output::vtk::PvdIndex;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::StageRegistry;

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Frame interval [s]. Default 0.05.
    pub interval: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self { interval: 0.05 }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register(
        "vtk_frames",
        "ParaView particle frames (.vtp + frames.pvd)",
        |p: Params| {
            if !(p.interval > 0.0 && p.interval.is_finite()) {
                return Err(format!(
                    "field `interval` = {} is out of range; accepted: seconds > 0",
                    p.interval
                ));
            }
            Ok(VtkFrames {
                params: p,
                next: 0.0,
                written: 0,
                index: None,
            })
        },
    );
}

pub struct VtkFrames {
    params: Params,
    next: f64,
    written: usize,
    index: Option<PvdIndex>,
}

impl Stage for VtkFrames {
    fn name(&self) -> &'static str {
        "vtk_frames"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        let dir = sim.out_dir.join("frames");
        std::fs::create_dir_all(&dir).map_err(|e| {
            SetupError::new(
                "vtk_frames",
                format!("cannot create {}: {e}", dir.display()),
            )
        })?;
        self.index = Some(PvdIndex::new(sim.out_dir.join("frames.pvd")));
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        if sim.clock.time + 1e-12 < self.next {
            return Ok(());
        }
        self.next += self.params.interval
            * ((sim.clock.time - self.next) / self.params.interval)
                .floor()
                .max(0.0)
            + self.params.interval;
        let name = format!("frames/frame_{:05}.vtp", self.written);
        write_fluid_frame(sim, &sim.out_dir.join(&name))?;
        self.written += 1;
        if let Some(index) = &mut self.index {
            index
                .push(sim.clock.time, &name)
                .map_err(|e| StepError::output(&sim.out_dir.join("frames.pvd"), e))?;
        }
        Ok(())
    }
}
