//! Components of the particle world. Every particle quantity is its own component so a
//! stage borrows exactly the columns it reads and writes; hecs stores each archetype's
//! components as contiguous columns, which the hot loops borrow as slices
//! ([`crate::world::columns`]).

use crate::dim::Vector;
use crate::motion::Pose;

macro_rules! component {
    ($(#[$doc:meta])* $name:ident($ty:ty)) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, Default, PartialEq)]
        #[repr(transparent)]
        pub struct $name(pub $ty);

        impl $name {
            /// A column of these as the plain values, without a copy.
            pub fn values(column: &[Self]) -> &[$ty] {
                // SAFETY: `#[repr(transparent)]` gives the type exactly the layout of
                // its one field, so the slices have the same length and layout.
                unsafe { std::slice::from_raw_parts(column.as_ptr().cast(), column.len()) }
            }
        }
    };
}

component!(
    /// Particle position x [m].
    Position(Vector)
);
component!(
    /// Particle velocity v [m/s] at the current (integer) time level.
    Velocity(Vector)
);
component!(
    /// Density rho [kg/m^3].
    Density(f64)
);
component!(
    /// Pressure p [Pa], from the equation of state.
    Pressure(f64)
);
component!(
    /// Particle mass m [kg]; constant.
    Mass(f64)
);
component!(
    /// dv/dt from the momentum equation [m/s^2]; written by the forces stage.
    Acceleration(Vector)
);
component!(
    /// d rho / dt from the continuity equation [kg/m^3/s]; written by the density stage.
    DensityRate(f64)
);
component!(
    /// Number of neighbours within the kernel support (fluid and ghost), self excluded.
    NeighbourCount(u32)
);
component!(
    /// Stable identity of a fluid particle (its index at creation), kept when the
    /// particle columns are reordered.
    ParticleId(u32)
);

/// The wall entity a ghost particle was (first) mirrored across: a component of every
/// ghost, written with it by the ghost-wall stage (its body's acceleration enters the
/// ghost's hydrostatic density).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MirrorWall(pub hecs::Entity);

impl Default for MirrorWall {
    fn default() -> Self {
        Self(hecs::Entity::DANGLING)
    }
}

/// Marker of fluid particles: the integrated particles.
#[derive(Clone, Copy, Debug, Default)]
pub struct Fluid;

/// A ghost particle: the mirror image of fluid particle `source` (its index in the
/// fluid columns) across one wall, or two walls at a corner. Ghosts live in their own
/// archetype and are reused from step to step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Ghost {
    pub source: u32,
}

impl Ghost {
    /// The `source` of a fixed wall particle (the `WallParticles` stage), which mirrors
    /// no fluid particle.
    pub const WALL_PARTICLE: u32 = u32::MAX;

    /// Whether this is a fixed wall particle rather than a mirror image.
    pub fn is_wall_particle(&self) -> bool {
        self.source == Self::WALL_PARTICLE
    }
}

/// A plane wall: in 2D the segment from `a` to `b`, the fluid on its left (the inward
/// normal is the direction a->b turned 90 degrees counter-clockwise); in 3D the
/// rectangle with corner `a` and edges a->b and a->c, the fluid on the side of
/// (c - a) x (b - a) (so a 2D wall drawn out along +z keeps its normal).
/// As a component it holds the wall at rest, in the frame of the body it rides on (the
/// tank frame, or a piston's rest place), as the scenario wrote it; where the wall is
/// now is its [`WallPose`], which the kinematics ([`crate::kinematics`]) writes.
#[derive(Clone, Debug, PartialEq)]
pub struct Wall {
    pub name: String,
    pub a: Vector,
    pub b: Vector,
    /// The corner at the end of the wall's second edge from `a` (3D).
    #[cfg(feature = "dim3")]
    pub c: Vector,
    /// Pose of the body the wall rides on, for its velocity and acceleration
    /// (at rest for a fixed wall).
    pub body: Pose,
}

impl Wall {
    /// The wall where it rests (its own geometry as a [`WallPose`]).
    pub fn at_rest(&self) -> WallPose {
        WallPose {
            a: self.a,
            b: self.b,
            #[cfg(feature = "dim3")]
            c: self.c,
            body: self.body,
        }
    }
    /// The wall carried to the world by `pose`, the pose of the body it rides on.
    pub fn placed(&self, pose: Pose) -> WallPose {
        let placement = pose.placement();
        WallPose {
            a: placement.to_world(self.a),
            b: placement.to_world(self.b),
            #[cfg(feature = "dim3")]
            c: placement.to_world(self.c),
            body: pose,
        }
    }
    /// Unit normal pointing into the fluid.
    pub fn normal(&self) -> Vector {
        self.at_rest().normal()
    }
    /// Signed distance of `x` from the wall's line, positive on the fluid side.
    pub fn distance(&self, x: Vector) -> f64 {
        self.at_rest().distance(x)
    }
    /// Abscissa of the projection of `x` along the wall, 0 at `a`, |b-a| at `b`.
    pub fn abscissa(&self, x: Vector) -> f64 {
        self.at_rest().abscissa(x)
    }
    pub fn length(&self) -> f64 {
        self.at_rest().length()
    }
}

