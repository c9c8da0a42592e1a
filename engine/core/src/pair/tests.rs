//! The pass against a plain loop, and the instruction sets against each other.

use super::*;
use crate::components::{Density, Fluid, Ghost, Mass, Position, Pressure, Velocity};
use crate::dim::{self, Vector, DIM};
use crate::kernel::{KernelKind, Wendland};
use crate::sim::Tait;
use crate::world::Particles;
#[cfg(not(feature = "dim3"))]
use glam::DVec2;

#[derive(Clone)]
/// A test term: sum_j m_j W_ij, sum_j m_j v_ij . grad_i W_ij and sum_j m_j p_j/rho_j^2 |grad W|.
struct Probe;

impl PairTerm for Probe {
    type Acc<L: Lane> = [L; 3];
    type Out = [f64; 3];
    fn reads(&self) -> Fields {
        Fields::of(&Field::VELOCITY).with(Fields::of(&[Field::PRho2]))
    }
    fn zero<L: Lane>(&self) -> [L; 3] {
        [L::zero(); 3]
    }
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, acc: &mut [L; 3]) {
        let m = p.j(Field::Mass);
        let (v, g) = (p.velocity_ij(me), p.grad());
        acc[0] = acc[0] + m * p.w;
        acc[1] = acc[1] + m * dot(v, g);
        acc[2] = acc[2] + m * p.j(Field::PRho2) * dot(g, g).sqrt();
    }
    fn finish<L: Lane>(&self, _: &Me, acc: [L; 3]) -> [f64; 3] {
        acc.map(L::sum)
    }
}

/// A jittered lattice of fluid particles and a few ghosts (spacing 1 cm, h = 1.3 cm)
/// with random velocities, densities and pressures of either sign.
fn world(seed: u64) -> hecs::World {
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut next = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut world = hecs::World::new();
    // One layer in 2D; four along z in 3D (the z components drawn after the others).
    for layer in 0..if DIM == 2 { 1 } else { 4 } {
        for a in 0..9 {
            for b in 0..9 {
                let rho = 1000.0 * (0.97 + 0.06 * next());
                let mut x = dim::xy(a as f64, b as f64) * 0.01
                    + 0.003 * dim::xy(next() - 0.5, next() - 0.5);
                let mut v = dim::xy(next() - 0.5, next() - 0.5);
                if DIM == 3 {
                    x[DIM - 1] = 0.01 * layer as f64 + 0.003 * (next() - 0.5);
                    v[DIM - 1] = next() - 0.5;
                }
                let p = Pressure(2000.0 * (next() - 0.3));
                let c = (Position(x), Velocity(v), Density(rho), Mass(0.1), p);
                if b == 0 {
                    world.spawn((Ghost { source: 0 }, c.0, c.1, c.2, c.3, c.4));
                } else {
                    world.spawn((Fluid, c.0, c.1, c.2, c.3, c.4));
                }
            }
        }
    }
    world
}

/// Record `j`'s position.
fn position(r: &Records, j: usize) -> Vector {
    let mut x = Vector::ZERO;
    for (k, f) in Field::POSITION.into_iter().enumerate() {
        x[k] = r.get(j, f);
    }
    x
}

/// Record `j`'s velocity.
fn velocity(r: &Records, j: usize) -> Vector {
    let mut v = Vector::ZERO;
    for (k, f) in Field::VELOCITY.into_iter().enumerate() {
        v[k] = r.get(j, f);
    }
    v
}

fn eos() -> Tait {
    Tait::new(1000.0, 30.0, 7.0)
}

fn packed(world: &hecs::World, fields: Fields) -> Records {
    let mut r = Records::default();
    r.pack(&Particles::of(world).unwrap(), fields, &eos())
        .unwrap();
    r
}

fn neighbours(r: &Records, i: usize, h: f64) -> Vec<u32> {
    let xi = position(r, i);
    (0..r.len() as u32)
        .filter(|&j| j as usize != i && (xi - position(r, j as usize)).length() < 2.0 * h)
        .collect()
}

