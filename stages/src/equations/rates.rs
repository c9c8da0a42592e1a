//! The neighbour loop of the rate stages (`Forces`, `Continuity`): a set of rate terms
//! summed over every fluid particle's neighbours in one pass of the pair layer, and
//! the results written into the particle columns.

use crate::terms::{Fixed, RateTerms, TermBit};
use crate::wall_work;
use rayon::prelude::*;
use sph_core::components::{
    Acceleration, Density, DensityRate, Mass, NeighbourCount, Position, Pressure, Velocity,
};
use sph_core::contract::Access;
use sph_core::dim::Vector;
use sph_core::pair::{
    with_records, Counted, EquationsOfMotion, Field, Fields, PairTerm, Pass, RateSums, RateTerm,
    Shares, SHARE, SHARE_AX, SHARE_AY, SHARE_DRHO,
};
use sph_core::sim::Sim;
use sph_core::stage::StepError;
use sph_core::vocab::Neighbours;
use sph_core::with_kernel;

/// Declares in `access` the particle columns that records of `fields` are packed from.
pub(crate) fn declare_reads(access: Access, fields: Fields) -> Access {
    let has = |list: &[Field]| list.iter().any(|&f| fields.contains(f));
    access
        .reads::<Neighbours>()
        .reads::<Position>()
        .reads::<Mass>()
        .reads_if::<Velocity>(has(&Field::VELOCITY))
        .reads_if::<Density>(has(&[Field::Rho, Field::Sound, Field::PRho2]))
        .reads_if::<Pressure>(has(&[Field::PRho2]))
}

/// How a pass computes each fluid pair (`Forces(pairs)`; the `Continuity` stage runs
/// `Auto`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Pairs {
    #[default]
    Auto,
    /// Once, for both particles, each particle summing its neighbours of higher index.
    Once,
    /// From each side: each particle sums its whole list.
    Twice,
}

impl Pairs {
    /// Whether the pass computes each pair once on the instruction set it runs.
    pub(crate) fn once(self) -> bool {
        match self {
            Pairs::Auto => sph_core::pair::Isa::detect() == sph_core::pair::Isa::SCALAR,
            Pairs::Once => true,
            Pairs::Twice => false,
        }
    }
}

/// Fluid particles per parallel chunk.
const CHUNK: usize = 256;

/// Which columns a pass writes.
#[derive(Clone, Copy)]
pub(crate) struct Outputs {
    /// dv/dt = the terms' sum + gravity, into `Acceleration`.
    pub acceleration: bool,
    /// d rho/dt into `DensityRate`.
    pub density_rate: bool,
    /// The energy rates ([`Power`]), returned.
    pub power: bool,
    /// The walls' power on the fluid into [`Power::wall`], from the sums over each
    /// particle's ghost neighbours (the lists put them last), which the pass then adds
    /// to the fluid neighbours' sums: no second pass. The terms must include
    /// continuity (`wall_work.rs`).
    pub wall: bool,
    /// Each particle's neighbours within the support into `NeighbourCount`, counted in
    /// the same loop (lists with a skin hold more).
    pub counts: bool,
    /// Each fluid pair computed once for both particles, where the terms allow it
    /// ([`Pairs`]).
    pub once: bool,
}

/// The energy rates of a pass [W per metre of depth].
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Power {
    /// The viscous dissipation rate (1/2) sum_i m_i P_i.
    pub viscous: f64,
    /// The rate at which density diffusion changes the internal energy,
    /// sum_i m_i (p_i/rho_i^2) D_i.
    pub diffusion: f64,
    /// The walls' power on the fluid (`wall_work.rs`), when asked.
    pub wall: f64,
}

