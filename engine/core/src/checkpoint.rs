//! Checkpoints: the complete state of a run in one file, so `engine resume <dir>`
//! continues it and produces the same outputs, bit for bit, as a run never stopped.
//!
//! The file (`checkpoint.bin` in the output folder) is
//! `magic, version, step, time, scenario fingerprint, origin, payload, checksum`, the
//! checksum (64-bit FNV-1a) covering every byte before it. It is written to
//! `checkpoint.bin.tmp`, synced to disk, and renamed into place; the checkpoint it
//! replaces is kept as `checkpoint.prev.bin`. A run killed while writing leaves a
//! temporary file that [`read_latest`] ignores; a damaged newest file (truncated,
//! garbled) makes it fall back to the previous checkpoint, with a message saying so.
//!
//! The payload is written by the runner: clock, diagnostics, the fluid and ghost
//! particle columns of the core components, then every stage's private state
//! ([`crate::Stage::save_state`]), encoded with [`Enc`] (little-endian, no padding).
//! Wall and piston positions are functions of time and are not stored: the runner puts
//! the scene back where it was at the checkpoint's time ([`crate::kinematics`]).

use crate::components::{
    Acceleration, Density, DensityRate, Fluid, Ghost, Mass, MirrorWall, NeighbourCount, ParticleId,
    Position, Pressure, Velocity,
};
use crate::dim::Vector;
use crate::world::archetype;
use glam::{DVec2, DVec3};
use hecs::{Archetype, Component, World};
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The first bytes of a 2D and of a 3D checkpoint: each build writes and reads its own
/// dimension's (2D's unchanged since the first checkpoints).
const MAGICS: [&[u8; 8]; 2] = [b"SPHCKPT\0", b"SPHCK3D\0"];
const MAGIC: &[u8; 8] = MAGICS[crate::dim::DIM - 2];
/// 2: the ghosts' `MirrorWall` column joined the ghost columns.
const VERSION: u32 = 2;
/// The newest checkpoint's file name.
pub const LATEST: &str = "checkpoint.bin";
/// The previous checkpoint's file name (the fallback).
pub const PREVIOUS: &str = "checkpoint.prev.bin";
/// The temporary name a checkpoint is written under before the rename.
pub const TEMPORARY: &str = "checkpoint.bin.tmp";

/// Why a checkpoint, or a stage's part of one, cannot be read back.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StateError {
    #[error("not a checkpoint file (bad magic number or truncated)")]
    NotCheckpoint,
    /// A checkpoint of the other dimension's build.
    #[error(
        "a {found}D checkpoint; this engine is built for {}D runs",
        crate::dim::DIM
    )]
    Dimension { found: usize },
    #[error("checksum mismatch: the file is truncated or damaged")]
    Checksum,
    #[error(
        "checkpoint format version {found}; this engine reads version {}",
        VERSION
    )]
    Version { found: u32 },
    #[error("checkpoint data ends early")]
    Truncated,
    /// A count that asks for more bytes than are left (a damaged count).
    #[error("checkpoint data is inconsistent (a count of {count} with {left} bytes left)")]
    Count { count: u64, left: u64 },
    #[error("checkpoint data has {0} unread bytes")]
    Unread(usize),
    #[error("checkpoint text is not UTF-8: {0}")]
    Text(#[from] std::string::FromUtf8Error),
    /// The checkpoint does not fit the scenario: other stages, particles or columns.
    #[error("{0}")]
    Mismatch(String),
    /// A stage could not put back a file it keeps (e.g. a `.pvd` index).
    #[error("{path}: {message}")]
    Output { path: String, message: String },
    /// A stage's state failed to load.
    #[error("stage `{stage}`: {error}")]
    Stage {
        stage: String,
        error: Box<StateError>,
    },
}

/// Where a run came from, so `engine resume` can load the same scenario again.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Origin {
    /// The scenario file (absolute when the command line wrote it).
    pub scenario: PathBuf,
    /// The `--set PATH=VALUE` overrides, as given.
    pub sets: Vec<String>,
}