/// The scalar pass is the plain loop over the same records, bit for bit; every SIMD
/// set agrees with it to round-off (relative 1e-12 of the sums' scale: the same
/// terms added in another order, ~20 terms), and with each other bit for bit.
#[test]
fn every_instruction_set_sums_the_same_terms() {
    let h = 0.013;
    let k = Wendland::new(h);
    for seed in 0..20 {
        let w = world(seed);
        let r = packed(&w, Probe.reads());
        assert_eq!(r.stride(), 8);
        for i in [10, 40, 70] {
            let js = neighbours(&r, i, h);
            let scalar = Pass::with_isa(&Probe, k, &r, Isa::SCALAR)
                .unwrap()
                .sum(i, &js);
            let mut plain = [0.0; 3];
            let (xi, vi) = (position(&r, i), velocity(&r, i));
            for &j in &js {
                let j = j as usize;
                let xij = xi - position(&r, j);
                let vij = vi - velocity(&r, j);
                let g = k.grad(xij, xij.length());
                let m = r.get(j, Field::Mass);
                plain[0] += m * k.w(xij.length());
                plain[1] += m * vij.dot(g);
                plain[2] += m * r.get(j, Field::PRho2) * g.length();
            }
            assert_eq!(scalar, plain, "seed {seed}, particle {i}");
            let lanes: Vec<[f64; 3]> = Isa::available()
                .into_iter()
                .map(|isa| Pass::with_isa(&Probe, k, &r, isa).unwrap().sum(i, &js))
                .collect();
            for l in &lanes {
                for c in 0..3 {
                    let scale = plain[c].abs().max(1e-3);
                    assert!(
                        (l[c] - plain[c]).abs() <= 1e-12 * scale,
                        "seed {seed}: {l:?} vs {plain:?}"
                    );
                }
                assert_eq!(l.map(f64::to_bits), lanes[0].map(f64::to_bits));
            }
            // Fewer neighbours than lanes: the padding adds nothing.
            for isa in Isa::available() {
                let few = Pass::with_isa(&Probe, k, &r, isa).unwrap().sum(i, &js[..3]);
                let one = Pass::with_isa(&Probe, k, &r, Isa::SCALAR)
                    .unwrap()
                    .sum(i, &js[..3]);
                for c in 0..3 {
                    assert!((few[c] - one[c]).abs() <= 1e-12 * one[c].abs().max(1e-3));
                }
            }
        }
    }
}

/// [`Probe`] compiled for no record layout: its passes find the offsets at run time.
#[derive(Clone)]
struct ProbeAnyLayout;

impl PairTerm for ProbeAnyLayout {
    const LAYOUTS: Layouts = Layouts::NONE;
    type Acc<L: Lane> = [L; 3];
    type Out = [f64; 3];
    fn reads(&self) -> Fields {
        Probe.reads()
    }
    fn zero<L: Lane>(&self) -> [L; 3] {
        Probe.zero()
    }
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, acc: &mut [L; 3]) {
        Probe.pair(me, p, acc)
    }
    fn finish<L: Lane>(&self, me: &Me, acc: [L; 3]) -> [f64; 3] {
        Probe.finish(me, acc)
    }
}

#[test]
fn a_layout_a_term_is_not_compiled_for_sums_the_same_bits() {
    let h = 0.013;
    let k = Wendland::new(h);
    let w = world(3);
    // Records of the momentum layout, which `Probe` (every layout) reads with constant
    // offsets and `ProbeAnyLayout` with offsets found at run time.
    let r = packed(&w, Fields::of(&Field::MOMENTUM));
    assert_eq!(Layouts::of(r.fields()), Layouts::MOMENTUM);
    for isa in Isa::available().into_iter().chain([Isa::SCALAR]) {
        for i in [10, 40, 70] {
            let js = neighbours(&r, i, h);
            let fixed = Pass::with_isa(&Probe, k, &r, isa).unwrap().sum(i, &js);
            let found = Pass::with_isa(&ProbeAnyLayout, k, &r, isa)
                .unwrap()
                .sum(i, &js);
            assert_ne!(fixed, [0.0; 3]);
            assert_eq!(fixed.map(f64::to_bits), found.map(f64::to_bits), "{isa:?}");
        }
    }
}

