//! Particle frames for ParaView: `frames/frame_NNNNN.vtp` every `interval` seconds of
//! simulated time, indexed by `frames.pvd` (open that file in ParaView). A moving tank
//! also gets its walls at the same times, `frames/walls_NNNNN.vtp` in `walls.pvd`
//! (open both; ParaView plays them together).

use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::{Density, NeighbourCount, Position, Pressure, Velocity};
use sph_core::contract::Access;
use sph_core::series::check_samples;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{Guarded, WallPose, Walls};
use sph_core::StageRegistry;
use sph_output::frame::write_fluid_frame;
use sph_output::vtk::{write_segments_vtp, PvdIndex};

/// The most frames a run may write.
const MAX_FRAMES: f64 = 1e5;

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
    registry.register_checked(
        "vtk_frames",
        "ParaView particle frames (.vtp + frames.pvd)",
        |p: Params| {
            if !(p.interval > 0.0 && p.interval.is_finite()) {
                return Err(sph_core::ParamError::new(
                    "interval",
                    p.interval,
                    "seconds > 0",
                ));
            }
            Ok(VtkFrames {
                params: p,
                next: 0.0,
                written: 0,
                index: None,
                walls: None,
            })
        },
    );
}

pub struct VtkFrames {
    params: Params,
    next: f64,
    written: usize,
    index: Option<PvdIndex>,
    /// The walls' index, when the scene moves (the walls are read from the world).
    walls: Option<PvdIndex>,
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
        check_samples(
            sim.clock.end_time,
            self.params.interval,
            MAX_FRAMES,
            "frames",
        )
        .map_err(|e| SetupError::new("vtk_frames", e.to_string()))?;
        self.index = Some(PvdIndex::new(sim.out_dir.join("frames.pvd")));
        if sph_core::kinematics::moving(&sim.world) {
            self.walls = Some(PvdIndex::new(sim.out_dir.join("walls.pvd")));
        }
        Ok(())
    }

    /// The next frame time, the frame count and the .pvd indexes.
    fn save_state(&mut self, _sim: &Sim) -> Result<Vec<u8>, StepError> {
        let mut e = Enc::default();
        e.f64(self.next);
        e.u64(self.written as u64);
        let indexes = self.index.iter().chain(self.walls.iter());
        for index in indexes {
            e.u64(index.entries().len() as u64);
            for (t, name) in index.entries() {
                e.f64(*t);
                e.str(name);
            }
        }
        Ok(e.into_bytes())
    }

    fn load_state(&mut self, _sim: &mut Sim, state: &[u8]) -> Result<(), sph_core::StateError> {
        let mut d = Dec::new(state);
        self.next = d.f64()?;
        self.written = d.u64()? as usize;
        let indexes = self.index.iter_mut().chain(self.walls.iter_mut());
        for index in indexes {
            let n = d.len(16)?;
            let entries = (0..n)
                .map(|_| Ok((d.f64()?, d.str()?)))
                .collect::<Result<Vec<_>, sph_core::StateError>>()?;
            index
                .restore(entries)
                .map_err(|e| sph_core::StateError::Output {
                    path: index.path().display().to_string(),
                    message: e.to_string(),
                })?;
        }
        d.end()
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
        let _span = tracing::info_span!("write_frame").entered();
        let name = format!("frames/frame_{:05}.vtp", self.written);
        write_fluid_frame(sim, &sim.out_dir.join(&name))?;
        if let Some(index) = &mut self.index {
            index
                .push(sim.clock.time, &name)
                .map_err(|e| StepError::output(&sim.out_dir.join("frames.pvd"), e))?;
        }
        if let Some(index) = &mut self.walls {
            let name = format!("frames/walls_{:05}.vtp", self.written);
            let path = sim.out_dir.join(&name);
            // Where the world has the walls now.
            let segments: Vec<_> = Walls::of(&sim.world)
                .now()
                .iter()
                .map(|w| (w.a, w.b))
                .collect();
            write_segments_vtp(&path, &segments).map_err(|e| StepError::output(&path, e))?;
            index
                .push(sim.clock.time, &name)
                .map_err(|e| StepError::output(index.path(), e))?;
        }
        self.written += 1;
        Ok(())
    }

    /// Writes the fluid state and the walls where the world has them.
    fn access(&self) -> Access {
        Access::new()
            .reads::<Position>()
            .reads::<Velocity>()
            .reads::<Density>()
            .reads::<Pressure>()
            .reads::<WallPose>()
            .uses::<NeighbourCount>()
            .uses::<Guarded>()
    }
}