/// A checkpoint read back from disk.
#[derive(Clone, Default, PartialEq)]
pub struct Checkpoint {
    /// Completed steps.
    pub step: u64,
    /// Simulated time [s].
    pub time: f64,
    /// Hash of the resolved scenario it was written for ([`fingerprint`]).
    pub fingerprint: u64,
    pub origin: Origin,
    /// The runner's encoded state.
    pub payload: Vec<u8>,
    /// The file it was read from.
    pub file: PathBuf,
}

impl std::fmt::Debug for Checkpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Checkpoint")
            .field("step", &self.step)
            .field("time", &self.time)
            .field("origin", &self.origin)
            .field("payload_bytes", &self.payload.len())
            .field("file", &self.file)
            .finish()
    }
}

/// Inserted into [`crate::Sim::resources`] before the stages' setup when a run resumes,
/// so output writers continue their files ([`crate::series::SeriesWriter::open`]) rather
/// than start them afresh.
#[derive(Clone, Copy, Debug)]
pub struct Resuming {
    /// The checkpoint's simulated time [s]: rows after it are dropped.
    pub time: f64,
}

/// 64-bit FNV-1a hash.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// The fingerprint of a resolved scenario text: a checkpoint resumes only the scenario
/// it was written for.
pub fn fingerprint(resolved_ron: &str) -> u64 {
    fnv1a(resolved_ron.as_bytes())
}

/// Encodes a checkpoint file ([`begin`], the payload, [`seal`]).
pub fn encode(step: u64, time: f64, fingerprint: u64, origin: &Origin, payload: &[u8]) -> Vec<u8> {
    let mut e = begin(step, time, fingerprint, origin);
    e.raw(payload);
    seal(e)
}

/// Starts a checkpoint file with its header; the caller appends the payload (the rest
/// of the file up to the checksum, so it is built in place, not copied) and calls
/// [`seal`].
pub fn begin(step: u64, time: f64, fingerprint: u64, origin: &Origin) -> Enc {
    let mut e = Enc::default();
    e.raw(MAGIC);
    e.u32(VERSION);
    e.u64(step);
    e.f64(time);
    e.u64(fingerprint);
    e.str(&origin.scenario.to_string_lossy());
    e.u64(origin.sets.len() as u64);
    for s in &origin.sets {
        e.str(s);
    }
    e
}

/// Ends a checkpoint file started by [`begin`] with its checksum.
pub fn seal(mut e: Enc) -> Vec<u8> {
    let sum = fnv1a(&e.0);
    e.u64(sum);
    e.0
}

/// Decodes a checkpoint file, checking its magic, version and checksum. The payload
/// keeps the file's buffer (no copy).
pub fn decode(mut bytes: Vec<u8>, file: &Path) -> Result<Checkpoint, StateError> {
    if bytes.len() < MAGIC.len() + 8 || &bytes[..MAGIC.len()] != MAGIC {
        if let Some(k) = MAGICS.iter().position(|m| bytes.starts_with(*m)) {
            return Err(StateError::Dimension { found: k + 2 });
        }
        return Err(StateError::NotCheckpoint);
    }
    let (body, sum) = bytes.split_at(bytes.len() - 8);
    let stored = u64::from_le_bytes(sum.try_into().unwrap_or_default());
    if fnv1a(body) != stored {
        return Err(StateError::Checksum);
    }
    let mut d = Dec::new(&body[MAGIC.len()..]);
    let version = d.u32()?;
    if version != VERSION {
        return Err(StateError::Version { found: version });
    }
    let (step, time, fingerprint) = (d.u64()?, d.f64()?, d.u64()?);
    let scenario = PathBuf::from(d.str()?);
    let n = d.len(1)?;
    let sets = (0..n).map(|_| d.str()).collect::<Result<_, _>>()?;
    let header = MAGIC.len() + d.pos;
    let body = bytes.len() - 8;
    bytes.truncate(body);
    bytes.drain(..header);
    let payload = bytes;
    Ok(Checkpoint {
        step,
        time,
        fingerprint,
        origin: Origin { scenario, sets },
        payload,
        file: file.to_path_buf(),
    })
}