#[test]
fn layouts_name_the_four_compiled_field_sets() {
    let rho = Fields::of(&[Field::Rho]);
    assert_eq!(Layouts::of(rho), Layouts::FILTER);
    assert_eq!(Layouts::of(Fields::of(&Field::MOMENTUM)), Layouts::MOMENTUM);
    // A vector column in the first DIM slots.
    #[cfg(not(feature = "dim3"))]
    let slots = Fields::of(&[Field::Slot0, Field::Slot1]);
    #[cfg(feature = "dim3")]
    let slots = Fields::of(&[Field::Slot0, Field::Slot1, Field::Slot2]);
    assert_eq!(
        Layouts::of(Fields::of(&Field::MOMENTUM).with(slots)),
        Layouts::GRADIENT
    );
    let far_slots = Fields::of(&[Field::Slot2, Field::Slot3]);
    assert_eq!(
        Layouts::of(Fields::of(&Field::MOMENTUM).with(far_slots)),
        Layouts::SHEAR
    );
    assert!(!Layouts::COMMON.has(Layouts::SHEAR));
    // A viscosity alone with the walls' velocities is packed as the SHEAR layout.
    let av = Fields::of(&[Field::Vx, Field::Vy, Field::Rho, Field::Sound]).with(far_slots);
    assert_eq!(
        Layouts::widen(av),
        Fields::of(&Field::MOMENTUM).with(far_slots)
    );
    // (x, y, m) with pressures only: no compiled layout.
    assert_eq!(Layouts::of(Fields::of(&[Field::PRho2])), Layouts::NONE);
    assert!(Layouts::COMMON.has(Layouts::FILTER.with(Layouts::GRADIENT)));
    assert!(!Layouts::FILTER.has(Layouts::MOMENTUM));
    assert!(Layouts::FILTER.has(Layouts::NONE));
}

/// Every kernel's lane definition gives its scalar values on every instruction set.
#[test]
fn kernels_in_lanes_match_the_scalar_kernels() {
    #[derive(Clone)]
    struct Shape;
    impl PairTerm for Shape {
        type Acc<L: Lane> = [L; 3];
        type Out = [f64; 3];
        fn reads(&self) -> Fields {
            Fields::GEOMETRY
        }
        fn zero<L: Lane>(&self) -> [L; 3] {
            [L::zero(); 3]
        }
        fn pair<L: Lane>(&self, _: &Me, p: &Pair<L>, acc: &mut [L; 3]) {
            acc[0] = acc[0] + p.w;
            acc[1] = acc[1] + p.gx;
            acc[2] = acc[2] + p.gy * p.gy;
        }
        fn finish<L: Lane>(&self, _: &Me, acc: [L; 3]) -> [f64; 3] {
            acc.map(L::sum)
        }
    }
    let w = world(3);
    let r = packed(&w, Fields::GEOMETRY);
    assert_eq!(r.stride(), 4);
    for kind in KernelKind::ALL {
        crate::with_kernel!(kind, 0.013, |k| {
            let js: Vec<u32> = neighbours(&r, 40, 0.02);
            let base = Pass::with_isa(&Shape, k, &r, Isa::SCALAR)
                .unwrap()
                .sum(40, &js);
            for isa in Isa::available() {
                let l = Pass::with_isa(&Shape, k, &r, isa).unwrap().sum(40, &js);
                for c in 0..3 {
                    assert!(
                        (l[c] - base[c]).abs() <= 1e-12 * base[c].abs().max(1.0),
                        "{kind:?} {isa:?}: {l:?} vs {base:?}"
                    );
                }
            }
        });
    }
}

