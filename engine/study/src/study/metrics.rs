//! The study metrics as pure functions of time series and particle sets, each with a
//! unit test on a constructed input whose answer is known.
//!
//! A series is a list of (t, y) samples in time order. Windows are closed: [from, to].

use glam::DVec2;
use std::collections::HashMap;

/// Linear interpolation of `series` at `t`, clamped to its end values; NaN if empty.
pub fn interpolate(series: &[(f64, f64)], t: f64) -> f64 {
    match series.iter().position(|p| p.0 >= t) {
        Some(0) => series[0].1,
        Some(k) => {
            let (a, b) = (series[k - 1], series[k]);
            a.1 + (b.1 - a.1) * (t - a.0) / (b.0 - a.0)
        }
        None => series.last().map_or(f64::NAN, |p| p.1),
    }
}

/// The reference points inside the window and inside the simulated time span (a run
/// that stopped early is compared only where it has data).
fn compared<'a>(
    sim: &'a [(f64, f64)],
    reference: &'a [(f64, f64)],
    from: f64,
    to: f64,
) -> impl Iterator<Item = (f64, f64)> + 'a {
    let end = sim.last().map_or(f64::NEG_INFINITY, |p| p.0);
    reference
        .iter()
        .filter(move |p| p.0 >= from && p.0 <= to && p.0 <= end)
        .map(move |&(t, r)| (interpolate(sim, t), r))
}

/// RMS difference sqrt(mean_k (s(t_k) - r_k)^2) over the reference samples r_k at
/// t_k in [from, to], the simulation s interpolated linearly; NaN if none.
pub fn rms_difference(sim: &[(f64, f64)], reference: &[(f64, f64)], from: f64, to: f64) -> f64 {
    rms(compared(sim, reference, from, to).map(|(s, r)| s - r))
}

/// RMS relative difference sqrt(mean_k (s(t_k)/r_k - 1)^2) over [from, to] (as
/// [`rms_difference`]); used for the surge front, whose size grows with time.
pub fn rms_relative(sim: &[(f64, f64)], reference: &[(f64, f64)], from: f64, to: f64) -> f64 {
    rms(compared(sim, reference, from, to).map(|(s, r)| s / r - 1.0))
}

/// Normalised mean absolute error mean_k |s(t_k) - r_k| / max_k |r_k| over the
/// reference samples in [from, to] (as [`rms_difference`]): the error as a fraction of
/// the measured range from zero (a water height, a pressure); NaN if none.
pub fn nmae(sim: &[(f64, f64)], reference: &[(f64, f64)], from: f64, to: f64) -> f64 {
    let (n, sum, scale) = compared(sim, reference, from, to)
        .fold((0usize, 0.0, 0.0_f64), |(n, sum, scale), (s, r)| {
            (n + 1, sum + (s - r).abs(), scale.max(r.abs()))
        });
    if n == 0 || scale == 0.0 {
        f64::NAN
    } else {
        sum / n as f64 / scale
    }
}

/// The first time at or after `from` that `series` reaches `level` from below, linearly
/// interpolated between the samples around the crossing; None if it never does.
pub fn arrival(series: &[(f64, f64)], level: f64, from: f64) -> Option<f64> {
    let mut before: Option<(f64, f64)> = None;
    for &(t, y) in series.iter().filter(|p| p.0 >= from) {
        if y >= level {
            return Some(match before {
                Some((t0, y0)) if y0 < level => t0 + (t - t0) * (level - y0) / (y - y0),
                _ => t,
            });
        }
        before = Some((t, y));
    }
    None
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (n, sum) = values.fold((0usize, 0.0), |(n, s), v| (n + 1, s + v * v));
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    }
}

/// The largest sample in [from, to] as (time, value); NaN values if none.
pub fn peak(series: &[(f64, f64)], from: f64, to: f64) -> (f64, f64) {
    series
        .iter()
        .filter(|p| p.0 >= from && p.0 <= to)
        .fold((f64::NAN, f64::NAN), |best, &p| {
            if best.1.is_nan() || p.1 > best.1 {
                p
            } else {
                best
            }
        })
}