/// A checkpoint that could not be written or read.
#[derive(Clone, Debug, thiserror::Error)]
pub enum CheckpointError {
    /// A file could not be written, read or decoded.
    #[error("{}: {message}", path.display())]
    File { path: PathBuf, message: String },
    #[error("{0}; and there is no previous checkpoint to fall back to")]
    NoFallback(Box<CheckpointError>),
    #[error("{latest}; and the previous checkpoint is unusable too: {previous}")]
    BothUnusable {
        latest: Box<CheckpointError>,
        previous: Box<CheckpointError>,
    },
    #[error("no checkpoint in {} (run with --checkpoint-every SECONDS or --stop-at SECONDS, or stop a run with Ctrl-C)", dir.display())]
    None { dir: PathBuf },
}

impl CheckpointError {
    fn file(path: &Path, e: impl std::fmt::Display) -> Self {
        Self::File {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }
}

/// Writes a checkpoint into `dir`: to [`TEMPORARY`], synced, then the current
/// [`LATEST`] becomes [`PREVIOUS`] and the new file takes its place. An error names the
/// file and leaves the earlier checkpoints as they were.
pub fn write(dir: &Path, bytes: &[u8]) -> Result<(), CheckpointError> {
    let (tmp, latest) = (dir.join(TEMPORARY), dir.join(LATEST));
    let named = |p: &Path, e: std::io::Error| CheckpointError::file(p, e);
    let written = fs::File::create(&tmp).and_then(|mut f| {
        f.write_all(bytes)?;
        f.sync_all()
    });
    if let Err(e) = written {
        let _ = fs::remove_file(&tmp);
        return Err(named(&tmp, e));
    }
    if latest.exists() {
        let prev = dir.join(PREVIOUS);
        fs::rename(&latest, &prev).map_err(|e| named(&prev, e))?;
    }
    fs::rename(&tmp, &latest).map_err(|e| named(&latest, e))?;
    // Make the renames durable; not every file system allows syncing a folder.
    if let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// The space dimensions of the checkpoints in run folder `dir` (2 or 3, by their
/// files' magic), the newest file first; `None` when neither file has a checkpoint's
/// magic (the reader of either build then says what is wrong).
pub fn dimensions_in(dir: &Path) -> Option<u32> {
    [LATEST, PREVIOUS].iter().find_map(|name| {
        let mut head = [0u8; 8];
        let mut file = std::fs::File::open(dir.join(name)).ok()?;
        std::io::Read::read_exact(&mut file, &mut head).ok()?;
        MAGICS
            .iter()
            .position(|m| **m == head)
            .map(|k| k as u32 + 2)
    })
}

/// Reads the newest usable checkpoint in `dir`. Returns it with notes for the user: a
/// leftover temporary file (removed), or a damaged newest checkpoint (renamed to
/// `checkpoint.bin.damaged`) and the fallback to the previous one.
pub fn read_latest(dir: &Path) -> Result<(Checkpoint, Vec<String>), CheckpointError> {
    let mut notes = Vec::new();
    let tmp = dir.join(TEMPORARY);
    if tmp.exists() {
        notes.push(format!(
            "ignoring {}: left by a checkpoint write that was interrupted",
            tmp.display()
        ));
        let _ = fs::remove_file(&tmp);
    }
    let read = |name: &str| -> Result<Checkpoint, CheckpointError> {
        let path = dir.join(name);
        let bytes = fs::read(&path).map_err(|e| CheckpointError::file(&path, e))?;
        decode(bytes, &path).map_err(|e| CheckpointError::file(&path, e))
    };
    let latest = dir.join(LATEST);
    let first = if latest.exists() {
        match read(LATEST) {
            Ok(c) => return Ok((c, notes)),
            Err(e) => Some(e),
        }
    } else {
        None
    };
    let prev = dir.join(PREVIOUS);
    if !prev.exists() {
        return Err(match first {
            Some(e) => CheckpointError::NoFallback(Box::new(e)),
            None => CheckpointError::None {
                dir: dir.to_path_buf(),
            },
        });
    }
    let c = read(PREVIOUS).map_err(|e2| match &first {
        Some(e1) => CheckpointError::BothUnusable {
            latest: Box::new(e1.clone()),
            previous: Box::new(e2),
        },
        None => e2,
    })?;
    if let Some(e) = first {
        let damaged = dir.join("checkpoint.bin.damaged");
        // Keep the damaged file aside, so the next checkpoint does not rotate it over
        // the good previous one.
        let _ = fs::rename(&latest, &damaged);
        notes.push(format!(
            "{e}; falling back to the previous checkpoint {} (t = {} s, step {}); the damaged file was moved to {}",
            prev.display(),
            c.time,
            c.step,
            damaged.display()
        ));
    }
    Ok((c, notes))
}

/// A little-endian binary encoder for checkpoint payloads.
#[derive(Default)]
pub struct Enc(pub Vec<u8>);

impl Enc {
    /// Bytes as they are (no length).
    pub fn raw(&mut self, b: &[u8]) {
        self.0.extend_from_slice(b);
    }
    pub fn u32(&mut self, v: u32) {
        self.raw(&v.to_le_bytes());
    }
    pub fn u64(&mut self, v: u64) {
        self.raw(&v.to_le_bytes());
    }
    pub fn f64(&mut self, v: f64) {
        self.raw(&v.to_le_bytes());
    }
    pub fn bool(&mut self, v: bool) {
        self.0.push(v as u8);
    }
    pub fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    pub fn opt_f64(&mut self, v: Option<f64>) {
        self.bool(v.is_some());
        self.f64(v.unwrap_or(0.0));
    }
    /// Length-prefixed bytes.
    pub fn bytes(&mut self, b: &[u8]) {
        self.u64(b.len() as u64);
        self.raw(b);
    }
    pub fn str(&mut self, s: &str) {
        self.bytes(s.as_bytes());
    }
    /// A value of a [`Field`] type.
    pub fn put<T: Field>(&mut self, v: &T) {
        v.put(self);
    }
    pub fn into_bytes(self) -> Vec<u8> {
        self.0
    }
}

/// The decoder matching [`Enc`]; every read checks the remaining length.
pub struct Dec<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Dec<'a> {
    pub fn new(buf: &'a [u8]) -> Self {
        Self { buf, pos: 0 }
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], StateError> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.buf.len());
        let end = end.ok_or(StateError::Truncated)?;
        let out = &self.buf[self.pos..end];
        self.pos = end;
        Ok(out)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], StateError> {
        let mut a = [0; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    pub fn u32(&mut self) -> Result<u32, StateError> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub fn u64(&mut self) -> Result<u64, StateError> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    pub fn f64(&mut self) -> Result<f64, StateError> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    pub fn bool(&mut self) -> Result<bool, StateError> {
        Ok(self.take(1)?[0] != 0)
    }
    pub fn u8(&mut self) -> Result<u8, StateError> {
        Ok(self.take(1)?[0])
    }
    pub fn opt_f64(&mut self) -> Result<Option<f64>, StateError> {
        let some = self.bool()?;
        let v = self.f64()?;
        Ok(some.then_some(v))
    }
    /// A count of items at least `min_bytes` each, checked against the bytes left so
    /// a damaged count cannot ask for an absurd allocation.
    pub fn len(&mut self, min_bytes: usize) -> Result<usize, StateError> {
        let n = self.u64()?;
        let left = (self.buf.len() - self.pos) as u64;
        if n.saturating_mul(min_bytes.max(1) as u64) > left {
            return Err(StateError::Count { count: n, left });
        }
        Ok(n as usize)
    }
    pub fn bytes(&mut self) -> Result<&'a [u8], StateError> {
        let n = self.len(1)?;
        self.take(n)
    }
    pub fn str(&mut self) -> Result<String, StateError> {
        Ok(String::from_utf8(self.bytes()?.to_vec())?)
    }
    /// A value of a [`Field`] type.
    pub fn get<T: Field>(&mut self) -> Result<T, StateError> {
        T::get(self)
    }
    /// Fails unless every byte was read.
    pub fn end(&self) -> Result<(), StateError> {
        if self.pos == self.buf.len() {
            Ok(())
        } else {
            Err(StateError::Unread(self.buf.len() - self.pos))
        }
    }
}