/// Every shipped kernel as the passes run it but the Wendland
/// ([`crate::kernel::DynKernel`], the shape inlined behind a branch) and through its
/// shape's pointers (as a plugin's) sums the same as compiled in, bit for bit, on
/// every path: the same operations in the same order.
#[test]
fn dynamic_kernels_sum_as_compiled_ones_bit_for_bit() {
    use crate::kernel::{
        CubicShape, GaussianShape, KernelShape, Native, PluginKernel, QuadraticShape, QuarticShape,
        WendlandShape,
    };
    fn check<S: KernelShape>(kind: KernelKind) {
        let h = 0.013;
        let native = Native::<S>::new(h);
        let (dynamic, pointers) = (kind.dynamic().at(h), PluginKernel::new::<S>("S").at(h));
        let w = world(5);
        let r = packed(&w, Probe.reads());
        let mut isas = Isa::available();
        isas.push(Isa::SCALAR);
        for isa in isas {
            for i in [31, 40, 58] {
                let js = neighbours(&r, i, 0.5 * kind.support_factor() * h);
                let a = Pass::with_isa(&Probe, native, &r, isa).unwrap().sum(i, &js);
                let b = Pass::with_isa(&Probe, dynamic, &r, isa)
                    .unwrap()
                    .sum(i, &js);
                let c = Pass::with_isa(&Probe, pointers, &r, isa)
                    .unwrap()
                    .sum(i, &js);
                assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits), "{kind:?} {isa:?}");
                assert_eq!(a.map(f64::to_bits), c.map(f64::to_bits), "{kind:?} {isa:?}");
            }
        }
    }
    check::<GaussianShape>(KernelKind::Gaussian);
    check::<QuadraticShape>(KernelKind::Quadratic);
    check::<CubicShape>(KernelKind::Cubic);
    check::<QuarticShape>(KernelKind::Quartic);
    check::<WendlandShape>(KernelKind::Wendland);
}

/// A neighbour index beyond the records panics on every path (before any read).
#[test]
fn an_index_beyond_the_records_panics() {
    let w = world(1);
    let r = packed(&w, Probe.reads());
    let k = Wendland::new(0.013);
    let mut isas = Isa::available();
    isas.push(Isa::SCALAR);
    for isa in isas {
        let pass = Pass::with_isa(&Probe, k, &r, isa).unwrap();
        let bad = [1, 2, r.len() as u32 + 7];
        let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| pass.sum(5, &bad)));
        assert!(caught.is_err(), "{isa:?}");
        let caught =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| pass.sum(r.len(), &[1])));
        assert!(caught.is_err(), "{isa:?}: particle index");
    }
}

/// A pass refuses records without a field its term reads.
#[test]
fn a_missing_field_is_refused() {
    let w = world(1);
    let r = packed(&w, Fields::GEOMETRY);
    let k = Wendland::new(0.013);
    let err = Pass::new(&Probe, k, &r).err().expect("refused");
    assert_eq!(err.missing, Field::Vx);
}

/// A vector column of every particle in slots 0 and 1.
struct Gradient;
impl ColumnKey for Gradient {
    const NAME: &'static str = "Gradient";
    const SLOTS: &'static [Field] = &[Field::Slot0, Field::Slot1];
}

/// A vector column of the ghosts in slots 2 and 3; the fluid's slots hold its velocity.
struct GhostVelocity;
impl ColumnKey for GhostVelocity {
    const NAME: &'static str = "GhostVelocity";
    const SLOTS: &'static [Field] = &[Field::Slot2, Field::Slot3];
}

/// A scalar column that wants slot 1, which `Gradient` holds.
struct Clashing;
impl ColumnKey for Clashing {
    const NAME: &'static str = "Clashing";
    const SLOTS: &'static [Field] = &[Field::Slot1];
}

/// A key that names a world field as its slot.
struct NotASlot;
impl ColumnKey for NotASlot {
    const NAME: &'static str = "NotASlot";
    const SLOTS: &'static [Field] = &[Field::Rho];
}

const GHOST_VELOCITY: Scope = Scope::Ghosts {
    fluid: &[Field::Vx, Field::Vy],
};

