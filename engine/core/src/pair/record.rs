//! Particles packed for the pair sums (docs/performance.md): what a neighbour sum reads
//! of particle j, in one record in the joint fluid + ghost numbering, instead of
//! several separate columns each reached through the fluid/ghost branch of
//! `Joined::get`. A record holds exactly the fields a pass's terms read (the union of
//! their [`Fields`]), at 4, 8 or 16 f64s, so the shipped momentum pass reads one
//! 64-byte cache line per neighbour and the Shepard filter half of one.
//!
//! One buffer serves every pair stage (a resource of the sim); each stage packs it
//! again at the start of its run, because the state changes between stages (the
//! filter changes densities, `Eos` pressures).

use super::columns::Columns;
use crate::components::{Density, Mass, Position, Pressure, Velocity};
use crate::dim::Vector;
use crate::sim::Tait;
use crate::stage::StepError;
use crate::world::Particles;
use rayon::prelude::*;

/// A particle quantity a pair term can read from the packed records.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Field {
    /// Position x [m].
    X,
    /// Position y [m].
    Y,
    /// Position z [m] (3D).
    #[cfg(feature = "dim3")]
    Z,
    /// Velocity, x [m/s].
    Vx,
    /// Velocity, y [m/s].
    Vy,
    /// Velocity, z [m/s] (3D).
    #[cfg(feature = "dim3")]
    Vz,
    /// Density rho [kg/m^3].
    Rho,
    /// Mass m [kg].
    Mass,
    /// p / rho^2 [Pa m^6/kg^2].
    PRho2,
    /// Sound speed c(rho) of the equation of state [m/s].
    Sound,
    /// Keyed column slot 0: a quantity a stage computes, packed as its key says
    /// ([`super::ColumnKey`]; delta-SPH's density gradient takes slots 0 and 1, and
    /// 2 in 3D).
    Slot0,
    /// Keyed column slot 1.
    Slot1,
    /// Keyed column slot 2 (the ghosts' no-slip velocity takes slots 2 and 3).
    Slot2,
    /// Keyed column slot 3.
    Slot3,
}

impl Field {
    /// Whether the field is a keyed column's slot (not a component of the world).
    pub const fn is_slot(self) -> bool {
        self as u8 >= Field::Slot0 as u8
    }
    /// How many fields there are.
    pub const COUNT: usize = 8 + 2 * crate::dim::DIM;
    /// Every field, in record order.
    #[cfg(not(feature = "dim3"))]
    pub const ALL: [Field; Field::COUNT] = [
        Field::X,
        Field::Y,
        Field::Vx,
        Field::Vy,
        Field::Rho,
        Field::Mass,
        Field::PRho2,
        Field::Sound,
        Field::Slot0,
        Field::Slot1,
        Field::Slot2,
        Field::Slot3,
    ];
    /// Every field, in record order.
    #[cfg(feature = "dim3")]
    pub const ALL: [Field; Field::COUNT] = [
        Field::X,
        Field::Y,
        Field::Z,
        Field::Vx,
        Field::Vy,
        Field::Vz,
        Field::Rho,
        Field::Mass,
        Field::PRho2,
        Field::Sound,
        Field::Slot0,
        Field::Slot1,
        Field::Slot2,
        Field::Slot3,
    ];
    /// The keyed columns' slots.
    pub const SLOTS: [Field; 4] = [Field::Slot0, Field::Slot1, Field::Slot2, Field::Slot3];
    /// The position's components.
    #[cfg(not(feature = "dim3"))]
    pub const POSITION: [Field; crate::dim::DIM] = [Field::X, Field::Y];
    /// The position's components.
    #[cfg(feature = "dim3")]
    pub const POSITION: [Field; crate::dim::DIM] = [Field::X, Field::Y, Field::Z];
    /// The velocity's components.
    #[cfg(not(feature = "dim3"))]
    pub const VELOCITY: [Field; crate::dim::DIM] = [Field::Vx, Field::Vy];
    /// The velocity's components.
    #[cfg(feature = "dim3")]
    pub const VELOCITY: [Field; crate::dim::DIM] = [Field::Vx, Field::Vy, Field::Vz];
    /// What the momentum equation's terms read, every field but the slots: one
    /// 64-byte record in 2D (eight fields); in 3D ten, a 128-byte record.
    pub const MOMENTUM: [Field; Field::COUNT - 4] = {
        let mut m = [Field::X; Field::COUNT - 4];
        let mut k = 0;
        while k < m.len() {
            m[k] = Field::ALL[k];
            k += 1;
        }
        m
    };
}