/// A value stored bit for bit in a checkpoint.
pub trait Field: Sized {
    /// Bytes per value in the encoding (for length checks).
    const BYTES: usize;
    fn put(&self, e: &mut Enc);
    fn get(d: &mut Dec) -> Result<Self, StateError>;
}

impl Field for f64 {
    const BYTES: usize = 8;
    fn put(&self, e: &mut Enc) {
        e.f64(*self);
    }
    fn get(d: &mut Dec) -> Result<Self, StateError> {
        d.f64()
    }
}

impl Field for u8 {
    const BYTES: usize = 1;
    fn put(&self, e: &mut Enc) {
        e.u8(*self);
    }
    fn get(d: &mut Dec) -> Result<Self, StateError> {
        d.u8()
    }
}

impl Field for u32 {
    const BYTES: usize = 4;
    fn put(&self, e: &mut Enc) {
        e.u32(*self);
    }
    fn get(d: &mut Dec) -> Result<Self, StateError> {
        d.u32()
    }
}

impl Field for DVec2 {
    const BYTES: usize = 16;
    fn put(&self, e: &mut Enc) {
        e.f64(self.x);
        e.f64(self.y);
    }
    fn get(d: &mut Dec) -> Result<Self, StateError> {
        Ok(DVec2::new(d.f64()?, d.f64()?))
    }
}