/// The packer puts each keyed column's values in its slots, record by record: a
/// per-particle column as given, a ghosts-only one after the fluid, with the fluid's
/// slots holding the fields its scope names (here the velocity). 2D: keyed vector
/// columns hold two components (docs/architecture.md, "Two and three dimensions").
#[cfg(not(feature = "dim3"))]
#[test]
fn keyed_columns_are_packed_into_their_slots() {
    let w = world(7);
    let particles = Particles::of(&w).unwrap();
    let n = particles.joined::<Position>().unwrap().view().len();
    let n_fluid = particles.fluid::<Position>().unwrap().len();
    let v: Vec<DVec2> = {
        let v = particles.joined::<Velocity>().unwrap();
        let v = v.view();
        (0..n as u32).map(|j| v.get(j).0).collect()
    };
    let (pressure, density): (Vec<f64>, Vec<f64>) = {
        let (p, rho) = (
            particles.joined::<Pressure>().unwrap(),
            particles.joined::<Density>().unwrap(),
        );
        let (p, rho) = (p.view(), rho.view());
        (0..n as u32).map(|j| (p.get(j).0, rho.get(j).0)).unzip()
    };
    assert!(n_fluid > 0 && n > n_fluid);
    let grad: Vec<DVec2> = (0..n)
        .map(|j| DVec2::new(j as f64, -2.0 * j as f64))
        .collect();
    let ghost: Vec<DVec2> = (0..n - n_fluid)
        .map(|k| DVec2::new(100.0 + k as f64, 0.5 * k as f64))
        .collect();
    let mut columns = Columns::default();
    columns
        .insert::<Gradient>(Scope::Particles, grad.clone())
        .unwrap();
    columns
        .insert::<GhostVelocity>(GHOST_VELOCITY, ghost.clone())
        .unwrap();
    let fields = Fields::of(&Field::MOMENTUM).with(Fields::of(&Field::SLOTS));
    let mut r = Records::default();
    r.pack_with(&particles, fields, &eos(), &columns).unwrap();
    for j in 0..n {
        assert_eq!(r.get(j, Field::Slot0), grad[j].x, "record {j}");
        assert_eq!(r.get(j, Field::Slot1), grad[j].y, "record {j}");
        let want = if j < n_fluid {
            v[j]
        } else {
            ghost[j - n_fluid]
        };
        assert_eq!(r.get(j, Field::Slot2), want.x, "record {j}");
        assert_eq!(r.get(j, Field::Slot3), want.y, "record {j}");
        assert_eq!(r.get(j, Field::Vx), v[j].x, "record {j}");
        let (p, rho) = (pressure[j], density[j]);
        assert_eq!(r.get(j, Field::PRho2), p / (rho * rho), "record {j}");
        assert_eq!(r.get(j, Field::Sound), eos().sound_speed(rho), "record {j}");
    }
}

/// A slot has one meaning: a second key on a held slot is refused with both names;
/// the same key replaces its values; a key or scope declared wrongly is refused.
#[test]
fn a_column_on_another_keys_slot_is_refused() {
    let mut columns = Columns::default();
    columns
        .insert::<Gradient>(Scope::Particles, vec![Vector::ONE])
        .unwrap();
    let err = columns
        .insert::<Clashing>(Scope::Particles, vec![])
        .unwrap_err();
    assert_eq!(
        err,
        ColumnError::Clash {
            new: "Clashing",
            held: "Gradient",
            slot: Field::Slot1
        }
    );
    assert!(err.to_string().contains("Clashing") && err.to_string().contains("Gradient"));
    columns
        .insert::<Gradient>(Scope::Particles, vec![Vector::X; 3])
        .unwrap();
    assert_eq!(columns.get::<Gradient>(), Some(&[Vector::X; 3][..]));
    assert!(matches!(
        columns.insert::<NotASlot>(Scope::Particles, vec![]),
        Err(ColumnError::Declaration {
            name: "NotASlot",
            ..
        })
    ));
    // A ghosts-only vector column needs two fluid fields, none a slot.
    for fluid in [&[Field::Vx][..], &[Field::Vx, Field::Slot0][..]] {
        assert!(matches!(
            columns.insert::<GhostVelocity>(Scope::Ghosts { fluid }, vec![]),
            Err(ColumnError::Declaration { .. })
        ));
    }
    assert!(!columns.contains::<GhostVelocity>());
    assert_eq!(columns.remove::<Gradient>(), Some(vec![Vector::X; 3]));
    columns
        .insert::<Clashing>(Scope::Particles, vec![])
        .unwrap();
}

