//! The pair-interaction layer: every sum over a particle's neighbours (the momentum
//! and continuity equations, the density filters, ...) is a [`PairTerm`] written once
//! over a [`Lane`] type and run by a [`Pass`]:
//!
//! - on `f64`, one neighbour at a time (the scalar path: other processors, or
//!   `SPH_NO_SIMD=1`);
//! - on eight lanes with AVX-512 or AVX2 (the SIMD path, chosen at run time), which
//!   reads neighbour j's fields from its packed record with gathers.
//!
//! The two paths evaluate the same source, operation for operation; they differ only
//! in the order a particle's pairs are added (docs/architecture.md, "Determinism").
//!
//! A pass works on [`Records`]: the particles (fluid, then ghosts: the joint numbering
//! of the neighbour lists) packed with the [`Field`]s its terms read, one record per
//! particle, so a neighbour's fields come from one cache line.

/// Runs `$body` for each field index `f` (0..Field::COUNT), written out. The pair
/// loop's field loops must unroll: then, for a field set known at compile time, which
/// fields are wanted and their offsets are constants and `Pair`'s fields stay in
/// registers. A counted loop of twelve was past the compiler's unrolling: the pair
/// sums took 20-35 % longer when the field count went from ten to twelve.
#[cfg(not(feature = "dim3"))]
macro_rules! each_field {
    (|$f:ident| $body:expr) => {
        each_field!(@ $f, $body, 0 1 2 3 4 5 6 7 8 9 10 11)
    };
    (@ $f:ident, $body:expr, $($k:literal)*) => {{
        const _: () = assert!(Field::COUNT == [$($k),*].len());
        $({
            let $f: usize = $k;
            $body;
        })*
    }};
}

/// The same for the fourteen fields of the 3D build.
#[cfg(feature = "dim3")]
macro_rules! each_field {
    (|$f:ident| $body:expr) => {
        each_field!(@ $f, $body, 0 1 2 3 4 5 6 7 8 9 10 11 12 13)
    };
    (@ $f:ident, $body:expr, $($k:literal)*) => {{
        const _: () = assert!(Field::COUNT == [$($k),*].len());
        $({
            let $f: usize = $k;
            $body;
        })*
    }};
}

mod columns;
pub mod lane;
mod plugin;
pub mod rates;
mod record;
#[cfg(target_arch = "x86_64")]
mod x86;

pub use columns::{ColumnError, ColumnKey, Columns, Scope};
pub use lane::{whole_pow, Lane};
pub(crate) use plugin::{shape, shape_fn};
pub use plugin::{NoTerms, PluginTerm, ShapeFn, WithPlugins};
#[cfg(feature = "dim3")]
pub use rates::SHARE_AZ;
pub use rates::{EquationsOfMotion, RateSums, RateTerm, Rates, SHARE_AX, SHARE_AY, SHARE_DRHO};
pub use record::{Field, Fields, Records};

use crate::kernel::Kernel;

/// A set of the record layouts (field sets) that pair loops are compiled for with
/// constant offsets: each costs a copy of a term's loop per kernel and instruction
/// set, so a term names those its records can have ([`PairTerm::LAYOUTS`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layouts(u8);

impl Layouts {
    /// No layout: the loop that finds the offsets at run time only.
    pub const NONE: Layouts = Layouts(0);
    /// The momentum equation's fields ([`Field::MOMENTUM`]): one 64-byte record.
    pub const MOMENTUM: Layouts = Layouts(1);
    /// The same with a vector column in the first DIM slots (0 and 1 in 2D, 0-2 in
    /// 3D): the momentum pass with delta-SPH's density gradient, or with the wall
    /// particles' normals (`WallPressure(pair_mirror: true)`).
    pub const GRADIENT: Layouts = Layouts(2);
    /// The density filters' (x, y, rho, m).
    pub const FILTER: Layouts = Layouts(4);
    /// Every layout above.
    pub const COMMON: Layouts = Layouts(7);
    /// The momentum record with a vector column in slots 2 and 3 (a viscous term that
    /// reads the walls' no-slip velocity). Not in [`Layouts::COMMON`]: only the
    /// compiled term sets with a viscous term name it.
    pub const SHEAR: Layouts = Layouts(8);