impl Field for DVec3 {
    const BYTES: usize = 24;
    fn put(&self, e: &mut Enc) {
        e.f64(self.x);
        e.f64(self.y);
        e.f64(self.z);
    }
    fn get(d: &mut Dec) -> Result<Self, StateError> {
        Ok(DVec3::new(d.f64()?, d.f64()?, d.f64()?))
    }
}

/// Implements [`Field`] for one-field tuple structs (components) by their inner value.
#[macro_export]
macro_rules! checkpoint_newtype {
    ($($name:ident($inner:ty)),* $(,)?) => {$(
        impl $crate::checkpoint::Field for $name {
            const BYTES: usize = <$inner as $crate::checkpoint::Field>::BYTES;
            fn put(&self, e: &mut $crate::checkpoint::Enc) {
                e.put(&self.0);
            }
            fn get(
                d: &mut $crate::checkpoint::Dec,
            ) -> Result<Self, $crate::checkpoint::StateError> {
                Ok($name(d.get()?))
            }
        }
    )*};
}

checkpoint_newtype!(
    Position(Vector),
    Velocity(Vector),
    Density(f64),
    Pressure(f64),
    Mass(f64),
    Acceleration(Vector),
    DensityRate(f64),
    NeighbourCount(u32),
    ParticleId(u32),
);

impl Field for Ghost {
    const BYTES: usize = 4;
    fn put(&self, e: &mut Enc) {
        e.u32(self.source);
    }
    fn get(d: &mut Dec) -> Result<Self, StateError> {
        Ok(Ghost { source: d.u32()? })
    }
}

impl Field for MirrorWall {
    const BYTES: usize = 8;
    fn put(&self, e: &mut Enc) {
        e.u64(self.0.to_bits().get());
    }
    fn get(d: &mut Dec) -> Result<Self, StateError> {
        let bits = d.u64()?;
        hecs::Entity::from_bits(bits)
            .map(MirrorWall)
            .ok_or_else(|| StateError::Mismatch(format!("{bits} is not a wall entity")))
    }
}