/// A pass that reads a slot no column fills, or a column computed for another
/// particle count, is an error, not stale or zero values.
#[test]
fn a_missing_or_stale_column_is_refused() {
    let w = world(3);
    let particles = Particles::of(&w).unwrap();
    let fields = Fields::of(&[Field::Slot0]);
    let mut r = Records::default();
    let err = r
        .pack_with(&particles, fields, &eos(), &Columns::default())
        .unwrap_err();
    assert!(err.to_string().contains("Slot0"), "{err}");
    let mut columns = Columns::default();
    columns
        .insert::<Gradient>(Scope::Particles, vec![Vector::ONE; 5])
        .unwrap();
    let err = r
        .pack_with(&particles, fields, &eos(), &columns)
        .unwrap_err();
    assert!(err.to_string().contains("Gradient holds 5 values"), "{err}");
    let mut columns = Columns::default();
    columns
        .insert::<GhostVelocity>(GHOST_VELOCITY, vec![Vector::ONE; 2])
        .unwrap();
    let err = r
        .pack_with(&particles, Fields::of(&[Field::Slot3]), &eos(), &columns)
        .unwrap_err();
    assert!(
        err.to_string().contains("GhostVelocity holds 2 values"),
        "{err}"
    );
}

/// A key with three slots: refused (a column is a scalar or a vector).
#[cfg(not(feature = "dim3"))]
struct ThreeSlots;
#[cfg(not(feature = "dim3"))]
impl ColumnKey for ThreeSlots {
    const NAME: &'static str = "ThreeSlots";
    const SLOTS: &'static [Field] = &[Field::Slot0, Field::Slot1, Field::Slot2];
}

/// A pass that reads only a ghosts-only column's slots still gets the fluid's own
/// fields there (the packer reads the velocity for it though the pass does not), and
/// the store's accessors see what was stored. 2D, as above.
#[cfg(not(feature = "dim3"))]
#[test]
fn a_ghost_column_alone_carries_the_fluids_own_fields() {
    let w = world(11);
    let particles = Particles::of(&w).unwrap();
    let n_fluid = particles.fluid::<Position>().unwrap().len();
    let n = particles.joined::<Position>().unwrap().view().len();
    let fluid_v: Vec<DVec2> = particles
        .fluid::<Velocity>()
        .unwrap()
        .iter()
        .map(|v| v.0)
        .collect();
    let mut columns = Columns::default();
    let ghost = vec![DVec2::new(-1.0, 2.0); n - n_fluid];
    columns
        .insert::<GhostVelocity>(GHOST_VELOCITY, ghost.clone())
        .unwrap();
    assert!(columns.contains::<GhostVelocity>() && !columns.contains::<Gradient>());
    assert_eq!(columns.heap_bytes(), ghost.capacity() * 16);
    columns.get_mut::<GhostVelocity>().unwrap()[0] = DVec2::new(5.0, 6.0);
    assert!(columns.get_mut::<Gradient>().is_none());
    let mut r = Records::default();
    r.pack_with(&particles, Fields::of(&Field::SLOTS[2..]), &eos(), &columns)
        .unwrap();
    assert!(!r.fields().contains(Field::Vx));
    for (j, v) in fluid_v.iter().enumerate() {
        assert_eq!((r.get(j, Field::Slot2), r.get(j, Field::Slot3)), (v.x, v.y));
    }
    assert_eq!(r.get(n_fluid, Field::Slot2), 5.0);
    assert_eq!(r.get(n - 1, Field::Slot3), 2.0);
    assert!(matches!(
        columns.insert::<ThreeSlots>(Scope::Particles, vec![]),
        Err(ColumnError::Declaration {
            name: "ThreeSlots",
            ..
        })
    ));
}

/// A symmetric test term: i sums m_j W_ij, and gives neighbour j, in every slot k of
/// its share, m_i W_ij (k + 1) x_ij[k mod DIM], so that each slot of each lane has a
/// value of its own.
#[derive(Clone)]
struct Shared;