    const MOMENTUM_BITS: u16 = Fields::of(&Field::MOMENTUM).bits();
    #[cfg(not(feature = "dim3"))]
    const GRADIENT_BITS: u16 = Fields::of(&Field::MOMENTUM)
        .with(Fields::of(&[Field::Slot0, Field::Slot1]))
        .bits();
    #[cfg(feature = "dim3")]
    const GRADIENT_BITS: u16 = Fields::of(&Field::MOMENTUM)
        .with(Fields::of(&[Field::Slot0, Field::Slot1, Field::Slot2]))
        .bits();
    const FILTER_BITS: u16 = Fields::GEOMETRY.with(Fields::of(&[Field::Rho])).bits();
    const SHEAR_BITS: u16 = Fields::of(&Field::MOMENTUM)
        .with(Fields::of(&[Field::Slot2, Field::Slot3]))
        .bits();

    /// The layout of records packed with `reads` (and the geometry, always packed),
    /// if it is one of the above; else [`Layouts::NONE`].
    pub const fn of(reads: Fields) -> Layouts {
        match reads.with(Fields::GEOMETRY).bits() {
            Self::MOMENTUM_BITS => Self::MOMENTUM,
            Self::GRADIENT_BITS => Self::GRADIENT,
            Self::FILTER_BITS => Self::FILTER,
            Self::SHEAR_BITS => Self::SHEAR,
            _ => Self::NONE,
        }
    }

    /// The field set to pack for a pass that reads `reads`: the smallest compiled
    /// layout that holds them (the density filters', the momentum record, then the
    /// momentum record with a vector column in the first DIM slots, then in slots 2-3), so that the pass runs a loop with
    /// offsets known when compiled (an artificial viscosity alone, say, reads the
    /// momentum record less p / rho^2; packing the one field more costs far less than
    /// finding the offsets at run time); `reads` with the geometry where no layout
    /// holds them.
    pub const fn widen(reads: Fields) -> Fields {
        let bits = reads.with(Fields::GEOMETRY).bits();
        if bits & !Self::FILTER_BITS == 0 {
            Fields(Self::FILTER_BITS)
        } else if bits & !Self::MOMENTUM_BITS == 0 {
            Fields(Self::MOMENTUM_BITS)
        } else if bits & !Self::GRADIENT_BITS == 0 {
            Fields(Self::GRADIENT_BITS)
        } else if bits & !Self::SHEAR_BITS == 0 {
            Fields(Self::SHEAR_BITS)
        } else {
            Fields(bits)
        }
    }

    /// Both sets.
    pub const fn with(self, other: Layouts) -> Layouts {
        Layouts(self.0 | other.0)
    }

    /// Whether this set holds every layout of `other`.
    pub const fn has(self, other: Layouts) -> bool {
        self.0 & other.0 == other.0
    }
}

/// The instruction set a pass sums with. A value other than `Scalar` can only be made
/// on a processor that has it, so the SIMD code it selects is sound to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Isa(IsaKind);

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum IsaKind {
    Scalar,
    #[cfg(target_arch = "x86_64")]
    Avx512,
    #[cfg(target_arch = "x86_64")]
    Avx2,
}

impl Isa {
    /// One neighbour at a time, on any processor.
    pub const SCALAR: Isa = Isa(IsaKind::Scalar);

    /// The widest this processor supports: AVX-512 (F and VL), else AVX2, else scalar;
    /// scalar with `SPH_NO_SIMD` set, AVX2 at most with `SPH_SIMD=avx2` (to measure
    /// that path). Worked out once per process.
    pub fn detect() -> Isa {
        static ISA: std::sync::OnceLock<Isa> = std::sync::OnceLock::new();
        *ISA.get_or_init(|| {
            let avx2_only = std::env::var_os("SPH_SIMD").is_some_and(|v| v == "avx2");
            let all = Isa::available();
            all.into_iter()
                .find(|isa| !(avx2_only && isa.name() == "avx512"))
                .filter(|_| simd_allowed())
                .unwrap_or(Isa::SCALAR)
        })
    }