/// Writes column `T` of `arch` (a presence flag, the length, the values).
pub fn put_column<T: Component + Field>(e: &mut Enc, arch: Option<&Archetype>) {
    match arch.and_then(|a| a.get::<&T>()) {
        Some(col) => {
            e.bool(true);
            e.u64(col.len() as u64);
            for v in col.iter() {
                v.put(e);
            }
        }
        None => e.bool(false),
    }
}

/// Reads a column written by [`put_column`] into `arch`, which must have the same
/// column of the same length.
pub fn get_column<T: Component + Field>(
    d: &mut Dec,
    arch: Option<&Archetype>,
) -> Result<(), StateError> {
    let short = short_name::<T>();
    let stored = d.bool()?;
    let col = arch.and_then(|a| a.get::<&mut T>());
    match (stored, col) {
        (false, None) => Ok(()),
        (true, Some(mut col)) => {
            let n = d.len(T::BYTES)?;
            if n != col.len() {
                return Err(StateError::Mismatch(format!(
                    "the checkpoint has {n} values of `{short}`, the scenario builds {}",
                    col.len()
                )));
            }
            for v in col.iter_mut() {
                *v = d.get()?;
            }
            Ok(())
        }
        (true, None) => Err(StateError::Mismatch(format!(
            "the checkpoint has a `{short}` column the scenario's particles lack (was the pipeline changed?)"
        ))),
        (false, Some(_)) => Err(StateError::Mismatch(format!(
            "the scenario's particles have a `{short}` column the checkpoint lacks (was the pipeline changed?)"
        ))),
    }
}

/// Reads a whole column written by [`put_column`] as values.
fn read_values<T: Field>(d: &mut Dec) -> Result<Option<Vec<T>>, StateError> {
    if !d.bool()? {
        return Ok(None);
    }
    let n = d.len(T::BYTES)?;
    (0..n).map(|_| d.get()).collect::<Result<_, _>>().map(Some)
}

fn short_name<T>() -> &'static str {
    let full = std::any::type_name::<T>();
    full.rsplit("::").next().unwrap_or(full)
}

/// Writes the core components of the fluid particles and the ghosts.
pub fn put_particles(e: &mut Enc, world: &World) {
    let fluid = archetype::<Fluid>(world);
    put_column::<ParticleId>(e, fluid);
    put_column::<Position>(e, fluid);
    put_column::<Velocity>(e, fluid);
    put_column::<Density>(e, fluid);
    put_column::<Pressure>(e, fluid);
    put_column::<Mass>(e, fluid);
    put_column::<Acceleration>(e, fluid);
    put_column::<DensityRate>(e, fluid);
    put_column::<NeighbourCount>(e, fluid);
    let ghost = archetype::<Ghost>(world);
    put_column::<Ghost>(e, ghost);
    put_column::<Position>(e, ghost);
    put_column::<Velocity>(e, ghost);
    put_column::<Density>(e, ghost);
    put_column::<Pressure>(e, ghost);
    put_column::<Mass>(e, ghost);
    put_column::<MirrorWall>(e, ghost);
}