impl PairTerm for Shared {
    type Acc<L: Lane> = L;
    type Out = f64;
    fn reads(&self) -> Fields {
        Fields::GEOMETRY
    }
    fn zero<L: Lane>(&self) -> L {
        L::zero()
    }
    fn pair<L: Lane>(&self, _: &Me, p: &Pair<L>, acc: &mut L) {
        *acc = *acc + p.j(Field::Mass) * p.w;
    }
    fn finish<L: Lane>(&self, _: &Me, acc: L) -> f64 {
        acc.sum()
    }
    const SYMMETRIC: bool = true;
    fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, acc: &mut L) -> Share<L> {
        self.pair(me, p, acc);
        let (x, mw) = (p.x_ij(), me.lanes::<L>(Field::Mass) * p.w);
        std::array::from_fn(|k| mw * L::splat((k + 1) as f64) * x[k % DIM])
    }
}

/// Each pair once (`Pass::sum_both`): i's own sum is the whole-list sum over its
/// upper neighbours, and every neighbour's record receives exactly the shares the
/// plain loop gives it, slot by slot, on every instruction set (to round-off:
/// relative 1e-12, the same terms in another order; the SIMD sets bit for bit alike),
/// groups shorter than eight included. In 3D a share has two quads of slots, which the
/// SIMD scatters transpose one after the other.
#[test]
fn each_pair_once_hands_every_slot_to_its_neighbour() {
    let h = 0.013;
    let k = Wendland::new(h);
    let w = world(5);
    let r = packed(&w, Fields::GEOMETRY);
    let n = r.len();
    let mut results: Vec<Vec<[f64; SHARE]>> = Vec::new();
    for isa in [Isa::SCALAR].into_iter().chain(Isa::available()) {
        let pass = Pass::with_isa(&Shared, k, &r, isa).unwrap();
        let mut records = vec![[0.0; SHARE]; n];
        let mut plain = vec![[0.0; SHARE]; n];
        for i in 0..n {
            let upper: Vec<u32> = neighbours(&r, i, h)
                .into_iter()
                .filter(|&j| j as usize > i)
                .collect();
            let mut shares = Shares {
                start: 0,
                records: &mut records,
            };
            let own = pass.sum_both(i, &upper, &mut shares);
            let whole = pass.sum(i, &upper);
            assert!(
                (own - whole).abs() <= 1e-12 * whole.abs().max(1e-3),
                "{isa:?} {i}"
            );
            for &j in &upper {
                let j = j as usize;
                let x = position(&r, i) - position(&r, j);
                let mw = r.get(i, Field::Mass) * k.w(x.length());
                for s in 0..SHARE {
                    plain[j][s] += mw * (s + 1) as f64 * x[s % DIM];
                }
            }
        }
        for j in 0..n {
            for s in 0..SHARE {
                let (got, want) = (records[j][s], plain[j][s]);
                assert!(
                    (got - want).abs() <= 1e-12 * want.abs().max(1e-3),
                    "{isa:?}: record {j} slot {s}: {got} against {want}"
                );
            }
        }
        results.push(records);
    }
    for simd in results.iter().skip(2) {
        assert!(simd
            .iter()
            .flatten()
            .zip(results[1].iter().flatten())
            .all(|(a, b)| a.to_bits() == b.to_bits()));
    }
}

/// A scalar column of the wall particles alone (zero for the fluid), in slot 2.
struct WallOnly;
impl ColumnKey for WallOnly {
    const NAME: &'static str = "WallOnly";
    const SLOTS: &'static [Field] = &[Field::Slot2];
}

/// A scalar column that is zero for the fluid but one particle, in slot 0.
struct AlmostWallOnly;
impl ColumnKey for AlmostWallOnly {
    const NAME: &'static str = "AlmostWallOnly";
    const SLOTS: &'static [Field] = &[Field::Slot0];
}

/// sum_j m_j W_ij (s2_j + s0_j) over the two columns' slots, and the groups the pass
/// called fluid-only.
#[derive(Clone)]
struct SlotProbe;

