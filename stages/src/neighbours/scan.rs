//! The neighbour search's candidate scan: from the particles of the cells around a
//! fluid particle, keep those within one kernel support (docs/physics.md, "Neighbour
//! search"). Most candidates are rejected (about 21 of 60 are kept), so this loop is
//! the grid stage's cost.
//!
//! Two implementations give the same lists, element for element: a portable scalar one
//! (a branch-free append) and, where the processor has AVX-512, one that tests eight
//! candidates at a time and compresses the kept ones to the front. The distance
//! test is the same arithmetic in both (dx*dx + dy*dy < r_s^2, no fused multiply-add),
//! so a run's numbers do not depend on which one the machine uses.

use sph_core::components::Position;
use sph_core::dim::Vector;
use sph_core::vocab::{resize_by_eighths, CellGrid, NeighbourBlock};
use std::ops::Range;

/// The candidate scan this machine runs, chosen once per step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scan {
    Scalar,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Scan {
    /// The fastest scan the processor supports.
    pub fn detect() -> Self {
        static SCAN: std::sync::OnceLock<Scan> = std::sync::OnceLock::new();
        *SCAN.get_or_init(Self::probe)
    }

    /// [`Scan::detect`]'s answer, worked out once per process.
    fn probe() -> Self {
        #[cfg(target_arch = "x86_64")]
        if sph_core::pair::simd_allowed()
            && std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512vl")
            && std::arch::is_x86_feature_detected!("popcnt")
        {
            return Scan::Avx512;
        }
        Scan::Scalar
    }

    /// Every scan this processor can run (for tests comparing them).
    pub fn available() -> Vec<Self> {
        let mut all = vec![Scan::Scalar];
        if Self::detect() != Scan::Scalar {
            all.push(Self::detect());
        }
        all
    }

    /// Builds the neighbour lists of fluid particles `range` into `block`.
    pub(crate) fn build_block(
        self,
        grid: &CellGrid,
        fpos: &[Position],
        r2max: f64,
        range: Range<usize>,
        block: &mut NeighbourBlock,
    ) {
        match self {
            Scan::Scalar => build_block(grid, fpos, r2max, range, block, scan_scalar),
            // SAFETY: `detect` found AVX-512F, VL and POPCNT on this processor.
            #[cfg(target_arch = "x86_64")]
            Scan::Avx512 => unsafe { avx512::build_block(grid, fpos, r2max, range, block) },
        }
    }
}

/// A reproducible stream of numbers in [0, 1) for the unit tests (a 64-bit linear
/// congruential generator).
#[cfg(test)]
pub(crate) fn test_numbers(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The candidates of one row of cells: their x, y (and z in 3D) and joint indices.
pub(crate) struct Candidates<'a> {
    pub xs: &'a [f64],
    pub ys: &'a [f64],
    #[cfg(feature = "dim3")]
    pub zs: &'a [f64],
    pub ids: &'a [u32],
}

/// Builds the lists of `range` with `scan`, which writes to the front of `out` the
/// indices of the candidates within sqrt(`r2max`) of `xi`, except `i` itself, in
/// candidate order, and returns how many (`out` holds at least as many elements as
/// there are candidates). Generic, so the scan is inlined.
#[inline(always)]
fn build_block(
    grid: &CellGrid,
    fpos: &[Position],
    r2max: f64,
    range: Range<usize>,
    block: &mut NeighbourBlock,
    scan: impl Fn(Vector, u32, f64, &Candidates, &mut [u32]) -> usize,
) {
    block.offsets.clear();
    block.offsets.push(0);
    block.list.clear();
    for i in range {
        let xi = fpos[i].0;
        let ranges = grid.ranges_near(xi);
        let base = block.list.len();
        let total: usize = ranges.iter().map(|r| r.len()).sum();
        resize_by_eighths(&mut block.list, base + total, 0);
        let mut len = base;
        for cand in ranges {
            let c = Candidates {
                xs: &grid.xs[cand.clone()],
                ys: &grid.ys[cand.clone()],
                #[cfg(feature = "dim3")]
                zs: &grid.zs[cand.clone()],
                ids: &grid.particles[cand],
            };
            len += scan(xi, i as u32, r2max, &c, &mut block.list[len..]);
        }
        block.list.truncate(len);
        block.offsets.push(len as u32);
    }
}