/// Restores what [`put_particles`] wrote into a world built from the same scenario
/// (the stages set up): the fluid columns in place, the ghosts spawned afresh.
pub fn get_particles(d: &mut Dec, world: &mut World) -> Result<(), StateError> {
    let fluid = archetype::<Fluid>(world);
    get_column::<ParticleId>(d, fluid)?;
    get_column::<Position>(d, fluid)?;
    get_column::<Velocity>(d, fluid)?;
    get_column::<Density>(d, fluid)?;
    get_column::<Pressure>(d, fluid)?;
    get_column::<Mass>(d, fluid)?;
    get_column::<Acceleration>(d, fluid)?;
    get_column::<DensityRate>(d, fluid)?;
    get_column::<NeighbourCount>(d, fluid)?;
    let source = read_values::<Ghost>(d)?.unwrap_or_default();
    let n = source.len();
    let column = |what: &str, got: Option<usize>| match got {
        Some(m) if m == n => Ok(()),
        None if n == 0 => Ok(()),
        _ => Err(StateError::Mismatch(format!(
            "the checkpoint's ghost `{what}` column does not match its ghosts"
        ))),
    };
    let x = read_values::<Position>(d)?;
    column("Position", x.as_ref().map(Vec::len))?;
    let v = read_values::<Velocity>(d)?;
    column("Velocity", v.as_ref().map(Vec::len))?;
    let rho = read_values::<Density>(d)?;
    column("Density", rho.as_ref().map(Vec::len))?;
    let p = read_values::<Pressure>(d)?;
    column("Pressure", p.as_ref().map(Vec::len))?;
    let m = read_values::<Mass>(d)?;
    column("Mass", m.as_ref().map(Vec::len))?;
    let wall = read_values::<MirrorWall>(d)?;
    column("MirrorWall", wall.as_ref().map(Vec::len))?;
    let old: Vec<hecs::Entity> = world
        .query::<hecs::Entity>()
        .with::<&Ghost>()
        .iter()
        .collect();
    for e in old.into_iter().rev() {
        let _ = world.despawn(e);
    }
    if n > 0 {
        let (x, v, rho, p, m, wall) = (
            x.unwrap_or_default(),
            v.unwrap_or_default(),
            rho.unwrap_or_default(),
            p.unwrap_or_default(),
            m.unwrap_or_default(),
            wall.unwrap_or_default(),
        );
        world.spawn_batch((0..n).map(|i| (source[i], x[i], v[i], rho[i], p[i], m[i], wall[i])));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_damage_detection() {
        let origin = Origin {
            scenario: "/x/s.ron".into(),
            sets: vec!["end_time=1".into()],
        };
        let bytes = encode(7, 0.125, 42, &origin, b"payload");
        let c = decode(bytes.clone(), Path::new("c")).unwrap();
        assert_eq!((c.step, c.time, c.fingerprint), (7, 0.125, 42));
        assert_eq!(c.origin, origin);
        assert_eq!(c.payload, b"payload");
        for cut in [0, 5, 20, bytes.len() - 1] {
            assert!(
                decode(bytes[..cut].to_vec(), Path::new("c")).is_err(),
                "cut {cut}"
            );
        }
        let mut flipped = bytes.clone();
        flipped[30] ^= 1;
        assert_eq!(decode(flipped, Path::new("c")), Err(StateError::Checksum));
    }

    /// A checkpoint of the other dimension is refused by name, whichever build reads
    /// it (its magic number is the other one), not as a damaged file.
    #[test]
    fn a_checkpoint_of_the_other_dimension_is_refused_as_such() {
        let origin = Origin {
            scenario: "/x/s.ron".into(),
            sets: vec![],
        };
        let mut bytes = encode(1, 0.5, 3, &origin, b"payload");
        let other = 5 - crate::dim::DIM;
        bytes[..8].copy_from_slice(MAGICS[other - 2]);
        let err = decode(bytes, Path::new("c")).unwrap_err();
        assert_eq!(err, StateError::Dimension { found: other });
        let text = err.to_string();
        assert!(
            text.contains(&format!("a {other}D checkpoint"))
                && text.contains(&format!("built for {}D runs", crate::dim::DIM)),
            "{text}"
        );
    }

    #[test]
    fn decoder_refuses_absurd_counts() {
        let mut e = Enc::default();
        e.u64(u64::MAX);
        let bytes = e.into_bytes();
        let err = Dec::new(&bytes).bytes().unwrap_err();
        assert_eq!(
            err,
            StateError::Count {
                count: u64::MAX,
                left: 0
            }
        );
        assert_eq!(Dec::new(&bytes[..3]).u64(), Err(StateError::Truncated));
        let mut d = Dec::new(&bytes);
        d.u32().unwrap();
        assert_eq!(d.end(), Err(StateError::Unread(4)));
    }
}
