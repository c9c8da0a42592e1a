//! The simulation state every stage sees: the particle world plus the run's constants,
//! clock and shared resources.

use crate::kernel::KernelKind;
use glam::DVec2;
use std::any::{Any, TypeId};
use std::collections::HashMap;
use std::path::PathBuf;

/// Simulated time and step counter.
#[derive(Clone, Debug, Default)]
pub struct Clock {
    /// Simulated time t [s] of the current state.
    pub time: f64,
    /// The time step the integrator last took [s] (0 before the first step).
    pub dt: f64,
    /// Completed steps.
    pub step: u64,
    /// End time [s].
    pub end_time: f64,
}

/// The Tait equation of state p = B [(rho/rho_0)^gamma - 1], B = rho_0 c_0^2 / gamma
/// (physics.md, "Governing equations").
#[derive(Clone, Copy, Debug)]
pub struct Tait {
    pub rho0: f64,
    pub c0: f64,
    pub gamma: f64,
    pub b: f64,
}

impl Tait {
    pub fn new(rho0: f64, c0: f64, gamma: f64) -> Self {
        Self {
            rho0,
            c0,
            gamma,
            b: rho0 * c0 * c0 / gamma,
        }
    }
    /// p(rho).
    #[inline(always)]
    pub fn pressure(&self, rho: f64) -> f64 {
        self.b * ((rho / self.rho0).powf(self.gamma) - 1.0)
    }
    /// rho(p), the inverse of [`Tait::pressure`]. Tension beyond -B has no density; it
    /// maps to the smallest positive one, rho_0 1e-12^(1/gamma) (a ghost of a spray
    /// particle, corrected hydrostatically upward, can ask for it; a zero density
    /// would make p / rho^2 undefined).
    pub fn density(&self, p: f64) -> f64 {
        self.rho0 * (1.0 + p / self.b).max(1e-12).powf(1.0 / self.gamma)
    }
    /// Specific internal energy e(rho) = integral from rho_0 to rho of p/rho'^2 drho'.
    pub fn internal_energy(&self, rho: f64) -> f64 {
        let g = self.gamma;
        let r0 = self.rho0;
        self.b * (((rho / r0).powf(g - 1.0) - 1.0) / ((g - 1.0) * r0) + 1.0 / rho - 1.0 / r0)
    }
    /// Speed of sound at density rho: c^2 = dp/drho.
    #[inline(always)]
    pub fn sound_speed(&self, rho: f64) -> f64 {
        (self.c0 * self.c0 * (rho / self.rho0).powf(self.gamma - 1.0)).sqrt()
    }
}

/// Fluid and discretisation constants, fixed for a run.
#[derive(Clone, Debug)]
pub struct Constants {
    pub eos: Tait,
    /// Gravity [m/s^2].
    pub gravity: DVec2,
    /// Initial particle spacing ds [m].
    pub spacing: f64,
    /// Smoothing length h [m].
    pub h: f64,
    pub kernel: KernelKind,
    /// Height of the tallest initial fluid block H [m] (pressure scale rho_0 g H).
    pub fluid_height: f64,
    /// Particles outside this box have left the domain (an instability).
    pub domain: (DVec2, DVec2),
}

impl Constants {
    /// Kernel support radius [m].
    pub fn support(&self) -> f64 {
        self.kernel.support_factor() * self.h
    }
}

/// Type-keyed shared state that stages publish for later stages (the neighbour list,
/// energy ledgers, ...). A stage that needs a resource checks for it at setup.
#[derive(Default)]
pub struct Resources {
    map: HashMap<TypeId, Box<dyn Any + Send + Sync>>,
}

impl Resources {
    pub fn insert<T: Any + Send + Sync>(&mut self, value: T) {
        self.map.insert(TypeId::of::<T>(), Box::new(value));
    }
    pub fn get<T: Any + Send + Sync>(&self) -> Option<&T> {
        self.map
            .get(&TypeId::of::<T>())
            .and_then(|b| b.downcast_ref())
    }
    pub fn get_mut<T: Any + Send + Sync>(&mut self) -> Option<&mut T> {
        self.map
            .get_mut(&TypeId::of::<T>())
            .and_then(|b| b.downcast_mut())
    }
    pub fn contains<T: Any + Send + Sync>(&self) -> bool {
        self.map.contains_key(&TypeId::of::<T>())
    }
    /// Takes a resource out (to borrow it alongside the world), to be put back with
    /// [`Resources::insert`].
    pub fn take<T: Any + Send + Sync>(&mut self) -> Option<T> {
        self.map
            .remove(&TypeId::of::<T>())
            .and_then(|b| b.downcast().ok())
            .map(|b| *b)
    }
}

/// Everything a stage sees.
pub struct Sim {
    pub world: hecs::World,
    pub clock: Clock,
    pub constants: Constants,
    pub resources: Resources,
    /// Folder for this run's outputs.
    pub out_dir: PathBuf,
    /// Scenario name, for titles.
    pub name: String,
    /// Named run diagnostics (e.g. `wall_reflections`), written to summary.json.
    pub diagnostics: std::collections::BTreeMap<String, f64>,
}