/// The largest (`largest`) or smallest sample in [from, to]; NaN if none. The density
/// fluctuation and neighbour-count metrics are extremes of their probe columns.
pub fn extreme(series: &[(f64, f64)], from: f64, to: f64, largest: bool) -> f64 {
    let inside = series
        .iter()
        .filter(|p| p.0 >= from && p.0 <= to)
        .map(|p| p.1);
    if largest {
        inside.fold(f64::NAN, f64::max)
    } else {
        inside.fold(f64::NAN, f64::min)
    }
}

/// Total variation TV = sum_k |y_{k+1} - y_k| over the samples in [from, to]: a
/// measure of a signal's roughness (a monotone signal's TV is its net change; noise
/// adds twice its amplitude per oscillation). NaN with fewer than two samples.
pub fn total_variation(series: &[(f64, f64)], from: f64, to: f64) -> f64 {
    let inside: Vec<f64> = series
        .iter()
        .filter(|p| p.0 >= from && p.0 <= to)
        .map(|p| p.1)
        .collect();
    if inside.len() < 2 {
        return f64::NAN;
    }
    inside.windows(2).map(|w| (w[1] - w[0]).abs()).sum()
}

/// Mean absolute difference (1/n) sum_k |y_k - expected| over the samples at t >= from;
/// NaN if none. The hydrostatic pressure error with expected = rho_0 g (H - y_s).
pub fn mean_abs_error(series: &[(f64, f64)], expected: f64, from: f64) -> f64 {
    let (n, sum) = series
        .iter()
        .filter(|p| p.0 >= from)
        .fold((0usize, 0.0), |(n, s), p| {
            (n + 1, s + (p.1 - expected).abs())
        });
    if n == 0 {
        f64::NAN
    } else {
        sum / n as f64
    }
}

/// Angular frequency [rad/s] of an oscillating signal from its zero crossings about
/// its mean over t >= from: with n crossings at t_1 < ... < t_n (linearly interpolated),
/// omega = pi (n - 1) / (t_n - t_1), half a period between crossings. NaN with fewer
/// than three crossings.
pub fn crossing_frequency(series: &[(f64, f64)], from: f64) -> f64 {
    let inside: Vec<(f64, f64)> = series.iter().copied().filter(|p| p.0 >= from).collect();
    if inside.is_empty() {
        return f64::NAN;
    }
    let mean = inside.iter().map(|p| p.1).sum::<f64>() / inside.len() as f64;
    let crossings: Vec<f64> = inside
        .windows(2)
        .filter_map(|w| {
            let (a, b) = (w[0].1 - mean, w[1].1 - mean);
            (a < 0.0 && b >= 0.0 || a >= 0.0 && b < 0.0)
                .then(|| w[0].0 + (w[1].0 - w[0].0) * a / (a - b))
        })
        .collect();
    match (crossings.first(), crossings.last()) {
        (Some(&t1), Some(&tn)) if crossings.len() >= 3 => {
            std::f64::consts::PI * (crossings.len() - 1) as f64 / (tn - t1)
        }
        _ => f64::NAN,
    }
}

/// Fraction of the mechanical energy E = kinetic + potential lost by time t:
/// (E(0) - E(t)) / E(0), E interpolated; the potential is zero at y = 0, so E(0) is the
/// column's initial potential energy. NaN if t is beyond the series.
pub fn energy_loss(energy: &[(f64, f64)], t: f64) -> f64 {
    match (energy.first(), energy.last()) {
        (Some(&(_, e0)), Some(&(end, _))) if t <= end + 1e-12 => (e0 - interpolate(energy, t)) / e0,
        _ => f64::NAN,
    }
}

/// Spattered particles: fluid particles with fewer than `min_neighbours` other fluid
/// particles within `radius` of them — isolated drops or pairs thrown off the bulk,
/// whose own kernel sums are meaningless. (With radius 2 ds a particle inside the bulk
/// has about 12 such neighbours, one on a flat free surface about 8, so the count
/// excludes the surface itself.)
pub fn spattered(positions: &[DVec2], radius: f64, min_neighbours: usize) -> usize {
    let cell = |p: DVec2| ((p.x / radius).floor() as i64, (p.y / radius).floor() as i64);
    let mut grid: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
    for (i, &p) in positions.iter().enumerate() {
        grid.entry(cell(p)).or_default().push(i);
    }
    let r2 = radius * radius;
    positions
        .iter()
        .enumerate()
        .filter(|&(i, &p)| {
            let (cx, cy) = cell(p);
            let mut n = 0;
            for dx in -1..=1 {
                for dy in -1..=1 {
                    if let Some(list) = grid.get(&(cx + dx, cy + dy)) {
                        n += list
                            .iter()
                            .filter(|&&j| j != i && (positions[j] - p).length_squared() <= r2)
                            .count();
                    }
                }
            }
            n < min_neighbours
        })
        .count()
}

