//! Regular-wave analysis of gauge records: wave height by zero up-crossings, and the
//! first harmonic's amplitude and phase (least squares, [`crate::sweep::fit_harmonic`]),
//! from which two gauges give the wavenumber. Used by the wave-maker validation.

use crate::sweep::fit_harmonic;
use std::f64::consts::PI;

/// Mean crest-to-trough height of the complete waves (zero up-crossing to zero
/// up-crossing about the window's mean level) in `t0 <= t <= t1`; None if the window
/// holds no complete wave.
pub fn mean_wave_height(t: &[f64], eta: &[f64], t0: f64, t1: f64) -> Option<f64> {
    let (_, eta) = window(t, eta, t0, t1);
    let mean = eta.iter().sum::<f64>() / eta.len().max(1) as f64;
    let up: Vec<usize> = (1..eta.len())
        .filter(|&i| eta[i - 1] - mean < 0.0 && eta[i] - mean >= 0.0)
        .collect();
    let heights: Vec<f64> = up
        .windows(2)
        .map(|w| {
            let wave = &eta[w[0]..w[1]];
            let max = wave.iter().copied().fold(f64::MIN, f64::max);
            let min = wave.iter().copied().fold(f64::MAX, f64::min);
            max - min
        })
        .collect();
    (!heights.is_empty()).then(|| heights.iter().sum::<f64>() / heights.len() as f64)
}

/// First-harmonic amplitude and phase [rad] of `eta` at angular frequency `omega` over
/// `t0 <= t <= t1`: eta ~ a sin(omega t + phase) + mean.
pub fn harmonic(t: &[f64], eta: &[f64], omega: f64, t0: f64, t1: f64) -> Option<(f64, f64)> {
    let (t, eta) = window(t, eta, t0, t1);
    fit_harmonic(&t, &eta, omega)
}

/// The samples with `t0 <= t <= t1`.
fn window(t: &[f64], y: &[f64], t0: f64, t1: f64) -> (Vec<f64>, Vec<f64>) {
    t.iter()
        .zip(y)
        .filter(|(t, _)| (t0..=t1).contains(*t))
        .map(|(t, y)| (*t, *y))
        .unzip()
}

/// Wavenumber from the phases of a progressive wave eta = a sin(omega t - k x) at two
/// gauges `dx` apart (downstream minus upstream), with `dx` shorter than a wavelength
/// so the phase difference is unambiguous.
pub fn wavenumber_from_phases(phase_up: f64, phase_down: f64, dx: f64) -> f64 {
    let lag = (phase_up - phase_down).rem_euclid(2.0 * PI);
    lag / dx
}

/// Incident and reflected wave amplitudes from two gauges (Goda & Suzuki 1976): the
/// first harmonics (amplitude, phase) at x1 and x2 of eta = a_I sin(wt - kx + .) +
/// a_R sin(wt + kx + .), with k the wavenumber; k (x2 - x1) must stay away from
/// multiples of pi (a quarter wavelength apart is best). Returns (a_I, a_R).
pub fn incident_reflected(g1: (f64, f64), g2: (f64, f64), k: f64, x1: f64, x2: f64) -> (f64, f64) {
    // Complex amplitudes A(x) = I e^{-ikx} + R e^{ikx}, as (re, im) pairs.
    type C = (f64, f64);
    let mul = |a: C, b: C| (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0);
    let sub = |a: C, b: C| (a.0 - b.0, a.1 - b.1);
    let cis = |t: f64| (t.cos(), t.sin());
    let abs = |a: C| a.0.hypot(a.1);
    let (a1, a2) = (mul((g1.0, 0.0), cis(g1.1)), mul((g2.0, 0.0), cis(g2.1)));
    // Determinant 2i sin(k dx); only its modulus matters for the amplitudes.
    let det = 2.0 * (k * (x2 - x1)).sin().abs();
    let incident = sub(mul(a1, cis(k * x2)), mul(a2, cis(k * x1)));
    let reflected = sub(mul(a2, cis(-k * x1)), mul(a1, cis(-k * x2)));
    (abs(incident) / det, abs(reflected) / det)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sampled_progressive_wave_gives_back_its_height_and_wavenumber() {
        let (a, omega, k) = (0.027, 2.0 * PI / 1.5, 2.22);
        let t: Vec<f64> = (0..1200).map(|i| i as f64 * 0.01).collect();
        let eta = |x: f64| -> Vec<f64> {
            t.iter()
                .map(|&t| 0.5 + a * (omega * t - k * x).sin())
                .collect()
        };
        let (g1, g3) = (eta(2.0), eta(3.415));
        let h = mean_wave_height(&t, &g1, 3.0, 11.0).unwrap();
        // Sampled at 0.01 s a crest is caught within omega^2 dt^2 / 8 of its height.
        assert!((h / (2.0 * a) - 1.0).abs() < 1e-3, "{h}");
        let (a1, p1) = harmonic(&t, &g1, omega, 3.0, 11.0).unwrap();
        let (_, p3) = harmonic(&t, &g3, omega, 3.0, 11.0).unwrap();
        assert!((a1 / a - 1.0).abs() < 1e-9);
        let k_fit = wavenumber_from_phases(p1, p3, 1.415);
        assert!((k_fit / k - 1.0).abs() < 1e-9, "{k_fit}");
        assert!(mean_wave_height(&t, &g1, 3.0, 3.5).is_none());
    }

    #[test]
    fn two_gauges_split_a_partly_reflected_wave() {
        let (ai, ar, omega, k) = (0.027, 0.004, 2.0 * PI / 1.5, 2.22);
        let t: Vec<f64> = (0..1200).map(|i| i as f64 * 0.01).collect();
        let eta = |x: f64| -> Vec<f64> {
            t.iter()
                .map(|&t| ai * (omega * t - k * x).sin() + ar * (omega * t + k * x + 0.7).sin())
                .collect()
        };
        let (x1, x2) = (2.0, 2.7075);
        let h1 = harmonic(&t, &eta(x1), omega, 0.0, 12.0).unwrap();
        let h2 = harmonic(&t, &eta(x2), omega, 0.0, 12.0).unwrap();
        let (i, r) = incident_reflected(h1, h2, k, x1, x2);
        assert!(
            (i / ai - 1.0).abs() < 1e-9 && (r / ar - 1.0).abs() < 1e-9,
            "{i} {r}"
        );
    }
}
