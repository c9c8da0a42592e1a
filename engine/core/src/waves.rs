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
}