    /// Every SIMD instruction set this processor can run, widest first (for tests
    /// comparing them); empty off x86-64.
    pub fn available() -> Vec<Isa> {
        #[allow(unused_mut)]
        let mut all = Vec::new();
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx512f") && has!("avx512vl") {
                all.push(Isa(IsaKind::Avx512));
            }
            if has!("avx2") {
                all.push(Isa(IsaKind::Avx2));
            }
        }
        all
    }

    /// `scalar`, `avx512` or `avx2`.
    pub fn name(self) -> &'static str {
        match self.0 {
            IsaKind::Scalar => "scalar",
            #[cfg(target_arch = "x86_64")]
            IsaKind::Avx512 => "avx512",
            #[cfg(target_arch = "x86_64")]
            IsaKind::Avx2 => "avx2",
        }
    }
}

/// False when the environment variable `SPH_NO_SIMD` is set (to any value): every
/// SIMD path (pair sums, neighbour scan) then runs its scalar code.
pub fn simd_allowed() -> bool {
    static ALLOWED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ALLOWED.get_or_init(|| std::env::var_os("SPH_NO_SIMD").is_none())
}

/// Particle i's packed fields, as a term reads them: `me.get(Field::Rho)` is rho_i,
/// the same in every lane.
#[derive(Clone, Copy, Debug)]
pub struct Me {
    values: [f64; Field::COUNT],
    /// i's index in the joint numbering.
    pub index: usize,
}

impl Me {
    /// Field `f` of particle i (0 if the records do not hold it).
    #[inline(always)]
    pub fn get(&self, f: Field) -> f64 {
        self.values[f as usize]
    }
    /// The same, in every lane.
    #[inline(always)]
    pub fn lanes<L: Lane>(&self, f: Field) -> L {
        L::splat(self.get(f))
    }
}

/// A group of neighbours j of particle i (one, or up to eight in lanes) with the
/// geometry every term shares: x_ij = x_i - x_j, r_ij, q = r/h, W_ij and
/// grad_i W_ij, and the fields of j the pass's term reads (each gathered once per
/// group, however many terms read it). The lanes of a group beyond its neighbours
/// hold a padding particle of zero mass beyond the support (W = grad W = 0), so they
/// add nothing to a term that is weighted by m_j, W or grad W.
pub struct Pair<L: Lane> {
    pub dx: L,
    pub dy: L,
    /// x_ij's z component (3D).
    #[cfg(feature = "dim3")]
    pub dz: L,
    pub r: L,
    pub q: L,
    /// W(r_ij).
    pub w: L,
    /// grad_i W_ij = x_ij (dW/dr)/r.
    pub gx: L,
    pub gy: L,
    /// grad_i W_ij's z component (3D).
    #[cfg(feature = "dim3")]
    pub gz: L,
    fields: [L; Field::COUNT],
    fluid_only: bool,
}

impl<L: Lane> Pair<L> {
    /// Field `f` of the neighbours (the padding value in unused lanes; 0 for a field
    /// the term does not declare in [`PairTerm::reads`]).
    #[inline(always)]
    pub fn j(&self, f: Field) -> L {
        self.fields[f as usize]
    }

    /// True when every neighbour of the group is a fluid particle and the records
    /// hold a keyed column that is zero for the whole fluid ([`Records::fluid_zero`]),
    /// so that its slots read 0 in every lane; false says nothing. A term whose work
    /// on such a column vanishes for the fluid may skip it.
    #[inline(always)]
    pub fn fluid_only(&self) -> bool {
        self.fluid_only
    }

    /// The relative velocity v_ij = v_i - v_j (the term must read `Vx` and `Vy`).
    #[inline(always)]
    pub fn v_ij(&self, me: &Me) -> (L, L) {
        (
            me.lanes::<L>(Field::Vx) - self.j(Field::Vx),
            me.lanes::<L>(Field::Vy) - self.j(Field::Vy),
        )
    }

    /// x_ij = x_i - x_j by component, in any dimension.
    #[inline(always)]
    pub fn x_ij(&self) -> [L; crate::dim::DIM] {
        #[cfg(not(feature = "dim3"))]
        return [self.dx, self.dy];
        #[cfg(feature = "dim3")]
        return [self.dx, self.dy, self.dz];
    }

    /// grad_i W_ij by component, in any dimension.
    #[inline(always)]
    pub fn grad(&self) -> [L; crate::dim::DIM] {
        #[cfg(not(feature = "dim3"))]
        return [self.gx, self.gy];
        #[cfg(feature = "dim3")]
        return [self.gx, self.gy, self.gz];
    }