/// Where a wall is now (at the clock's time), in the world frame, with the pose of the
/// body it rides on (the tank's, or a piston's own). A component of every wall entity,
/// written by the kinematics ([`crate::kinematics`]) whenever the clock advances;
/// stages read wall poses from here.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WallPose {
    pub a: Vector,
    pub b: Vector,
    /// The corner at the end of the wall's second edge from `a` (3D).
    #[cfg(feature = "dim3")]
    pub c: Vector,
    /// Pose of the body the wall rides on, for its velocity and acceleration.
    pub body: Pose,
}

impl WallPose {
    /// Unit normal pointing into the fluid: a->b turned a quarter counter-clockwise
    /// in 2D, (c - a) x (b - a) normalised in 3D.
    pub fn normal(&self) -> Vector {
        #[cfg(not(feature = "dim3"))]
        return (self.b - self.a).perp().normalize_or_zero();
        #[cfg(feature = "dim3")]
        return (self.c - self.a).cross(self.b - self.a).normalize_or_zero();
    }
    /// Unit tangent from a to b.
    pub fn tangent(&self) -> Vector {
        (self.b - self.a).normalize_or_zero()
    }
    /// Signed distance of `x` from the wall's plane (2D: line), positive on the fluid
    /// side.
    pub fn distance(&self, x: Vector) -> f64 {
        (x - self.a).dot(self.normal())
    }
    /// Abscissa of the projection of `x` along the wall, 0 at `a`, |b-a| at `b`.
    pub fn abscissa(&self, x: Vector) -> f64 {
        (x - self.a).dot(self.tangent())
    }
    pub fn length(&self) -> f64 {
        (self.b - self.a).length()
    }
    /// Unit tangent from a to c (3D).
    #[cfg(feature = "dim3")]
    pub fn tangent_across(&self) -> Vector {
        (self.c - self.a).normalize_or_zero()
    }
    /// Abscissa of the projection of `x` along a->c, 0 at `a`, |c-a| at `c` (3D).
    #[cfg(feature = "dim3")]
    pub fn abscissa_across(&self, x: Vector) -> f64 {
        (x - self.a).dot(self.tangent_across())
    }
    /// The wall's extent along a->c (3D).
    #[cfg(feature = "dim3")]
    pub fn breadth(&self) -> f64 {
        (self.c - self.a).length()
    }
    /// Mirror image of `x` across the wall's plane (2D: line).
    pub fn mirror(&self, x: Vector) -> Vector {
        x - 2.0 * self.distance(x) * self.normal()
    }
    /// The point at abscissa `s` along the edge a->b.
    pub fn point(&self, s: f64) -> Vector {
        self.a + s * self.tangent()
    }
    /// Edge `k` of the rectangle (3D) as its two ends: 0 a->b, 1 a->c, 2 b->d,
    /// 3 c->d, with d = b + c - a the corner across from a.
    #[cfg(feature = "dim3")]
    pub fn edge(&self, k: usize) -> (Vector, Vector) {
        let d = self.b + self.c - self.a;
        match k {
            0 => (self.a, self.b),
            1 => (self.a, self.c),
            2 => (self.b, d),
            _ => (self.c, d),
        }
    }
    /// The rectangle's centre (3D).
    #[cfg(feature = "dim3")]
    pub fn centre(&self) -> Vector {
        0.5 * (self.b + self.c)
    }
    /// Velocity of the wall material at world point `x` on or near it.
    pub fn velocity_at(&self, x: Vector) -> Vector {
        self.body.velocity_at(x)
    }
}

/// The pose now (at the clock's time) of a body with a prescribed motion: the tank
/// (at rest for a fixed tank) and each piston. Written by the kinematics
/// ([`crate::kinematics`]) from the body's [`crate::motion::Motion`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BodyPose(pub Pose);

/// The tank: an axis-aligned box in its own frame with the bottom-left inner corner at
/// the origin, and the pivot it rolls about. A moving tank also has a
/// [`crate::motion::Motion`] component.
#[derive(Clone, Debug, PartialEq)]
pub struct Tank {
    pub width: f64,
    pub height: f64,
    /// The extent along z (3D).
    #[cfg(feature = "dim3")]
    pub breadth: f64,
    /// Roll axis in the tank frame (in 3D the line through it along z); the roll
    /// moment is taken about it.
    pub pivot: Vector,
}

/// Where a wall sensor's pressure is read: abscissa `along` on the wall entity `wall`
/// (so it rides with the wall), over a width `width` along the wall (Method III's
/// pseudo-sensor); with a transducer's face `diameter` and time `filter` window (0 for
/// none), it also reads as such a transducer would.
#[derive(Clone, Debug, PartialEq)]
pub struct PressureSensor {
    pub name: String,
    pub wall: hecs::Entity,
    pub along: f64,
    /// In 3D, the abscissa along the wall's second edge (a->c).
    #[cfg(feature = "dim3")]
    pub across: f64,
    pub width: f64,
    /// The transducer's face diameter [m]; 0 for a point.
    pub diameter: f64,
    /// The transducer's time-filter window [s]; 0 for none.
    pub filter: f64,
}

impl PressureSensor {
    /// Whether the sensor also reads as a transducer (a face or a filter).
    pub fn transducer(&self) -> bool {
        self.diameter > 0.0 || self.filter > 0.0
    }
}

/// A wave gauge: free-surface elevation on the vertical line x = `x` (and z = `z` in
/// 3D) of the tank frame, measured from the tank bottom along the tank's vertical.
#[derive(Clone, Debug, PartialEq)]
pub struct WaveGauge {
    pub name: String,
    pub x: f64,
    #[cfg(feature = "dim3")]
    pub z: f64,
}