/// Sums `terms` for every fluid particle and writes `out`; returns the energy rates
/// when asked (else 0). `scratch.chunk_power` keeps one partial sum per chunk of particles
/// between steps; the chunks are added in order, so the totals are the same for any
/// thread count.
///
/// With `kernel_sums` (a vector that is filled in, not appended to), the pass also
/// sums m_j W_ij for each particle (`vocab::KernelSums`); only the Riemann set has a
/// loop compiled for it, other sets run the generic loop then.
pub(crate) fn run(
    sim: &mut Sim,
    terms: &RateTerms,
    out: Outputs,
    scratch: &mut Scratch,
    kernel_sums: Option<&mut Vec<f64>>,
) -> Result<Power, StepError> {
    use crate::terms::set_of as bits;
    use TermBit::*;
    // The sets the shipped scenarios and studies run get loops compiled for them,
    // named by their terms: the pressure gradient (PG) with Monaghan's artificial
    // viscosity (AV) [and artificial pressure (AP)], continuity (C) and each density
    // diffusion (MC Molteni-Colagrossi, F Fourtakas, D delta-SPH); the Riemann set.
    const PG_AV_AP_C: u16 = bits(&[
        PressureGradient,
        ArtificialViscosity,
        ArtificialPressure,
        Continuity,
    ]);
    const PG_AV_C: u16 = bits(&[PressureGradient, ArtificialViscosity, Continuity]);
    const PG_AV: u16 = bits(&[PressureGradient, ArtificialViscosity]);
    const C: u16 = bits(&[Continuity]);
    const PG_AV_AP_C_MC: u16 = PG_AV_AP_C | bits(&[MolteniColagrossi]);
    const PG_AV_AP_C_F: u16 = PG_AV_AP_C | bits(&[Fourtakas]);
    const PG_AV_C_MC: u16 = PG_AV_C | bits(&[MolteniColagrossi]);
    const PG_AV_C_F: u16 = PG_AV_C | bits(&[Fourtakas]);
    const PG_AV_AP_C_D: u16 = PG_AV_AP_C | bits(&[DeltaSph]);
    const PG_AV_C_D: u16 = PG_AV_C | bits(&[DeltaSph]);
    const RIEMANN: u16 = bits(&[RiemannPressure, Continuity, RiemannDiffusion]);
    if let Some(sums) = kernel_sums {
        return match Fixed::<RIEMANN>::of(terms) {
            Some(set) if !generic_only() => run_set_with(sim, set, out, scratch, Some(sums)),
            _ => run_set_with(sim, *terms, out, scratch, Some(sums)),
        };
    }
    let none = &mut Vec::new();
    // 3D compiles loops for the Riemann set and the still tank's only: every compiled
    // set is a copy of the loop per kernel, instruction set and layout, and the 3D
    // build doubled the suite's build time; the others run the generic loop, at the
    // same results, until 3D scenarios use them.
    #[cfg(feature = "dim3")]
    let result = {
        // The 2D sets, named above, not compiled here.
        let _ = (
            PG_AV_AP_C,
            PG_AV_AP_C_F,
            PG_AV_AP_C_MC,
            PG_AV_C_MC,
            PG_AV_AP_C_D,
            PG_AV_C_D,
            PG_AV,
            C,
        );
        if generic_only() {
            run_set::<_, false>(sim, *terms, out, scratch, none)
        } else if let Some(set) = Fixed::<RIEMANN>::of(terms) {
            run_set::<_, false>(sim, set, out, scratch, none)
        } else if let Some(set) = Fixed::<PG_AV_C_F>::of(terms) {
            run_set::<_, false>(sim, set, out, scratch, none)
        } else {
            run_set::<_, false>(sim, *terms, out, scratch, none)
        }
    };
    #[cfg(not(feature = "dim3"))]
    let result = if generic_only() {
        run_set::<_, false>(sim, *terms, out, scratch, none)
    } else if let Some(set) = Fixed::<PG_AV_AP_C>::of(terms) {
        run_set::<_, false>(sim, set, out, scratch, none)
    } else if let Some(set) = Fixed::<RIEMANN>::of(terms) {
        run_set::<_, false>(sim, set, out, scratch, none)
    } else if let Some(set) = Fixed::<PG_AV_AP_C_F>::of(terms) {
        run_set::<_, false>(sim, set, out, scratch, none)
    } else if let Some(set) = Fixed::<PG_AV_C_F>::of(terms) {
        run_set::<_, false>(sim, set, out, scratch, none)
    } else if let Some(set) = Fixed::<PG_AV_AP_C_MC>::of(terms) {
        run_set::<_, false>(sim, set, out, scratch, none)
    } else if let Some(set) = Fixed::<PG_AV_C_MC>::of(terms) {
        run_set::<_, false>(sim, set, out, scratch, none)
    } else if let Some(set) = Fixed::<PG_AV_AP_C_D>::of(terms) {
        run_set::<_, false>(sim, set, out, scratch, none)
    } else if let Some(set) = Fixed::<PG_AV_C_D>::of(terms) {
        run_set::<_, false>(sim, set, out, scratch, none)
    } else if let Some(set) = Fixed::<PG_AV_C>::of(terms) {
        run_set::<_, false>(sim, set, out, scratch, none)
    } else if let Some(set) = Fixed::<PG_AV>::of(terms) {
        run_set::<_, false>(sim, set, out, scratch, none)
    } else if let Some(set) = Fixed::<C>::of(terms) {
        run_set::<_, false>(sim, set, out, scratch, none)
    } else {
        run_set::<_, false>(sim, *terms, out, scratch, none)
    };
    result
}