/// Particles outside the box [lo, hi] (the tank's walls): lost through a wall.
pub fn outside(positions: &[DVec2], lo: DVec2, hi: DVec2) -> usize {
    positions
        .iter()
        .filter(|p| p.x < lo.x || p.y < lo.y || p.x > hi.x || p.y > hi.y)
        .count()
}

/// The whole periods of length `period` from `from` to the series' end, as the window's
/// end `from + n period` (n >= 1), or None if the series is shorter than one period
/// after `from` or the period is not positive.
fn whole_periods_end(series: &[(f64, f64)], from: f64, period: f64) -> Option<(usize, f64)> {
    let end = series.last()?.0;
    // NaNs fail both comparisons.
    if period.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
        || end.partial_cmp(&from) != Some(std::cmp::Ordering::Greater)
    {
        return None;
    }
    // A sample interval's worth of slack: a run that ends on a period boundary has its
    // last sample up to one interval before it, and keeps that period.
    let interval = match series {
        [.., a, b] => (b.0 - a.0).max(0.0),
        _ => 0.0,
    };
    let n = ((end + interval - from) / period).floor();
    (n >= 1.0).then_some((n as usize, from + n * period))
}

/// First harmonic of a forced response over the whole periods from `from`: the least-
/// squares fit y = a sin(w t + phi) + c with w = 2 pi / period (see
/// [`crate::waves::harmonic`]), as (a, lag) where lag = `forcing_phase` - phi in
/// degrees, wrapped into (-180, 180]: how far the response trails a forcing
/// A sin(w t + forcing_phase). NaNs if less than one whole period is available.
pub fn forced_harmonic(
    series: &[(f64, f64)],
    period: f64,
    forcing_phase_deg: f64,
    from: f64,
) -> (f64, f64) {
    let Some((_, to)) = whole_periods_end(series, from, period) else {
        return (f64::NAN, f64::NAN);
    };
    let (t, y): (Vec<f64>, Vec<f64>) = series.iter().copied().unzip();
    let omega = 2.0 * std::f64::consts::PI / period;
    match crate::waves::harmonic(&t, &y, omega, from, to) {
        Some((a, phi)) => {
            let lag = (forcing_phase_deg - phi.to_degrees()).rem_euclid(360.0);
            (a, if lag > 180.0 { lag - 360.0 } else { lag })
        }
        None => (f64::NAN, f64::NAN),
    }
}

/// The largest sample in each whole period [from + k T, from + (k + 1) T) to the
/// series' end, in time order (NaN for a period holding a NaN sample: f64::max would
/// drop it). Empty if less than one whole period.
pub fn period_peak_list(series: &[(f64, f64)], period: f64, from: f64) -> Vec<f64> {
    let Some((n, _)) = whole_periods_end(series, from, period) else {
        return Vec::new();
    };
    (0..n)
        .map(|k| {
            let lo = from + k as f64 * period;
            let inside = series.iter().filter(|p| p.0 >= lo && p.0 < lo + period);
            inside.fold(f64::NEG_INFINITY, |m, p| {
                if m.is_nan() || p.1.is_nan() {
                    f64::NAN
                } else {
                    m.max(p.1)
                }
            })
        })
        .collect()
}

/// The per-period peaks of [`period_peak_list`] as (median, maximum): the statistics
/// of impacts that recur once per forcing period. NaNs if less than one whole period
/// or if a period holds a NaN.
pub fn period_peaks(series: &[(f64, f64)], period: f64, from: f64) -> (f64, f64) {
    let mut peaks = period_peak_list(series, period, from);
    let n = peaks.len();
    if n == 0 || peaks.iter().any(|p| !p.is_finite()) {
        return (f64::NAN, f64::NAN);
    }
    peaks.sort_by(f64::total_cmp);
    let median = if n % 2 == 1 {
        peaks[n / 2]
    } else {
        0.5 * (peaks[n / 2 - 1] + peaks[n / 2])
    };
    (median, peaks[n - 1])
}