/// A set of [`Field`]s.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Fields(pub(crate) u16);

impl Fields {
    /// What every pass packs: the geometry and the mass (the padding lanes of a group
    /// are a particle of zero mass).
    #[cfg(not(feature = "dim3"))]
    pub const GEOMETRY: Fields = Fields::of(&[Field::X, Field::Y, Field::Mass]);
    /// What every pass packs: the geometry and the mass (the padding lanes of a group
    /// are a particle of zero mass).
    #[cfg(feature = "dim3")]
    pub const GEOMETRY: Fields = Fields::of(&[Field::X, Field::Y, Field::Z, Field::Mass]);

    /// The set of `list`.
    pub const fn of(list: &[Field]) -> Fields {
        let mut bits = 0u16;
        let mut k = 0;
        while k < list.len() {
            bits |= 1 << list[k] as u16;
            k += 1;
        }
        Fields(bits)
    }
    /// Both sets.
    pub const fn with(self, other: Fields) -> Fields {
        Fields(self.0 | other.0)
    }
    pub const fn contains(self, f: Field) -> bool {
        self.0 & (1 << f as u16) != 0
    }
    /// How many fields.
    pub const fn len(self) -> usize {
        self.0.count_ones() as usize
    }
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
    /// The set as bits, bit k for the field of discriminant k.
    pub const fn bits(self) -> u16 {
        self.0
    }
    /// Offset of field `f` in a record holding this set (fields in `Field` order):
    /// how many fields of the set come before it.
    pub(crate) const fn offset(self, f: Field) -> usize {
        (self.0 & ((1u16 << f as u16) - 1)).count_ones() as usize
    }
}

/// One cache line of records.
#[derive(Clone, Copy, Default)]
#[repr(C, align(64))]
struct Line([f64; 8]);

/// The packed particles: `len` records of `stride` f64s (4, 8 or 16), the fields in
/// [`Field`] order.
#[derive(Default)]
pub struct Records {
    lines: Vec<Line>,
    len: usize,
    stride: usize,
    fields: Fields,
    /// Offset of each field in a record (valid for the fields held).
    offsets: [usize; Field::COUNT],
    /// Fluid particles: records 0 to `n_fluid` - 1.
    n_fluid: usize,
    /// The keyed columns' slots held as +0.0 in every fluid particle's record (a
    /// column of the walls alone, such as their normals).
    fluid_zero: Fields,
}

impl Records {
    /// Records in the joint numbering.
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    /// f64s per record.
    pub fn stride(&self) -> usize {
        self.stride
    }
    /// The fields held.
    pub fn fields(&self) -> Fields {
        self.fields
    }
    /// Fluid particles: records 0 to `n_fluid() - 1`; the ghosts follow.
    pub fn n_fluid(&self) -> usize {
        self.n_fluid
    }
    /// The keyed columns' slots that every fluid particle's record holds as +0.0, so
    /// that a group of fluid neighbours need not gather them (a column of the walls
    /// alone: the wall particles' normals, `WallNormal`).
    pub fn fluid_zero(&self) -> Fields {
        self.fluid_zero
    }
    /// Bytes held (capacity), for memory accounting.
    pub fn heap_bytes(&self) -> usize {
        self.lines.capacity() * std::mem::size_of::<Line>()
    }

    /// The first field of `wanted` that the records lack.
    pub(crate) fn lacks(&self, wanted: Fields) -> Option<Field> {
        Field::ALL
            .into_iter()
            .find(|&f| wanted.contains(f) && !self.fields.contains(f))
    }

    /// Offset of field `f` in a record: below the stride (0 for a field not held,
    /// which [`super::Pass::new`] refuses to read).
    #[inline(always)]
    pub(crate) fn offset(&self, f: Field) -> usize {
        self.offsets[f as usize]
    }

    #[inline(always)]
    pub(crate) fn base(&self) -> *const f64 {
        self.lines.as_ptr() as *const f64
    }

    /// Field `f` of record `j` (0 for a field not held).
    ///
    /// # Panics
    /// If `j` is beyond the records.
    pub fn get(&self, j: usize, f: Field) -> f64 {
        assert!(j < self.len, "record {j} of {}", self.len);
        if !self.fields.contains(f) {
            return 0.0;
        }
        bytemuck_lines_ref(&self.lines)[j * self.stride + self.offset(f)]
    }