/// True when the environment variable `SPH_GENERIC_TERMS` is set (to any value): every
/// term set runs the generic loop, which tests each term per pair, instead of a loop
/// compiled for it (to measure what the compiled sets buy; the results are the same).
fn generic_only() -> bool {
    static GENERIC: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *GENERIC.get_or_init(|| std::env::var_os("SPH_GENERIC_TERMS").is_some())
}

/// [`run_set`] with the kernel sums when `kernel_sums` is given (the loop compiled
/// with or without them).
pub(crate) fn run_set_with<R: RateTerm + Copy>(
    sim: &mut Sim,
    terms: R,
    out: Outputs,
    scratch: &mut Scratch,
    kernel_sums: Option<&mut Vec<f64>>,
) -> Result<Power, StepError> {
    match kernel_sums {
        Some(sums) => run_set::<_, true>(sim, terms, out, scratch, sums),
        None => run_set::<_, false>(sim, terms, out, scratch, &mut Vec::new()),
    }
}

/// [`run`] for a term set `terms`; with `KERNEL_SUM`, each fluid particle's
/// sum_j m_j W_ij into `kernel_sums` (resized to the fluid).
fn run_set<R: RateTerm + Copy, const KERNEL_SUM: bool>(
    sim: &mut Sim,
    terms: R,
    out: Outputs,
    scratch: &mut Scratch,
    kernel_sums: &mut Vec<f64>,
) -> Result<Power, StepError> {
    let power = with_records(sim, terms.reads(), |sim, particles, records| {
        let Some(nb) = sim.resources.get::<Neighbours>() else {
            return Ok(Power::default());
        };
        let n = nb.n_fluid;
        let eom = Counted::<_, KERNEL_SUM> {
            term: EquationsOfMotion(terms),
            radius: nb.support,
        };
        kernel_sums.clear();
        if KERNEL_SUM {
            kernel_sums.resize(n, 0.0);
        }
        let mut acc = match out.acceleration {
            true => Some(particles.fluid_mut::<Acceleration>()?),
            false => None,
        };
        let mut rate = match out.density_rate {
            true => Some(particles.fluid_mut::<DensityRate>()?),
            false => None,
        };
        let mut counts = match out.counts {
            true => Some(particles.fluid_mut::<NeighbourCount>()?),
            false => None,
        };
        let state = match out.wall {
            true => Some((
                particles.fluid::<Velocity>()?,
                particles.fluid::<Density>()?,
                particles.fluid::<Mass>()?,
            )),
            false => None,
        };
        let lens = [
            acc.as_ref().map(|a| a.len()),
            rate.as_ref().map(|r| r.len()),
            counts.as_ref().map(|c| c.len()),
            state.as_ref().map(|s| s.0.len()),
        ];
        if let Some(len) = lens.into_iter().flatten().find(|&len| len != n) {
            return Err(StepError::Internal(format!(
                "the neighbour lists cover {n} fluid particles but the world holds {len}"
            )));
        }
        let acc: &mut [Acceleration] = acc.as_deref_mut().unwrap_or(&mut []);
        let rate: &mut [DensityRate] = rate.as_deref_mut().unwrap_or(&mut []);
        let counts: &mut [NeighbourCount] = counts.as_deref_mut().unwrap_or(&mut []);
        let state = state.as_ref().map(|(v, rho, m)| (&v[..], &rho[..], &m[..]));
        let chunks = n.div_ceil(CHUNK);
        scratch.chunk_power.clear();
        scratch.chunk_power.resize(
            if out.power || out.wall { chunks } else { 0 },
            Power::default(),
        );
        let (c, g) = (&sim.constants, sim.constants.gravity);
        let eos = c.eos;
        with_kernel!(c.kernel, c.h, |k| {
            let pass =
                Pass::new(&eom, k, records).map_err(|e| StepError::Internal(e.to_string()))?;
            if <Counted<EquationsOfMotion<R>, KERNEL_SUM> as PairTerm>::SYMMETRIC
                && out.once
                && nb.fluid_ascending
            {
                let out = Outs { acc, rate, counts };
                each_pair_once(&pass, nb, out, scratch, g, &eos, state);
            } else {
                optional_pieces(acc, n, CHUNK)
                    .zip(optional_pieces(rate, n, CHUNK))
                    .zip(optional_pieces(counts, n, CHUNK))
                    .zip(optional_pieces(&mut kernel_sums[..], n, CHUNK))
                    .zip(optional_pieces(&mut scratch.chunk_power[..], chunks, 1))
                    .enumerate()
                    .for_each(
                        |(c, ((((mut acc, mut rate), mut counts), mut sums), power))| {
                            let mut sum = Power::default();
                            for k in 0..(n - c * CHUNK).min(CHUNK) {
                                let i = c * CHUNK + k;
                                let list = nb.of(i);
                                // The ghost neighbours, last in the list, summed apart (for the
                                // walls' power; always, so that every rate stage adds a
                                // particle's pairs in the same order).
                                let ghosts = match list.last() {
                                    Some(&j) if j as usize >= n => {
                                        list.partition_point(|&j| (j as usize) < n)
                                    }
                                    _ => list.len(),
                                };
                                let (s, count, kernel) = if ghosts == list.len() {
                                    pass.sum(i, list)
                                } else {
                                    let (f, cf, kf) = pass.sum(i, &list[..ghosts]);
                                    let (w, cw, kw) = pass.sum(i, &list[ghosts..]);
                                    if let Some((v, rho, m)) = state {
                                        sum.wall += wall_work::particle_power(
                                            &eos, m[i].0, v[i].0, rho[i].0, &w,
                                        );
                                    }
                                    (f + w, cf + cw, kf + kw)
                                };
                                if let Some(k_sum) = sums.as_deref_mut() {
                                    k_sum[k] = kernel;
                                }
                                if let Some(a) = acc.as_deref_mut() {
                                    a[k].0 = s.acc + g;
                                }
                                if let Some(r) = rate.as_deref_mut() {
                                    r[k].0 = s.drho;
                                }
                                if let Some(n) = counts.as_deref_mut() {
                                    n[k].0 = count;
                                }
                                sum.viscous += s.power;
                                sum.diffusion += s.diffusion;
                            }
                            if let Some(p) = power {
                                p[0] = sum;
                            }
                        },
                    );
            }
            Ok::<(), StepError>(())
        })?;
        Ok(scratch
            .chunk_power
            .iter()
            .fold(Power::default(), |a, p| Power {
                viscous: a.viscous + p.viscous,
                diffusion: a.diffusion + p.diffusion,
                wall: a.wall + p.wall,
            }))
    })?;
    Ok(power.unwrap_or_default())
}