    /// v_ij = v_i - v_j by component, in any dimension (the term must read the
    /// velocity, [`Field::VELOCITY`]).
    #[inline(always)]
    pub fn velocity_ij(&self, me: &Me) -> [L; crate::dim::DIM] {
        // Written out, not `array::map`, which the pair loop does not inline (it cost
        // the AVX-512 loop 9 %).
        let (x, y) = self.v_ij(me);
        #[cfg(not(feature = "dim3"))]
        return [x, y];
        #[cfg(feature = "dim3")]
        return [x, y, me.lanes::<L>(Field::Vz) - self.j(Field::Vz)];
    }
}

/// a . b of two vectors of lanes, the components added in order (x first), as the 2D
/// terms write `ax * bx + ay * by`.
#[inline(always)]
pub fn dot<L: Lane>(a: [L; crate::dim::DIM], b: [L; crate::dim::DIM]) -> L {
    #[cfg(not(feature = "dim3"))]
    return a[0] * b[0] + a[1] * b[1];
    #[cfg(feature = "dim3")]
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/// `v` in every lane, by component (a constant vector of a term, such as rho_0 g).
#[inline(always)]
pub fn splat<L: Lane>(v: [f64; crate::dim::DIM]) -> [L; crate::dim::DIM] {
    #[cfg(not(feature = "dim3"))]
    return [L::splat(v[0]), L::splat(v[1])];
    #[cfg(feature = "dim3")]
    return [L::splat(v[0]), L::splat(v[1]), L::splat(v[2])];
}

/// `k v`, by component.
#[inline(always)]
pub fn scale<L: Lane>(k: L, v: [L; crate::dim::DIM]) -> [L; crate::dim::DIM] {
    #[cfg(not(feature = "dim3"))]
    return [k * v[0], k * v[1]];
    #[cfg(feature = "dim3")]
    return [k * v[0], k * v[1], k * v[2]];
}

/// A sum over a particle's neighbours, written once over the lane type.
///
/// `zero`, `pair` and `finish` are called for one particle i: `pair` for each group
/// of neighbours, in list order (the group's lanes are neighbours l, l + WIDTH, ...
/// of the list in the SIMD path), `finish` once with the lanes of the accumulator.
/// Implementations are monomorphised per lane type and kernel: no dynamic dispatch
/// per pair.
pub trait PairTerm: Sync + Clone {
    /// The record layouts its loop is compiled for with constant field offsets
    /// ([`Layouts`]); records of any other layout are read with offsets found at run
    /// time, at the same results. The default, every common layout, suits a term
    /// whose records another stage may have packed with more fields than it reads.
    const LAYOUTS: Layouts = Layouts::COMMON;
    /// The per-particle accumulator in lanes.
    type Acc<L: Lane>: Copy;
    /// The per-particle result.
    type Out: Send;
    /// The fields of i and j the term reads (x, y and mass are always packed).
    fn reads(&self) -> Fields;
    /// The accumulator before the first neighbour.
    fn zero<L: Lane>(&self) -> Self::Acc<L>;
    /// Adds one group of neighbours.
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, acc: &mut Self::Acc<L>);
    /// The result from the accumulated lanes (add them with [`Lane::sum`]) and i's own
    /// fields (for a self contribution).
    fn finish<L: Lane>(&self, me: &Me, acc: Self::Acc<L>) -> Self::Out;

    /// Whether [`PairTerm::pair_both`] gives neighbour j's share of each pair from the
    /// same evaluation, so that a pass can compute each pair once ([`Pass::sum_both`]).
    const SYMMETRIC: bool = false;
    /// Adds one group of neighbours to i's accumulator, as [`PairTerm::pair`], and
    /// returns each neighbour j's share of the same pairs: the values added to j's own
    /// sums ([`Shares`]; what each slot means is the term's). Only called when
    /// [`PairTerm::SYMMETRIC`]; the default adds i's share and gives j nothing.
    #[inline(always)]
    fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, acc: &mut Self::Acc<L>) -> Share<L> {
        self.pair(me, p, acc);
        [L::zero(); SHARE]
    }
    /// The result of a pass that computed each pair once ([`Pass::sum_both`]); the
    /// default is [`PairTerm::finish`].
    #[inline(always)]
    fn finish_both<L: Lane>(&self, me: &Me, acc: Self::Acc<L>) -> Self::Out {
        self.finish(me, acc)
    }
}