/// The portable scan: write every candidate, keep it (advance the length) if it is
/// within the support and not i itself.
#[inline(always)]
fn scan_scalar(xi: Vector, i: u32, r2max: f64, c: &Candidates, out: &mut [u32]) -> usize {
    let out = &mut out[..c.ids.len()];
    let mut kept = 0;
    #[cfg(not(feature = "dim3"))]
    for ((&x, &y), &j) in c.xs.iter().zip(c.ys).zip(c.ids) {
        let (dx, dy) = (xi.x - x, xi.y - y);
        let keep = (dx * dx + dy * dy < r2max) & (j != i);
        out[kept] = j;
        kept += keep as usize;
    }
    #[cfg(feature = "dim3")]
    for (((&x, &y), &z), &j) in c.xs.iter().zip(c.ys).zip(c.zs).zip(c.ids) {
        let (dx, dy, dz) = (xi.x - x, xi.y - y, xi.z - z);
        let keep = (dx * dx + dy * dy + dz * dz < r2max) & (j != i);
        out[kept] = j;
        kept += keep as usize;
    }
    kept
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::*;
    use std::arch::x86_64::*;

    /// [`super::build_block`] compiled for AVX-512 with the eight-lane scan inlined.
    ///
    /// # Safety
    /// The processor must support AVX-512F, AVX-512VL and POPCNT.
    #[target_feature(enable = "avx512f,avx512vl,popcnt")]
    pub(super) unsafe fn build_block(
        grid: &CellGrid,
        fpos: &[Position],
        r2max: f64,
        range: Range<usize>,
        block: &mut NeighbourBlock,
    ) {
        super::build_block(grid, fpos, r2max, range, block, |xi, i, r2, c, out| {
            // SAFETY: this closure only runs inside this function, on a processor
            // with the features it was compiled for.
            unsafe { scan(xi, i, r2, c, out) }
        });
    }

    /// Eight candidates at a time: masked loads for the tail, the distance test as in
    /// [`super::scan_scalar`], and the kept indices compressed to the front.
    #[target_feature(enable = "avx512f,avx512vl,popcnt")]
    #[inline]
    pub(super) unsafe fn scan(
        xi: Vector,
        i: u32,
        r2max: f64,
        c: &Candidates,
        out: &mut [u32],
    ) -> usize {
        let n = c.ids.len();
        assert!(c.xs.len() == n && c.ys.len() == n && out.len() >= n);
        #[cfg(feature = "dim3")]
        assert!(c.zs.len() == n);
        let (px, py) = (_mm512_set1_pd(xi.x), _mm512_set1_pd(xi.y));
        #[cfg(feature = "dim3")]
        let pz = _mm512_set1_pd(xi.z);
        let r2 = _mm512_set1_pd(r2max);
        let me = _mm256_set1_epi32(i as i32);
        let mut kept = 0usize;
        let mut k = 0usize;
        while k < n {
            let lanes: __mmask8 = if n - k >= 8 {
                0xff
            } else {
                (1u8 << (n - k)) - 1
            };
            // SAFETY: the masked loads read only lanes k..min(k + 8, n) of slices of
            // length n. The kept indices are compressed in a register and stored: all
            // eight lanes where out[kept..] has room for them (a plain store is much
            // faster than a compress-store), else only the kept ones, popcount(keep)
            // <= n - k elements at out[kept..] with kept <= k, within out[..n].
            unsafe {
                let x = _mm512_maskz_loadu_pd(lanes, c.xs.as_ptr().add(k));
                let y = _mm512_maskz_loadu_pd(lanes, c.ys.as_ptr().add(k));
                let j = _mm256_maskz_loadu_epi32(lanes, c.ids.as_ptr().add(k) as *const i32);
                let (dx, dy) = (_mm512_sub_pd(px, x), _mm512_sub_pd(py, y));
                let d2 = _mm512_add_pd(_mm512_mul_pd(dx, dx), _mm512_mul_pd(dy, dy));
                #[cfg(feature = "dim3")]
                let d2 = {
                    let z = _mm512_maskz_loadu_pd(lanes, c.zs.as_ptr().add(k));
                    let dz = _mm512_sub_pd(pz, z);
                    _mm512_add_pd(d2, _mm512_mul_pd(dz, dz))
                };
                let near = _mm512_mask_cmp_pd_mask::<_CMP_LT_OQ>(lanes, d2, r2);
                let keep = near & _mm256_cmpneq_epi32_mask(j, me);
                let packed = _mm256_maskz_compress_epi32(keep, j);
                let count = keep.count_ones() as usize;
                let at = out.as_mut_ptr().add(kept);
                if kept + 8 <= out.len() {
                    _mm256_storeu_si256(at as *mut __m256i, packed);
                } else {
                    _mm256_mask_storeu_epi32(at as *mut i32, ((1u16 << count) - 1) as u8, packed);
                }
                kept += count;
            }
            k += 8;
        }
        kept
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every available scan keeps the same candidates in the same order, including
    /// candidates exactly on the support, the particle itself and short tails.
    #[test]
    fn every_scan_keeps_the_same_candidates() {
        let mut next = test_numbers(12345);
        let r2max = 1.0;
        for n in 0..40 {
            let mut xs: Vec<f64> = (0..n).map(|_| 2.0 * next() - 1.0).collect();
            let ys: Vec<f64> = (0..n).map(|_| 2.0 * next() - 1.0).collect();
            if n > 3 {
                xs[2] = 1.0; // exactly on the support (y may push it out or not)
            }
            let ids: Vec<u32> = (0..n as u32).map(|j| 3 * j).collect();
            #[cfg(feature = "dim3")]
            let zs: Vec<f64> = (0..n).map(|_| 2.0 * next() - 1.0).collect();
            let c = Candidates {
                xs: &xs,
                ys: &ys,
                #[cfg(feature = "dim3")]
                zs: &zs,
                ids: &ids,
            };
            let me = if n > 5 { ids[5] } else { u32::MAX };
            let lists: Vec<Vec<u32>> = Scan::available()
                .into_iter()
                .map(|scan| {
                    let mut out = vec![0; n];
                    let k = match scan {
                        Scan::Scalar => scan_scalar(Vector::ZERO, me, r2max, &c, &mut out),
                        #[cfg(target_arch = "x86_64")]
                        Scan::Avx512 => unsafe {
                            avx512::scan(Vector::ZERO, me, r2max, &c, &mut out)
                        },
                    };
                    out.truncate(k);
                    out
                })
                .collect();
            #[cfg(not(feature = "dim3"))]
            let d2 = |k: usize| xs[k] * xs[k] + ys[k] * ys[k];
            #[cfg(feature = "dim3")]
            let d2 = |k: usize| xs[k] * xs[k] + ys[k] * ys[k] + zs[k] * zs[k];
            let expected: Vec<u32> = (0..n)
                .filter(|&k| d2(k) < r2max && ids[k] != me)
                .map(|k| ids[k])
                .collect();
            for list in &lists {
                assert_eq!(list, &expected, "n = {n}");
            }
        }
    }
}