/// The columns a pass writes, each empty when not wanted.
struct Outs<'a> {
    acc: &'a mut [Acceleration],
    rate: &'a mut [DensityRate],
    counts: &'a mut [NeighbourCount],
}

/// Splits `records` into the ascending, disjoint `ranges` of fluid indices.
fn carve<'a>(
    records: &'a mut [[f64; SHARE]],
    ranges: &[(usize, usize)],
) -> Vec<&'a mut [[f64; SHARE]]> {
    let (mut rest, mut at) = (records, 0);
    ranges
        .iter()
        .map(|&(lo, hi)| {
            let (_, tail) = std::mem::take(&mut rest).split_at_mut(lo - at);
            let (window, tail) = tail.split_at_mut(hi - lo);
            (rest, at) = (tail, hi);
            window
        })
        .collect()
}

/// The pass with each fluid pair computed once ([`Pass::sum_both`]): particle i sums
/// its fluid neighbours of higher index and adds each one's share to that
/// particle's record of sums (`scratch.shares`: dv/dt, d rho/dt and the count), then
/// its ghosts (whose sums give the walls' power, as in the pass over whole lists).
///
/// Results are the same for any thread count: chunks of [`CHUNK`] particles run in
/// phases, and in each phase only chunks whose windows (their particles and the
/// highest neighbour they write) do not overlap run in parallel; a particle's record
/// is the sum of what each phase adds to it, in phase and then chunk order, each
/// chunk adding in particle and list order. The phase count is fixed by the lists
/// alone: chunk c writes below the start of chunk c + phases.
fn each_pair_once<T, K>(
    pass: &Pass<'_, T, K>,
    nb: &Neighbours,
    out: Outs<'_>,
    scratch: &mut Scratch,
    g: Vector,
    eos: &sph_core::sim::Tait,
    state: Option<(&[Velocity], &[Density], &[Mass])>,
) where
    T: PairTerm<Out = (RateSums, u32, f64)>,
    K: sph_core::kernel::Kernel,
{
    let n = nb.n_fluid;
    let chunks = n.div_ceil(CHUNK);
    let Scratch {
        chunk_power,
        shares,
        reach,
        done,
    } = scratch;
    shares.clear();
    shares.resize(n, [0.0; SHARE]);
    // One past the highest fluid particle each chunk writes: the upper neighbours are
    // the tail of each list's ascending fluid part.
    (0..chunks)
        .into_par_iter()
        .map(|c| {
            let range = c * CHUNK..((c + 1) * CHUNK).min(n);
            range.clone().fold(range.end, |top, i| {
                let [_, upper, _] = nb.parts(i);
                upper.last().map_or(top, |&j| top.max(j as usize + 1))
            })
        })
        .collect_into_vec(reach);
    let phases = (0..chunks)
        .map(|c| reach[c].div_ceil(CHUNK) - c)
        .max()
        .unwrap_or(1);
    for phase in 0..phases {
        let ids: Vec<usize> = (phase..chunks).step_by(phases).collect();
        let ranges: Vec<(usize, usize)> = ids.iter().map(|&c| (c * CHUNK, reach[c])).collect();
        ids.par_iter()
            .zip(carve(shares, &ranges))
            .map(|(&c, records)| {
                let mut window = Shares {
                    start: c * CHUNK,
                    records,
                };
                let mut sum = Power::default();
                for i in c * CHUNK..((c + 1) * CHUNK).min(n) {
                    let [_, upper, ghosts] = nb.parts(i);
                    let (mut s, mut count, _) = pass.sum_both(i, upper, &mut window);
                    if !ghosts.is_empty() {
                        let (w, cw, _) = pass.sum(i, ghosts);
                        if let Some((v, rho, m)) = state {
                            sum.wall +=
                                wall_work::particle_power(eos, m[i].0, v[i].0, rho[i].0, &w);
                        }
                        (s, count) = (s + w, count + cw);
                    }
                    let mut own = [0.0; SHARE];
                    own[SHARE_AX] = s.acc.x;
                    own[SHARE_AY] = s.acc.y;
                    #[cfg(feature = "dim3")]
                    {
                        own[sph_core::pair::SHARE_AZ] = s.acc.z;
                    }
                    own[SHARE_DRHO] = s.drho;
                    own[COUNT] = f64::from(count);
                    window.add(i, own);
                    sum.viscous += s.power;
                    sum.diffusion += s.diffusion;
                }
                (c, sum)
            })
            .collect_into_vec(done);
        for &(c, p) in done.iter() {
            if let Some(slot) = chunk_power.get_mut(c) {
                *slot = p;
            }
        }
    }
    // Gravity last, as in the pass over whole lists.
    let records = &shares[..];
    out.acc.par_iter_mut().zip(records).for_each(|(a, r)| {
        #[cfg(not(feature = "dim3"))]
        let shared = Vector::new(r[SHARE_AX], r[SHARE_AY]);
        #[cfg(feature = "dim3")]
        let shared = Vector::new(r[SHARE_AX], r[SHARE_AY], r[sph_core::pair::SHARE_AZ]);
        a.0 = shared + g;
    });
    out.rate
        .par_iter_mut()
        .zip(records)
        .for_each(|(d, r)| d.0 = r[SHARE_DRHO]);
    out.counts
        .par_iter_mut()
        .zip(records)
        .for_each(|(c, r)| c.0 = r[COUNT] as u32);
}

/// The slot of a particle's record that counts its neighbours within the support.
const COUNT: usize = Counted::<(), false>::COUNT_SLOT;

/// What the rate passes keep from step to step: each chunk's energy rates, and the
/// per-particle records of sums of the pass that computes each pair once.
#[derive(Default)]
pub(crate) struct Scratch {
    chunk_power: Vec<Power>,
    shares: Vec<[f64; SHARE]>,
    /// One past the highest particle each chunk writes.
    reach: Vec<usize>,
    done: Vec<(usize, Power)>,
}

/// Pieces of `per` elements of an optional output of `len` elements: the slice's own
/// pieces if it holds exactly `len`, else as many `None`s (the output is not wanted).
fn optional_pieces<T: Send>(
    out: &mut [T],
    len: usize,
    per: usize,
) -> impl IndexedParallelIterator<Item = Option<&mut [T]>> {
    use rayon::iter::Either;
    if out.len() == len && len > 0 {
        Either::Left(out.par_chunks_mut(per).map(Some))
    } else {
        Either::Right((0..len.div_ceil(per)).into_par_iter().map(|_| None))
    }
}