/// Slots of a neighbour's [`Share`]: four in 2D (one 256-bit add per neighbour),
/// eight in 3D (dv/dt's third component needs a fifth).
pub const SHARE: usize = 4 * (crate::dim::DIM - 1);

/// Neighbour j's share of a group of pairs, in lanes (lane l for neighbour l of the
/// group): the values added to j's own sums, [`SHARE`] slots whose meaning is the
/// term's.
pub type Share<L> = [L; SHARE];

/// Where a pass that computes each pair once ([`Pass::sum_both`]) adds each
/// neighbour's share of a pair: records of [`SHARE`] sums per particle, a window of
/// them from particle `start` (joint numbering) on.
pub struct Shares<'a> {
    pub start: usize,
    pub records: &'a mut [[f64; SHARE]],
}

impl Shares<'_> {
    /// Adds `values` to particle `j`'s record.
    ///
    /// # Panics
    /// If `j` is outside the window.
    #[inline(always)]
    pub fn add(&mut self, j: usize, values: [f64; SHARE]) {
        let r = &mut self.records[j.wrapping_sub(self.start)];
        for k in 0..SHARE {
            r[k] += values[k];
        }
    }
}

/// A term summed together with the count of neighbours nearer than `radius`, in the
/// same loop (the distance is computed for the term anyway): one compare and one add
/// per group. Neighbour lists with a skin hold pairs beyond the kernel support; this
/// counts those within it without a pass of its own. With `KERNEL_SUM` the loop also
/// sums m_j W_ij (the density summation's sum, i excluded), for a filter that would
/// otherwise take a pass of its own; without, the sum is 0 and costs nothing.
#[derive(Clone, Copy, Debug)]
pub struct Counted<T, const KERNEL_SUM: bool = false> {
    pub term: T,
    /// [m]
    pub radius: f64,
}

impl<T: PairTerm, const KERNEL_SUM: bool> PairTerm for Counted<T, KERNEL_SUM> {
    const LAYOUTS: Layouts = T::LAYOUTS;
    type Acc<L: Lane> = (T::Acc<L>, L, L);
    /// The term's result, the count and sum_j m_j W_ij [kg/m^2].
    type Out = (T::Out, u32, f64);

    fn reads(&self) -> Fields {
        self.term.reads()
    }
    #[inline(always)]
    fn zero<L: Lane>(&self) -> Self::Acc<L> {
        (self.term.zero(), L::zero(), L::zero())
    }
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, acc: &mut Self::Acc<L>) {
        self.term.pair(me, p, &mut acc.0);
        // The padding lanes lie four supports away: not counted, and of zero mass.
        acc.1 = acc.1 + L::splat(1.0).keep(p.r.lt(L::splat(self.radius)));
        if KERNEL_SUM {
            acc.2 = acc.2 + p.j(Field::Mass) * p.w;
        }
    }
    #[inline(always)]
    fn finish<L: Lane>(&self, me: &Me, acc: Self::Acc<L>) -> Self::Out {
        (self.term.finish(me, acc.0), acc.1.sum() as u32, acc.2.sum())
    }

    /// Without the kernel sum: a share has no slot for it.
    const SYMMETRIC: bool = T::SYMMETRIC && !KERNEL_SUM;
    /// The term's share, with the count in slot [`Counted::COUNT_SLOT`] (which the
    /// term must leave 0).
    #[inline(always)]
    fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, acc: &mut Self::Acc<L>) -> Share<L> {
        let mut share = self.term.pair_both(me, p, &mut acc.0);
        let within = L::splat(1.0).keep(p.r.lt(L::splat(self.radius)));
        acc.1 = acc.1 + within;
        share[Self::COUNT_SLOT] = within;
        share
    }
    #[inline(always)]
    fn finish_both<L: Lane>(&self, me: &Me, acc: Self::Acc<L>) -> Self::Out {
        (
            self.term.finish_both(me, acc.0),
            acc.1.sum() as u32,
            acc.2.sum(),
        )
    }
}

impl<T, const KERNEL_SUM: bool> Counted<T, KERNEL_SUM> {
    /// The slot of a neighbour's [`Share`] that counts the pair (1 within the radius).
    pub const COUNT_SLOT: usize = 3;
}