impl PairTerm for SlotProbe {
    type Acc<L: Lane> = (L, usize);
    type Out = (f64, usize);
    fn reads(&self) -> Fields {
        Fields::of(&Field::MOMENTUM).with(Fields::of(&[Field::Slot0, Field::Slot2]))
    }
    fn zero<L: Lane>(&self) -> (L, usize) {
        (L::zero(), 0)
    }
    fn pair<L: Lane>(&self, _: &Me, p: &Pair<L>, acc: &mut (L, usize)) {
        let s = p.j(Field::Slot2) + p.j(Field::Slot0);
        acc.0 = acc.0 + p.j(Field::Mass) * p.w * s;
        acc.1 += p.fluid_only() as usize;
    }
    fn finish<L: Lane>(&self, _: &Me, acc: (L, usize)) -> (f64, usize) {
        (acc.0.sum(), acc.1)
    }
}

/// A group of fluid neighbours leaves a column of the walls alone ungathered (its
/// slots read 0, as the records hold), and every group holding a wall particle
/// gathers it, in any list order: the sums equal the plain loop's on every
/// instruction set (1e-12 relative: the same terms in another order). A column
/// nonzero for one fluid particle is always gathered.
#[test]
fn fluid_groups_skip_a_column_of_the_walls_alone() {
    let h = 0.013;
    let k = Wendland::new(h);
    let w = world(5);
    let particles = Particles::of(&w).unwrap();
    let n = particles.joined::<Position>().unwrap().view().len();
    let n_fluid = particles.fluid::<Position>().unwrap().len();
    let value = |j: usize| match j < n_fluid {
        true => 0.0,
        false => 1.0 + j as f64,
    };
    let mut columns = Columns::default();
    let walls: Vec<Vector> = (0..n).map(|j| Vector::X * value(j)).collect();
    columns.insert::<WallOnly>(Scope::Particles, walls).unwrap();
    let mut almost = vec![Vector::ZERO; n];
    almost[n_fluid / 2] = Vector::X * 3.0;
    columns
        .insert::<AlmostWallOnly>(Scope::Particles, almost.clone())
        .unwrap();
    let mut r = Records::default();
    r.pack_with(&particles, SlotProbe.reads(), &eos(), &columns)
        .unwrap();
    assert_eq!(r.n_fluid(), n_fluid);
    assert!(r.fluid_zero().contains(Field::Slot2));
    assert!(!r.fluid_zero().contains(Field::Slot0));
    // The fluid particle nearest the first wall particle (index n_fluid), with that
    // wall particle alone among its walls: the group holding it has n_fluid as its
    // largest index.
    let first_wall = position(&r, n_fluid);
    let near = (0..n_fluid)
        .min_by(|&a, &b| {
            let d = |j| (position(&r, j) - first_wall).length();
            d(a).total_cmp(&d(b))
        })
        .unwrap();
    let mut lists = Vec::new();
    for i in [near, n_fluid / 2, 10, 40, 70] {
        let js = neighbours(&r, i, h);
        let mut reversed = js.clone();
        reversed.reverse();
        let first: Vec<u32> = js
            .iter()
            .copied()
            .filter(|&j| j as usize <= n_fluid)
            .collect();
        lists.extend([(i, js), (i, reversed), (i, first)]);
    }
    let mut fluid_groups = 0;
    for (i, js) in &lists {
        let xi = position(&r, *i);
        let plain: f64 = js
            .iter()
            .map(|&j| {
                let j = j as usize;
                let s = value(j) + almost[j].x;
                r.get(j, Field::Mass) * k.w((xi - position(&r, j)).length()) * s
            })
            .sum();
        assert!(plain > 0.0 || *i != near, "the test's list meets no wall");
        for isa in Isa::available().into_iter().chain([Isa::SCALAR]) {
            let (sum, groups) = Pass::with_isa(&SlotProbe, k, &r, isa).unwrap().sum(*i, js);
            assert!(
                (sum - plain).abs() <= 1e-12 * plain.abs().max(1e-3),
                "{isa:?}, particle {i}: {sum} against {plain}"
            );
            fluid_groups += groups;
        }
    }
    assert!(fluid_groups > 0, "no group was fluid-only");
}
