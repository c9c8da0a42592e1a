//! The simulation state every stage sees: the particle world plus the run's constants,
//! clock and shared resources.

use crate::dim::Vector;
use crate::kernel::KernelKind;
use std::any::{Any, TypeId};
use std::collections::{BTreeMap, HashMap};
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

impl Clock {
    /// Takes a step of `dt`: the time advances by it, the step count by one, and the
    /// scene (tank, walls, pistons) moves to the new time ([`crate::kinematics`]), so
    /// the world's wall poses always belong to `time`. Only the stage that declares the
    /// clock among its writes ([`crate::contract::Quantity::clock`]; `Integrate`) calls
    /// this, once per step.
    pub fn advance(&mut self, dt: f64, scene: &hecs::World) {
        self.dt = dt;
        self.time += dt;
        self.step += 1;
        crate::kinematics::place(scene, self.time);
    }
}

/// The Tait equation of state p = B [(rho/rho_0)^gamma - 1], B = rho_0 c_0^2 / gamma
/// (docs/physics.md, "Governing equations").
#[derive(Clone, Copy, Debug)]
pub struct Tait {
    pub rho0: f64,
    pub c0: f64,
    pub gamma: f64,
    pub b: f64,
    /// gamma when it is a whole number from 1 to 12 (7 is usual): the powers are then
    /// taken by multiplication, several times cheaper than `powf`.
    whole_gamma: Option<u32>,
}

impl Tait {
    pub fn new(rho0: f64, c0: f64, gamma: f64) -> Self {
        let whole = gamma.fract() == 0.0 && (1.0..=12.0).contains(&gamma);
        Self {
            rho0,
            c0,
            gamma,
            b: rho0 * c0 * c0 / gamma,
            whole_gamma: whole.then_some(gamma as u32),
        }
    }
    /// (rho/rho_0)^(gamma - k) for k = 0 or 1.
    #[inline(always)]
    fn ratio_pow(&self, rho: f64, k: u32) -> f64 {
        let x = rho / self.rho0;
        match self.whole_gamma {
            Some(n) => whole_pow(x, n - k),
            None => x.powf(self.gamma - k as f64),
        }
    }
    /// p(rho).
    #[inline(always)]
    pub fn pressure(&self, rho: f64) -> f64 {
        self.b * (self.ratio_pow(rho, 0) - 1.0)
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
        (self.c0 * self.c0 * self.ratio_pow(rho, 1)).sqrt()
    }
}

pub use crate::pair::lane::whole_pow;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_powers_match_powf() {
        for n in 0..=12 {
            for x in [0.3, 0.97, 1.0, 1.013, 2.5] {
                let (a, b) = (whole_pow::<f64>(x, n), f64::powf(x, n as f64));
                assert!(
                    (a - b).abs() <= 8.0 * f64::EPSILON * b,
                    "{x}^{n}: {a} vs {b}"
                );
            }
        }
        let (whole, general) = (
            Tait::new(1000.0, 20.0, 7.0),
            Tait::new(1000.0, 20.0, 7.0 + 1e-12),
        );
        assert!(whole.whole_gamma.is_some() && general.whole_gamma.is_none());
        for rho in [950.0, 1000.0, 1030.0] {
            let (p, q) = (whole.pressure(rho), general.pressure(rho));
            assert!((p - q).abs() < 1e-6 * whole.b, "{p} vs {q}");
            let (c, d) = (whole.sound_speed(rho), general.sound_speed(rho));
            assert!((c - d).abs() < 1e-9 * c, "{c} vs {d}");
        }
    }
}

/// Fluid and discretisation constants, fixed for a run.
#[derive(Clone, Debug)]
pub struct Constants {
    pub eos: Tait,
    /// Gravity [m/s^2].
    pub gravity: Vector,
    /// Initial particle spacing ds [m].
    pub spacing: f64,
    /// Smoothing length h [m].
    pub h: f64,
    pub kernel: KernelKind,
    /// Height of the tallest initial fluid block H [m] (pressure scale rho_0 g H).
    pub fluid_height: f64,
    /// Particles outside this box have left the domain (an instability).
    pub domain: (Vector, Vector),
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
    /// The resource of type `T`, inserted as its default first if absent.
    pub fn get_or_default<T: Any + Send + Sync + Default>(&mut self) -> &mut T {
        self.map
            .entry(TypeId::of::<T>())
            .or_insert_with(|| Box::new(T::default()))
            .downcast_mut()
            .expect("the entry under T's TypeId holds a T")
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
    pub diagnostics: BTreeMap<String, f64>,
}

/// A count kept over a run and reported in summary.json's diagnostics (a safeguard's
/// actions, particles a filter left alone, ...), keyed by type: the stage that counts
/// declares it in its [`crate::contract::Access`] (`writes::<C>()`), one that reads it
/// (`uses::<C>()`), and both name it by type, not by string. Kept in the sim's
/// `diagnostics` (so in checkpoints), which the methods take rather than the whole sim
/// so that a stage can count while it holds the world's columns.
pub trait Counter: 'static {
    /// Its name in summary.json.
    const NAME: &'static str;
    /// Adds `n` (a counter that never counted stays out of the summary).
    fn add(diagnostics: &mut BTreeMap<String, f64>, n: u64) {
        if n > 0 {
            *diagnostics.entry(Self::NAME.into()).or_insert(0.0) += n as f64;
        }
    }
    /// The count so far in the run.
    fn counted(diagnostics: &BTreeMap<String, f64>) -> f64 {
        diagnostics.get(Self::NAME).copied().unwrap_or(0.0)
    }
}