    /// Particle `i`'s fields for a term.
    ///
    /// # Panics
    /// If `i` is beyond the records.
    /// The `wanted` fields (held, at `offsets`) of particle `i`; 0 for the others.
    #[inline(always)]
    pub(crate) fn particle(
        &self,
        i: usize,
        wanted: &[bool; Field::COUNT],
        offsets: &[usize; Field::COUNT],
    ) -> super::Me {
        assert!(i < self.len, "particle {i} of {} records", self.len);
        let record = &bytemuck_lines_ref(&self.lines)[i * self.stride..][..self.stride];
        let mut values = [0.0; Field::COUNT];
        each_field!(|k| if wanted[k] {
            values[k] = record[offsets[k]];
        });
        super::Me { values, index: i }
    }

    /// Sets the layout for `fields` (and the geometry) and `len` records; the
    /// contents are left to be filled.
    fn shape(&mut self, fields: Fields, len: usize) {
        let fields = fields.with(Fields::GEOMETRY);
        for f in Field::ALL {
            self.offsets[f as usize] = if fields.contains(f) {
                fields.offset(f)
            } else {
                0
            };
        }
        self.stride = fields.len().next_power_of_two().max(4);
        self.fields = fields;
        self.len = len;
        let lines = (len * self.stride).div_ceil(8);
        // The buffer keeps its capacity from step to step. It grows to exactly what is
        // needed (a rare copy when the ghost count reaches a new high beats holding
        // slack in the largest buffer of the step), and to at least a line a record, so
        // that a narrow pass first in the step (the filters' four fields) does not make
        // the momentum pass reallocate it.
        if lines > self.lines.capacity() {
            self.lines = Vec::with_capacity(lines.max(len));
        }
        self.lines.resize(lines, Line::default());
    }

    /// Packs `fields` of every particle (fluid, then ghosts) from the world's columns;
    /// `eos` gives the sound speed.
    ///
    /// # Errors
    /// A column the fields need is missing, or the particles are too many to index
    /// the records with 32-bit offsets.
    pub fn pack(
        &mut self,
        particles: &Particles,
        fields: Fields,
        eos: &Tait,
    ) -> Result<(), StepError> {
        self.pack_with(particles, fields, eos, &Columns::default())
    }

    /// [`Records::pack`], with the keyed columns' slots filled from `columns`.
    ///
    /// # Errors
    /// As [`Records::pack`]; a slot is wanted that no column of `columns` holds, or a
    /// column's values are not one per particle (or ghost) of the world.
    pub fn pack_with(
        &mut self,
        particles: &Particles,
        fields: Fields,
        eos: &Tait,
        columns: &Columns,
    ) -> Result<(), StepError> {
        self.write(particles, fields, eos, columns, true)
    }

    /// Packs `changed` again into records that hold it, leaving the other fields as
    /// they are: for a pass that follows another on the same particles when only
    /// these fields have changed since (a pressure solve's iterations change the
    /// velocities or the pressures, not the positions). A stale field is the caller's
    /// to rule out; see [`super::Packing::Refresh`].
    ///
    /// # Errors
    /// The records lack a field of `changed`, or were packed for another number of
    /// particles; a column `changed` needs is missing (a keyed column's slot cannot
    /// be refreshed).
    pub fn refresh(
        &mut self,
        particles: &Particles,
        changed: Fields,
        eos: &Tait,
    ) -> Result<(), StepError> {
        self.write(particles, changed, eos, &Columns::default(), false)
    }