/// A term summed over neighbours with one kernel, on records packed for it, with an
/// instruction set. Sound for any input: the records must hold what the term reads
/// ([`Pass::new`] checks), and every neighbour index is checked against the records
/// before it is gathered (a wrong index panics).
pub struct Pass<'a, T: PairTerm, K: Kernel> {
    term: &'a T,
    kernel: K,
    records: &'a Records,
    isa: Isa,
    /// How far beyond i the padding particle sits: four supports.
    pad_shift: f64,
    /// The fields gathered for each group (x, y, m and those the term reads) and
    /// their offsets in a record, worked out once per pass.
    wanted: [bool; Field::COUNT],
    offsets: [usize; Field::COUNT],
}

/// The records do not hold a field that a term reads.
#[derive(Debug, thiserror::Error)]
#[error("the packed particles lack the field {missing:?} that a pair term reads")]
pub struct MissingField {
    pub missing: Field,
}

impl<'a, T: PairTerm, K: Kernel> Pass<'a, T, K> {
    /// A pass of `term` with `kernel` over `records`, with the processor's widest
    /// instruction set ([`Isa::detect`]).
    pub fn new(term: &'a T, kernel: K, records: &'a Records) -> Result<Self, MissingField> {
        Self::with_isa(term, kernel, records, Isa::detect())
    }

    /// The same with a given instruction set (tests compare them).
    pub fn with_isa(
        term: &'a T,
        kernel: K,
        records: &'a Records,
        isa: Isa,
    ) -> Result<Self, MissingField> {
        if let Some(missing) = records.lacks(term.reads()) {
            return Err(MissingField { missing });
        }
        Ok(Self {
            term,
            kernel,
            records,
            isa,
            pad_shift: 4.0 * kernel.support(),
            wanted: Field::ALL.map(|f| term.reads().with(Fields::GEOMETRY).contains(f)),
            offsets: Field::ALL.map(|f| records.offset(f)),
        })
    }

    /// The term's sum for particle `i` (joint numbering) over `neighbours` (joint
    /// indices, i excluded).
    ///
    /// # Panics
    /// If `i` or a neighbour index is beyond the records.
    #[inline]
    pub fn sum(&self, i: usize, neighbours: &[u32]) -> T::Out {
        self.sum_with::<false>(i, neighbours, None)
    }

    /// The term's sum for particle `i` over `upper`, its neighbours of higher index,
    /// with each pair computed once: i's share summed as by [`Pass::sum`] (with
    /// [`PairTerm::finish_both`]), each neighbour's share added to its record in
    /// `shares` (in list order, one group of neighbours after the other).
    ///
    /// # Panics
    /// If the term is not [`PairTerm::SYMMETRIC`], if a neighbour is outside the
    /// window of `shares`, or as [`Pass::sum`].
    #[inline]
    pub fn sum_both(&self, i: usize, upper: &[u32], shares: &mut Shares) -> T::Out {
        assert!(T::SYMMETRIC, "a pair term without neighbours' shares");
        self.sum_with::<true>(i, upper, Some(shares))
    }

    #[inline(always)]
    fn sum_with<const BOTH: bool>(
        &self,
        i: usize,
        neighbours: &[u32],
        shares: Option<&mut Shares>,
    ) -> T::Out {
        // The layouts `T` is compiled for (`PairTerm::LAYOUTS`) get a loop with known
        // offsets and no test per field; any other is read with offsets found at run
        // time. The tests are on constants, so a layout a term is not compiled for
        // costs no code.
        macro_rules! on {
            ($f:ident) => {{
                let bits = self.records.fields().bits();
                if const { T::LAYOUTS.has(Layouts::MOMENTUM) } && bits == Layouts::MOMENTUM_BITS {
                    return $f::<T, K, { Layouts::MOMENTUM_BITS }, BOTH>(
                        self, i, neighbours, shares,
                    );
                }
                if const { T::LAYOUTS.has(Layouts::GRADIENT) } && bits == Layouts::GRADIENT_BITS {
                    return $f::<T, K, { Layouts::GRADIENT_BITS }, BOTH>(
                        self, i, neighbours, shares,
                    );
                }
                if const { T::LAYOUTS.has(Layouts::FILTER) } && bits == Layouts::FILTER_BITS {
                    return $f::<T, K, { Layouts::FILTER_BITS }, BOTH>(self, i, neighbours, shares);
                }
                if const { T::LAYOUTS.has(Layouts::SHEAR) } && bits == Layouts::SHEAR_BITS {
                    return $f::<T, K, { Layouts::SHEAR_BITS }, BOTH>(self, i, neighbours, shares);
                }
                $f::<T, K, 0, BOTH>(self, i, neighbours, shares)
            }};
        }
        // SAFETY: f64 needs no instructions beyond the baseline; an `Isa` of a SIMD
        // kind exists only where the processor has it.
        unsafe {
            match self.isa.0 {
                IsaKind::Scalar => {
                    let scalar = |p: &Self, i, js, shares| p.drive::<f64, 0, BOTH>(i, js, shares);
                    scalar(self, i, neighbours, shares)
                }
                #[cfg(target_arch = "x86_64")]
                IsaKind::Avx512 => {
                    use x86::sum_avx512 as f;
                    on!(f)
                }
                #[cfg(target_arch = "x86_64")]
                IsaKind::Avx2 => {
                    use x86::sum_avx2 as f;
                    on!(f)
                }
            }
        }
    }