/// How far a value lies outside the band [lo, hi], relative to the edge it passed:
/// (v - hi)/hi above, (v - lo)/lo below (negative), 0 inside; NaN for a NaN value or
/// band.
pub fn band_distance(v: f64, lo: f64, hi: f64) -> f64 {
    if v.is_nan() || lo.is_nan() || hi.is_nan() {
        f64::NAN
    } else if v > hi {
        (v - hi) / hi
    } else if v < lo {
        (v - lo) / lo
    } else {
        0.0
    }
}

/// Indices of the Pareto-optimal points (x, y), both to be minimised: no other point
/// is at least as good in both and better in one. Non-finite points are never optimal.
/// Returned in increasing x.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].0.is_finite() && points[i].1.is_finite())
        .collect();
    order.sort_by(|&a, &b| {
        points[a]
            .0
            .total_cmp(&points[b].0)
            .then(points[a].1.total_cmp(&points[b].1))
    });
    let mut best = f64::INFINITY;
    order
        .into_iter()
        .filter(|&i| {
            let keep = points[i].1 < best;
            best = best.min(points[i].1);
            keep
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn sampled(f: impl Fn(f64) -> f64, t1: f64, n: usize) -> Vec<(f64, f64)> {
        (0..=n)
            .map(|k| {
                let t = t1 * k as f64 / n as f64;
                (t, f(t))
            })
            .collect()
    }

    #[test]
    fn rms_of_a_constant_offset_is_the_offset_and_only_the_window_counts() {
        let sim = sampled(|t| t + 0.5, 10.0, 100);
        let reference: Vec<(f64, f64)> = (0..=10).map(|k| (k as f64, k as f64)).collect();
        assert!((rms_difference(&sim, &reference, 2.0, 6.0) - 0.5).abs() < 1e-12);
        // Relative: s/r - 1 = 0.5/r over r = 2, 3, 4.
        let expected = ((0.25f64.powi(2) + (0.5f64 / 3.0).powi(2) + 0.125f64.powi(2)) / 3.0).sqrt();
        assert!((rms_relative(&sim, &reference, 2.0, 4.5) - expected).abs() < 1e-12);
        // A run that stopped at t = 3 is compared only up to there.
        let short = sampled(|t| t + 1.0, 3.0, 30);
        assert!((rms_difference(&short, &reference, 0.0, 10.0) - 1.0).abs() < 1e-12);
        assert!(rms_difference(&short, &reference, 5.0, 10.0).is_nan());
    }

    #[test]
    fn nmae_is_the_mean_error_over_the_largest_reference_value() {
        let reference = [(0.0, 0.0), (1.0, 2.0), (2.0, -4.0), (3.0, 1.0)];
        // Off by 1 everywhere: mean error 1 over |-4|.
        let sim: Vec<(f64, f64)> = reference.iter().map(|&(t, y)| (t, y + 1.0)).collect();
        assert!((nmae(&sim, &reference, 0.0, 3.0) - 0.25).abs() < 1e-12);
        // The window and the simulated span both bound it: only t = 1, 2 count.
        let short = &sim[..3];
        assert!((nmae(short, &reference, 1.0, 3.0) - 0.25).abs() < 1e-12);
        let half = [(0.0, 0.0), (1.0, 2.0), (2.0, -3.0)];
        assert!((nmae(&half, &reference, 1.0, 2.0) - 1.0 / 8.0).abs() < 1e-12);
        assert!(nmae(&sim, &reference, 5.0, 6.0).is_nan());
    }

    #[test]
    fn arrival_is_the_interpolated_first_crossing_after_from() {
        let s = [(0.0, 0.0), (1.0, 1.0), (2.0, 3.0), (3.0, 0.0), (4.0, 5.0)];
        assert_eq!(arrival(&s, 2.0, 0.0), Some(1.5));
        assert_eq!(arrival(&s, 1.0, 0.0), Some(1.0));
        assert_eq!(arrival(&s, 2.0, 2.5), Some(3.0 + 2.0 / 5.0));
        assert_eq!(arrival(&s, 0.0, 0.0), Some(0.0));
        assert_eq!(arrival(&s, 9.0, 0.0), None);
    }

    #[test]
    fn peak_finds_the_largest_sample_in_the_window() {
        let s = sampled(
            |t| (-(t - 2.0) * (t - 2.0)).exp() + 3.0 * (-(t - 8.0).powi(2)).exp(),
            10.0,
            1000,
        );
        let (t, v) = peak(&s, 0.0, 5.0);
        assert!((t - 2.0).abs() < 1e-9 && (v - 1.0).abs() < 1e-6);
        let (t, v) = peak(&s, 0.0, 10.0);
        assert!((t - 8.0).abs() < 1e-9 && (v - 3.0).abs() < 1e-6);
    }

    #[test]
    fn extremes_of_a_window() {
        let s = sampled(|t| (t - 1.0) * (t - 1.0), 3.0, 300);
        assert!((extreme(&s, 0.0, 3.0, true) - 4.0).abs() < 1e-12);
        assert!(extreme(&s, 0.0, 3.0, false).abs() < 1e-12);
        assert!((extreme(&s, 2.0, 2.5, false) - 1.0).abs() < 1e-12);
        assert!(extreme(&s, 5.0, 6.0, true).is_nan());
    }

    #[test]
    fn total_variation_of_a_sine_is_four_amplitudes_per_period() {
        let s = sampled(|t| 2.0 * (2.0 * PI * t).sin(), 3.0, 3000);
        assert!((total_variation(&s, 0.0, 3.0) - 3.0 * 4.0 * 2.0).abs() < 1e-6);
        // A ramp: its net change only.
        let ramp = sampled(|t| 5.0 * t, 1.0, 10);
        assert!((total_variation(&ramp, 0.0, 1.0) - 5.0).abs() < 1e-12);
        assert!(total_variation(&ramp, 2.0, 3.0).is_nan());
    }

    #[test]
    fn hydrostatic_error_is_the_mean_absolute_deviation_after_from() {
        let s: Vec<(f64, f64)> = (0..10)
            .map(|k| (k as f64, if k % 2 == 0 { 11.0 } else { 8.0 }))
            .collect();
        // From t = 2: 11, 8, 11, 8, 11, 8, 11, 8 against 10: mean of 1 and 2.
        assert!((mean_abs_error(&s, 10.0, 2.0) - 1.5).abs() < 1e-12);
    }

    #[test]
    fn crossing_frequency_recovers_a_known_frequency_with_offset() {
        let omega = 3.7;
        let s = sampled(|t| 4.0 + (omega * t + 0.3).cos(), 20.0, 20_000);
        assert!((crossing_frequency(&s, 1.0) / omega - 1.0).abs() < 2e-3);
        assert!(crossing_frequency(&sampled(|t| t, 1.0, 10), 0.0).is_nan());
    }

    #[test]
    fn energy_loss_is_the_lost_fraction_of_the_initial_energy() {
        let e = sampled(|t| 100.0 - 10.0 * t, 2.0, 20);
        assert!((energy_loss(&e, 1.5) - 0.15).abs() < 1e-12);
        assert!(energy_loss(&e, 3.0).is_nan());
    }

    #[test]
    fn spatter_counts_isolated_particles_not_the_bulk_or_its_surface() {
        let ds = 0.01;
        let mut x: Vec<DVec2> = Vec::new();
        for i in 0..20 {
            for j in 0..10 {
                x.push(DVec2::new(i as f64 * ds, j as f64 * ds));
            }
        }
        assert_eq!(spattered(&x, 2.0 * ds, 3), 0);
        // A lone drop, and a pair far from the bulk and from each other.
        x.push(DVec2::new(1.0, 1.0));
        x.push(DVec2::new(2.0, 1.0));
        x.push(DVec2::new(2.0 + ds, 1.0));
        assert_eq!(spattered(&x, 2.0 * ds, 3), 3);
        assert_eq!(spattered(&x, 2.0 * ds, 1), 1);
    }

    #[test]
    fn outside_counts_particles_beyond_the_walls() {
        let x = [
            DVec2::new(0.5, 0.5),
            DVec2::new(-0.1, 0.5),
            DVec2::new(0.5, -0.1),
            DVec2::new(0.8, 3.0),
        ];
        assert_eq!(outside(&x, DVec2::ZERO, DVec2::new(1.0, f64::INFINITY)), 2);
        assert_eq!(outside(&x, DVec2::ZERO, DVec2::ONE), 3);
    }

    #[test]
    fn pareto_front_keeps_only_undominated_points() {
        let p = [
            (1.0, 5.0),
            (2.0, 3.0),
            (3.0, 4.0),
            (4.0, 1.0),
            (2.0, 6.0),
            (f64::NAN, 0.0),
            (5.0, 1.0),
        ];
        assert_eq!(pareto_front(&p), vec![0, 1, 3]);
    }

    #[test]
    fn forced_harmonic_gives_amplitude_and_lag_behind_the_forcing() {
        let period = 1.6;
        let w = 2.0 * PI / period;
        // y trails sin(w t) by 95 deg, with an offset and a third harmonic that the
        // first-harmonic fit over whole periods must ignore.
        let y =
            |t: f64| 3.0 + 120.0 * (w * t - 95f64.to_radians()).sin() + 30.0 * (3.0 * w * t).sin();
        let s = sampled(y, 8.0, 8000);
        let (a, lag) = forced_harmonic(&s, period, 0.0, 1.6);
        assert!((a - 120.0).abs() < 1e-6, "{a}");
        assert!((lag - 95.0).abs() < 1e-6, "{lag}");
        // Against a forcing of phase 100 deg the response trails by 195 deg, which
        // wraps to -165 (a lead of 165 deg).
        let (_, lag) = forced_harmonic(&s, period, 100.0, 1.6);
        assert!((lag + 165.0).abs() < 1e-6, "{lag}");
        // Less than a whole period after `from`: nothing to fit.
        assert!(forced_harmonic(&s, period, 0.0, 7.0).0.is_nan());
        assert!(forced_harmonic(&s, -1.0, 0.0, 0.0).0.is_nan());
    }

    #[test]
    fn period_peaks_take_the_median_and_largest_of_one_peak_per_period() {
        // One spike per period of heights 5, 1, 9, 3 (periods of 2 s from t = 1), on a
        // zero background; the partial period after t = 9 is not counted.
        let heights = [5.0, 1.0, 9.0, 3.0, 100.0];
        let s = sampled(
            |t| {
                let k = ((t - 1.0) / 2.0).floor();
                let phase = t - 1.0 - 2.0 * k;
                if t >= 1.0 && (phase - 0.5).abs() < 0.01 {
                    heights[k as usize]
                } else {
                    0.0
                }
            },
            9.9,
            9900,
        );
        let (median, max) = period_peaks(&s, 2.0, 1.0);
        assert_eq!((median, max), (4.0, 9.0));
        // Sampled every 0.001 s up to t = 8.9995, one sample short of the fourth period's
        // end at t = 9: that period still counts.
        let short: Vec<(f64, f64)> = s.iter().copied().filter(|p| p.0 < 8.9995).collect();
        assert_eq!(period_peaks(&short, 2.0, 1.0), (4.0, 9.0));
        // A NaN sample in a period is not dropped: the statistics are NaN.
        let mut bad = s.clone();
        bad[3000].1 = f64::NAN;
        assert!(period_peaks(&bad, 2.0, 1.0).0.is_nan());
        assert!(period_peaks(&s, 2.0, 9.5).0.is_nan());
    }

    #[test]
    fn period_peak_list_keeps_the_order_and_band_distance_is_relative_to_the_edge() {
        let heights = [5.0, 1.0, 9.0, 3.0];
        let s = sampled(
            |t| {
                let k = ((t - 1.0) / 2.0).floor();
                let near = t >= 1.0 && (t - 1.0 - 2.0 * k - 0.5).abs() < 0.01;
                if near && (k as usize) < heights.len() {
                    heights[k as usize]
                } else {
                    0.0
                }
            },
            9.0,
            9000,
        );
        assert_eq!(period_peak_list(&s, 2.0, 1.0), heights.to_vec());
        assert!(period_peak_list(&s, 2.0, 8.5).is_empty());
        // The band 2-4: inside reads 0, above (v - 4)/4, below (v - 2)/2.
        assert_eq!(band_distance(3.0, 2.0, 4.0), 0.0);
        assert_eq!(band_distance(4.0, 2.0, 4.0), 0.0);
        assert_eq!(band_distance(6.0, 2.0, 4.0), 0.5);
        assert_eq!(band_distance(1.0, 2.0, 4.0), -0.5);
        assert!(band_distance(f64::NAN, 2.0, 4.0).is_nan());
        assert!(band_distance(3.0, f64::NAN, 4.0).is_nan());
    }
}