    /// Writes `fields` of every particle: into a fresh layout for them (`reshape`), or
    /// into the present layout, which must hold them.
    fn write(
        &mut self,
        particles: &Particles,
        fields: Fields,
        eos: &Tait,
        columns: &Columns,
        reshape: bool,
    ) -> Result<(), StepError> {
        let (x, rho, m) = (
            particles.joined::<Position>()?,
            particles.joined::<Density>()?,
            particles.joined::<Mass>()?,
        );
        let (x, rho, m) = (x.view(), rho.view(), m.view());
        let len = x.len();
        let n_fluid = x.fluid.len();
        let slots = columns.sources(fields, len, n_fluid)?;
        // A ghosts-only column's fluid values come from the fluid's own fields.
        let own = |f: Field| slots.iter().flatten().any(|s| s.fluid_reads(f));
        let wants = |f: &[Field]| f.iter().any(|&f| fields.contains(f) || own(f));
        let v = match wants(&Field::VELOCITY) {
            true => Some(particles.joined::<Velocity>()?),
            false => None,
        };
        let p = match wants(&[Field::PRho2]) {
            true => Some(particles.joined::<Pressure>()?),
            false => None,
        };
        let (v, p) = (v.as_ref().map(|c| c.view()), p.as_ref().map(|c| c.view()));
        if len.saturating_mul(16) >= i32::MAX as usize {
            return Err(StepError::Internal(format!(
                "{len} particles are too many for the packed records' 32-bit offsets"
            )));
        }
        if reshape {
            self.shape(fields, len);
        } else if len != self.len {
            return Err(StepError::Internal(format!(
                "records packed for {} particles refreshed for {len}",
                self.len
            )));
        } else if let Some(f) = self.lacks(fields) {
            return Err(StepError::Internal(format!(
                "the records lack {f:?}, so it cannot be refreshed: pack it first"
            )));
        }
        // The fields written: all the layout holds, or just those refreshed.
        let held = if reshape { self.fields } else { fields };
        let sound = held.contains(Field::Sound) || own(Field::Sound);
        let (stride, offsets) = (self.stride, self.offsets);
        let values: &mut [f64] = bytemuck_lines(&mut self.lines);
        // Blocks of records with a plain loop inside (no call per record).
        const PACK_CHUNK: usize = 512;
        values[..len * stride]
            .par_chunks_mut(stride * PACK_CHUNK)
            .enumerate()
            .for_each(|(c, block)| {
                for (k, out) in block.chunks_exact_mut(stride).enumerate() {
                    let j = (c * PACK_CHUNK + k) as u32;
                    // j's world fields, in `Field` order (0 where not read).
                    let (xj, rhoj) = (x.get(j).0, rho.get(j).0);
                    let vj = v.as_ref().map_or(Vector::ZERO, |v| v.get(j).0);
                    let mut base = [0.0; Field::COUNT];
                    for (k, f) in Field::POSITION.into_iter().enumerate() {
                        base[f as usize] = xj[k];
                    }
                    for (k, f) in Field::VELOCITY.into_iter().enumerate() {
                        base[f as usize] = vj[k];
                    }
                    base[Field::Rho as usize] = rhoj;
                    base[Field::Mass as usize] = m.get(j).0;
                    if let Some(p) = &p {
                        base[Field::PRho2 as usize] = p.get(j).0 / (rhoj * rhoj);
                    }
                    if sound {
                        base[Field::Sound as usize] = eos.sound_speed(rhoj);
                    }
                    for (s, source) in slots.iter().enumerate() {
                        if let Some(source) = source {
                            base[Field::SLOTS[s] as usize] =
                                source.value(j as usize, n_fluid, |f| base[f as usize]);
                        }
                    }
                    for f in Field::ALL {
                        if held.contains(f) {
                            out[offsets[f as usize]] = base[f as usize];
                        }
                    }
                }
            });
        // Slots cannot be refreshed, so only a new layout changes which are zero.
        if reshape {
            let fluid = &values[..n_fluid * stride];
            let fluid_zero = Field::SLOTS.into_iter().fold(0, |bits, f| {
                let o = offsets[f as usize];
                let zero =
                    held.contains(f) && fluid.par_chunks_exact(stride).all(|r| r[o].to_bits() == 0);
                bits | (zero as u16) << f as u16
            });
            (self.n_fluid, self.fluid_zero) = (n_fluid, Fields(fluid_zero));
        }
        Ok(())
    }
}

/// The lines as one slice of f64s.
fn bytemuck_lines_ref(lines: &[Line]) -> &[f64] {
    // SAFETY: as in `bytemuck_lines`.
    unsafe { std::slice::from_raw_parts(lines.as_ptr() as *const f64, lines.len() * 8) }
}

/// The lines as one mutable slice of f64s.
fn bytemuck_lines(lines: &mut [Line]) -> &mut [f64] {
    // SAFETY: `Line` is `repr(C)` around `[f64; 8]` with no padding (64 bytes, align
    // 64), so `lines.len()` lines are exactly `8 lines.len()` consecutive f64s.
    unsafe { std::slice::from_raw_parts_mut(lines.as_mut_ptr() as *mut f64, lines.len() * 8) }
}