    /// The neighbour loop on lane type `L`: the shared geometry of each group of
    /// neighbours and the fields the term reads, then the term. `FIELDS` is the
    /// records' field set when it is known at compile time (so are the offsets), 0
    /// for one found at run time.
    ///
    /// # Safety
    /// L's instructions exist on this processor; a nonzero `FIELDS` is the records'
    /// field set.
    /// With `BOTH`, the term's [`PairTerm::pair_both`] and each neighbour's share
    /// added to `shares` (which must then be given).
    #[inline(always)]
    unsafe fn drive<L: Lane, const FIELDS: u16, const BOTH: bool>(
        &self,
        i: usize,
        neighbours: &[u32],
        mut shares: Option<&mut Shares>,
    ) -> T::Out {
        let (rec, k) = (self.records, &self.kernel);
        // The fields gathered for every group: x, y and m (the geometry), and those
        // the term reads (checked to be in the records by `Pass::new`); constants
        // when the records' field set is.
        // (Loops, not `array::map`, which is not inlined, so that the constants fold.)
        let (mut wanted, mut offsets) = (self.wanted, self.offsets);
        if FIELDS != 0 {
            each_field!(|k| {
                wanted[k] = FIELDS & (1 << k) != 0;
                offsets[k] = (FIELDS & ((1 << k) - 1)).count_ones() as usize;
            });
        }
        let me = rec.particle(i, &wanted, &offsets);
        let mut pad = me.values;
        pad[Field::X as usize] += self.pad_shift;
        for f in [Field::Mass, Field::PRho2, Field::Sound] {
            pad[f as usize] = 0.0;
        }
        let (base, stride, len) = (rec.base(), rec.stride(), rec.len());
        let (xi, yi) = (L::splat(me.get(Field::X)), L::splat(me.get(Field::Y)));
        #[cfg(feature = "dim3")]
        let zi = L::splat(me.get(Field::Z));
        let inv_h = L::splat(k.inv_h());
        // A copy of the term in the loop's own frame, so that its parameters (and the
        // composite's choice of terms) are plain values there, not loads through
        // references in every group.
        let term = self.term.clone();
        // Groups of eight 64-byte records are read whole (`Gather::records8`), with
        // the padding particle as a record.
        let whole = L::WIDTH == 8 && stride == 8;
        let mut pad_record = [0.0; 8];
        if whole {
            each_field!(|f| if wanted[f] {
                pad_record[offsets[f]] = pad[f];
            });
        }
        // Slots every fluid record holds as +0.0, as does i's padding: a group of fluid
        // neighbours leaves them at zero without gathering them (the wall particles'
        // normals, say, read by a few terms, zero for the fluid).
        let mut skip = [false; Field::COUNT];
        each_field!(|f| {
            skip[f] =
                wanted[f] && rec.fluid_zero().contains(Field::ALL[f]) && pad[f].to_bits() == 0;
        });
        let (skipping, n_fluid) = (skip.contains(&true), rec.n_fluid());
        let mut acc = term.zero::<L>();
        for js in neighbours.chunks(L::WIDTH) {
            let fluid_only = skipping && (js.iter().fold(0, |a, &j| a.max(j)) as usize) < n_fluid;
            let mut fields = [L::zero(); Field::COUNT];
            // SAFETY: L's instructions exist (caller); `index` and `records8` check
            // every index against `len`; the gathers read records of this buffer at
            // offsets below its stride, `records8` whole records of eight f64s of the
            // 64-byte aligned buffer (`Records`' lines).
            unsafe {
                if whole {
                    let rows = L::records8(js, base, len, &pad_record);
                    each_field!(|f| if wanted[f] {
                        fields[f] = rows[offsets[f]];
                    });
                } else {
                    let index = L::index(js, stride, len);
                    each_field!(|f| if wanted[f] && !(fluid_only && skip[f]) {
                        fields[f] = L::gather(index, base, offsets[f], pad[f]);
                    });
                }
            }
            let (dx, dy) = (
                xi - fields[Field::X as usize],
                yi - fields[Field::Y as usize],
            );
            #[cfg(not(feature = "dim3"))]
            let r = (dx * dx + dy * dy).sqrt();
            #[cfg(feature = "dim3")]
            let dz = zi - fields[Field::Z as usize];
            #[cfg(feature = "dim3")]
            let r = (dx * dx + dy * dy + dz * dz).sqrt();
            let q = r * inv_h;
            let f = k.grad_factor_at(q, r);
            let p = Pair {
                dx,
                dy,
                #[cfg(feature = "dim3")]
                dz,
                r,
                q,
                w: k.w_at(q),
                gx: dx * f,
                gy: dy * f,
                #[cfg(feature = "dim3")]
                gz: dz * f,
                fields,
                fluid_only,
            };
            if let (true, Some(shares)) = (BOTH, shares.as_deref_mut()) {
                let share = term.pair_both(&me, &p, &mut acc);
                // SAFETY: L's instructions exist (caller); `scatter` checks every
                // index against the window.
                unsafe { L::scatter(js, &share, shares) };
            } else {
                term.pair(&me, &p, &mut acc);
            }
        }
        match BOTH {
            true => term.finish_both(&me, acc),
            false => term.finish(&me, acc),
        }
    }
}

/// Runs `f` with the sim's shared [`Records`] buffer (a resource, created on first
/// use) packed with `fields` from the current state; None when the world has no fluid.
pub fn with_records<R>(
    sim: &mut crate::Sim,
    fields: Fields,
    f: impl FnOnce(&crate::Sim, &crate::world::Particles, &Records) -> Result<R, crate::StepError>,
) -> Result<Option<R>, crate::StepError> {
    with_records_packed(sim, Packing::Full(fields), f)
}

/// How [`with_records_packed`] fills the shared records.
#[derive(Clone, Copy, Debug)]
pub enum Packing {
    /// Packed in full with these fields ([`Records::pack`]).
    Full(Fields),
    /// For a pass that follows another on records already packed with every field it
    /// reads: only these fields, changed since, are packed again
    /// ([`Records::refresh`]). Meant for the iterations of a solve, which change
    /// velocities or pressures between passes and nothing else; the caller packs the
    /// records in full before the first.
    Refresh(Fields),
}

/// [`with_records`] with the records filled as `packing` says.
///
/// # Errors
/// As [`Records::pack`] or [`Records::refresh`], or what `f` returns.
pub fn with_records_packed<R>(
    sim: &mut crate::Sim,
    packing: Packing,
    f: impl FnOnce(&crate::Sim, &crate::world::Particles, &Records) -> Result<R, crate::StepError>,
) -> Result<Option<R>, crate::StepError> {
    let mut records = sim.resources.take::<Records>().unwrap_or_default();
    let empty = Columns::default();
    let columns = sim.resources.get::<Columns>().unwrap_or(&empty);
    let eos = &sim.constants.eos;
    let result = match crate::world::Particles::of(&sim.world) {
        Some(particles) => match packing {
            Packing::Full(fields) => {
                records.pack_with(&particles, Layouts::widen(fields), eos, columns)
            }
            Packing::Refresh(changed) => records.refresh(&particles, changed, eos),
        }
        .and_then(|()| f(sim, &particles, &records))
        .map(Some),
        None => Ok(None),
    };
    sim.resources.insert(records);
    result
}

#[cfg(test)]
mod tests;
