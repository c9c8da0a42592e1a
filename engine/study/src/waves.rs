//! Regular-wave analysis of gauge records: wave height by zero up-crossings, and the
//! first harmonic's amplitude and phase (least squares, [`crate::sweep::fit_harmonic`]),
//! from which two gauges give the wavenumber, and the split of a gauge array into
//! incident and reflected waves. [`WaveTheory`] compares a piston flume's gauges with
//! Biesel's wave height and the dispersion relation (`waves.md` after a run).

use crate::series::read_series;
use crate::sweep::fit_harmonic;
use sph_core::piston::{biesel_height_over_stroke, wavenumber};
use sph_scenario::Scenario;
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::Path;

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

/// A complex number, enough for the gauge-array algebra below.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Cplx(f64, f64);

impl Cplx {
    /// e^{i t}
    fn cis(t: f64) -> Self {
        Self(t.cos(), t.sin())
    }
    fn conj(self) -> Self {
        Self(self.0, -self.1)
    }
    fn norm2(self) -> f64 {
        self.0 * self.0 + self.1 * self.1
    }
}

impl std::ops::Add for Cplx {
    type Output = Self;
    fn add(self, b: Self) -> Self {
        Self(self.0 + b.0, self.1 + b.1)
    }
}

impl std::ops::Sub for Cplx {
    type Output = Self;
    fn sub(self, b: Self) -> Self {
        Self(self.0 - b.0, self.1 - b.1)
    }
}

impl std::ops::Mul for Cplx {
    type Output = Self;
    fn mul(self, b: Self) -> Self {
        Self(self.0 * b.0 - self.1 * b.1, self.0 * b.1 + self.1 * b.0)
    }
}

impl std::ops::Div for Cplx {
    type Output = Self;
    fn div(self, b: Self) -> Self {
        let n = b.norm2();
        let p = self * b.conj();
        Self(p.0 / n, p.1 / n)
    }
}

/// First harmonic at one gauge: position x [m], amplitude [m] and phase [rad] of
/// eta ~ a sin(omega t + phase) (as returned by [`harmonic`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaugeHarmonic {
    pub x: f64,
    pub amplitude: f64,
    pub phase: f64,
}

/// Incident and reflected waves fitted to a gauge array (Goda & Suzuki 1976 for two
/// gauges, least squares of Mansard & Funke 1980 for more).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WaveSplit {
    /// Amplitude of the wave travelling towards +x [m].
    pub incident: f64,
    /// Amplitude of the wave travelling towards -x [m].
    pub reflected: f64,
    /// Sum of squared misfits of the complex amplitudes [m^2]; zero for two gauges.
    pub residual: f64,
}

/// Splits the first harmonics at the gauges into eta = a_I sin(wt - kx + .) +
/// a_R sin(wt + kx + .) for wavenumber k, i.e. complex amplitudes
/// A(x) = I e^{-ikx} + R e^{ikx}, by least squares. Gauge spacings with k dx within
/// 0.1 pi of a multiple of pi cannot separate the two (a quarter wavelength apart is
/// best): None.
pub fn incident_reflected(gauges: &[GaugeHarmonic], k: f64) -> Option<WaveSplit> {
    // Normal equations [[n, s*], [s, n]] (I, R) = (b1, b2) with e = e^{-ikx}.
    let n = gauges.len() as f64;
    let (mut s, mut b1, mut b2) = (Cplx::default(), Cplx::default(), Cplx::default());
    let data: Vec<(Cplx, Cplx)> = gauges
        .iter()
        .map(|g| {
            (
                Cplx::cis(-k * g.x),
                Cplx(g.amplitude, 0.0) * Cplx::cis(g.phase),
            )
        })
        .collect();
    for &(e, a) in &data {
        s = s + e * e;
        b1 = b1 + e.conj() * a;
        b2 = b2 + e * a;
    }
    // Real, n^2 - |s|^2; for two gauges 4 sin^2(k dx). Goda & Suzuki's usable range
    // 0.1 pi < k dx < 0.9 pi is det >= n^2 sin^2(0.1 pi); below it noise is amplified
    // more than tenfold.
    let det = Cplx(n * n, 0.0) - s * s.conj();
    if gauges.len() < 2 || det.0 < n * n * (0.1 * PI).sin().powi(2) {
        return None;
    }
    let i = (Cplx(n, 0.0) * b1 - s.conj() * b2) / det;
    let r = (Cplx(n, 0.0) * b2 - s * b1) / det;
    let residual = data
        .iter()
        .map(|&(e, a)| (a - i * e - r * e.conj()).norm2())
        .sum();
    Some(WaveSplit {
        incident: i.norm2().sqrt(),
        reflected: r.norm2().sqrt(),
        residual,
    })
}

/// The wavenumber that best explains three or more gauges as an incident plus a
/// reflected wave (least residual of [`incident_reflected`]), searched within
/// `k_range`. Unlike a phase difference this is not biased by the partial standing wave
/// a reflection makes.
pub fn wavenumber_fit(gauges: &[GaugeHarmonic], k_range: (f64, f64)) -> Option<f64> {
    if gauges.len() < 3 {
        return None;
    }
    let misfit = |k: f64| incident_reflected(gauges, k).map_or(f64::INFINITY, |w| w.residual);
    // A fine scan finds the basin, golden sections refine it.
    let steps = 400;
    let dk = (k_range.1 - k_range.0) / steps as f64;
    let (best, _) = (0..=steps)
        .map(|j| k_range.0 + j as f64 * dk)
        .map(|k| (k, misfit(k)))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    let (mut lo, mut hi) = (best - dk, best + dk);
    let phi = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..60 {
        let (k1, k2) = (hi - phi * (hi - lo), lo + phi * (hi - lo));
        if misfit(k1) < misfit(k2) {
            hi = k2;
        } else {
            lo = k1;
        }
    }
    let k = 0.5 * (lo + hi);
    misfit(k).is_finite().then_some(k)
}

/// Linear theory for a flume driven by a sinusoidal piston (docs/analytic.md section 5),
/// and the gauges to compare with it.
#[derive(Clone, Debug, PartialEq)]
pub struct WaveTheory {
    /// Still-water depth d [m] (the tallest fluid block).
    pub depth: f64,
    /// Angular frequency of the stroke [rad/s].
    pub omega: f64,
    /// Wavenumber of the dispersion relation omega^2 = g k tanh(k d) [1/m].
    pub k: f64,
    /// Biesel's first-order wave height H = S (H/S)(kd) [m].
    pub height: f64,
    /// Gauges (name, x [m]).
    pub gauges: Vec<(String, f64)>,
    /// Analysis window [s]: the last four periods of the run, from when the fully
    /// ramped wave has reached the farthest gauge at the group velocity on.
    pub window: (f64, f64),
}

/// The measured waves against [`WaveTheory`].
#[derive(Clone, Debug, PartialEq)]
pub struct WaveReport {
    pub theory: WaveTheory,
    /// Per gauge: (name, first-harmonic height 2a [m], mean zero-up-crossing height [m]).
    pub heights: Vec<(String, f64, Option<f64>)>,
    /// Wavenumber fitted to three or more gauges with the reflection accounted for.
    pub k_fit: Option<f64>,
    /// Incident and reflected amplitudes over all gauges at the theoretical k.
    pub split: Option<WaveSplit>,
}

impl WaveTheory {
    /// For a scenario with a sinusoidal piston and wave gauges that the ramped wave
    /// reaches at least two periods before the end; None otherwise.
    pub fn from_scenario(scenario: &Scenario) -> Option<Self> {
        let piston = scenario.spec.piston.as_ref()?;
        let (stroke, period) = (piston.stroke?, piston.period?.0);
        if scenario.spec.wave_gauges.is_empty() {
            return None;
        }
        let depth = scenario.fluid_height();
        let omega = 2.0 * PI / period;
        let g = scenario.spec.fluid.gravity.1.abs();
        let k = wavenumber(omega, depth, g);
        let end = scenario.spec.end_time.0;
        // Group velocity c_g = (omega / 2k)(1 + 2kd / sinh 2kd).
        let group = omega / (2.0 * k) * (1.0 + 2.0 * k * depth / (2.0 * k * depth).sinh());
        let farthest = scenario
            .spec
            .wave_gauges
            .iter()
            .map(|g| g.x - piston.x)
            .fold(0.0, f64::max);
        let ramp = piston.ramp.unwrap_or(2.0 * period);
        let arrival = ramp + farthest / group;
        let start = (end - 4.0 * period).max(arrival);
        if end - start < 2.0 * period {
            return None;
        }
        Some(Self {
            depth,
            omega,
            k,
            height: stroke.abs() * biesel_height_over_stroke(k * depth),
            gauges: scenario
                .spec
                .wave_gauges
                .iter()
                .map(|g| (g.name.clone(), g.x))
                .collect(),
            window: (start, end),
        })
    }

    /// Reads the gauges from `probes.csv` and fits them over the window.
    pub fn measure(&self, probes: &Path) -> Result<WaveReport, crate::StudyError> {
        let (t0, t1) = self.window;
        let mut heights = Vec::new();
        let mut harmonics = Vec::new();
        for (name, x) in &self.gauges {
            let (t, eta): (Vec<f64>, Vec<f64>) = read_series(probes, name)
                .map_err(|e| crate::StudyError::Missing {
                    error: Box::new(e),
                    hint: "wave gauges need `wave_gauges` and a Probe()",
                })?
                .into_iter()
                .unzip();
            let (amplitude, phase) = harmonic(&t, &eta, self.omega, t0, t1).ok_or_else(|| {
                crate::StudyError::TooFewSamples {
                    path: probes.to_path_buf(),
                    what: name.clone(),
                    from: t0,
                    to: t1,
                }
            })?;
            heights.push((
                name.clone(),
                2.0 * amplitude,
                mean_wave_height(&t, &eta, t0, t1),
            ));
            harmonics.push(GaugeHarmonic {
                x: *x,
                amplitude,
                phase,
            });
        }
        Ok(WaveReport {
            k_fit: wavenumber_fit(&harmonics, (0.5 * self.k, 1.5 * self.k)),
            split: incident_reflected(&harmonics, self.k),
            heights,
            theory: self.clone(),
        })
    }
}

impl WaveReport {
    /// Relative error of the fitted wavenumber against the dispersion relation.
    pub fn k_error(&self) -> Option<f64> {
        self.k_fit.map(|k| k / self.theory.k - 1.0)
    }

    /// Reflected over incident amplitude.
    pub fn reflection(&self) -> Option<f64> {
        self.split.map(|w| w.reflected / w.incident)
    }

    /// One line for the terminal.
    pub fn summary(&self) -> String {
        let th = &self.theory;
        let mut line = format!("waves: Biesel H = {:.4} m;", th.height);
        for (name, h, _) in &self.heights {
            let _ = write!(line, " {name} {:+.1} %", 100.0 * (h / th.height - 1.0));
        }
        if let Some(e) = self.k_error() {
            let _ = write!(line, "; k {:+.1} % of dispersion", 100.0 * e);
        }
        if let Some(r) = self.reflection() {
            let _ = write!(line, "; reflection {:.2}", r);
        }
        line
    }

    /// `waves.md`: the comparison as a table, with the window and the methods.
    pub fn markdown(&self) -> String {
        let th = &self.theory;
        let pct = |m: f64, t: f64| format!("{:+.1} %", 100.0 * (m / t - 1.0));
        let mut md = format!(
            "# Waves against linear theory\n\nWindow {:.2}-{:.2} s (at most the last four periods, \
             after the ramped wave has reached the farthest gauge). \
             Depth d = {:.4} m, omega = {:.4} rad/s; dispersion k = {:.4} 1/m \
             (L = {:.4} m, kd = {:.3}); Biesel H = {:.4} m.\n\n\
             | gauge | x [m] | H first harmonic [m] | error | H zero up-crossing [m] | error |\n\
             |---|---|---|---|---|---|\n",
            th.window.0,
            th.window.1,
            th.depth,
            th.omega,
            th.k,
            2.0 * PI / th.k,
            th.k * th.depth,
            th.height
        );
        for ((name, h, hz), (_, x)) in self.heights.iter().zip(&th.gauges) {
            let (zc, zc_err) = hz.map_or(("-".into(), "-".into()), |z| {
                (format!("{z:.4}"), pct(z, th.height))
            });
            let _ = writeln!(
                md,
                "| {name} | {x:.4} | {h:.4} | {} | {zc} | {zc_err} |",
                pct(*h, th.height)
            );
        }
        if let Some(k) = self.k_fit {
            let _ = write!(
                md,
                "\nWavenumber fitted to the gauges as incident plus reflected wave: k = {k:.4} 1/m \
                 ({} of the dispersion relation).\n",
                pct(k, th.k)
            );
        }
        if let Some(w) = self.split {
            let _ = write!(
                md,
                "\nIncident wave height {:.4} m ({} of Biesel), reflected {:.4} m: \
                 reflection coefficient {:.3}.\n",
                2.0 * w.incident,
                pct(2.0 * w.incident, th.height),
                2.0 * w.reflected,
                w.reflected / w.incident
            );
        }
        md
    }
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
    fn gauges_split_a_partly_reflected_wave_and_give_its_wavenumber() {
        let (ai, ar, omega, k) = (0.027, 0.004, 2.0 * PI / 1.5, 2.22);
        let t: Vec<f64> = (0..1200).map(|i| i as f64 * 0.01).collect();
        let gauge = |x: f64| {
            let eta: Vec<f64> = t
                .iter()
                .map(|&t| ai * (omega * t - k * x).sin() + ar * (omega * t + k * x + 0.7).sin())
                .collect();
            let (amplitude, phase) = harmonic(&t, &eta, omega, 0.0, 12.0).unwrap();
            GaugeHarmonic {
                x,
                amplitude,
                phase,
            }
        };
        let g = [gauge(2.0), gauge(2.7075), gauge(3.415)];
        // Two gauges: the exact Goda-Suzuki split.
        let w = incident_reflected(&g[..2], k).unwrap();
        assert!((w.incident / ai - 1.0).abs() < 1e-9, "{w:?}");
        assert!((w.reflected / ar - 1.0).abs() < 1e-9, "{w:?}");
        // Half a wavelength apart the two waves cannot be told apart.
        assert!(incident_reflected(&[g[0], g[2]], PI / (3.415 - 2.0)).is_none());
        // Three gauges: the residual vanishes at the true wavenumber only.
        let k_fit = wavenumber_fit(&g, (1.5, 3.0)).unwrap();
        assert!((k_fit / k - 1.0).abs() < 1e-6, "{k_fit}");
        // Whereas the phase lag between two of them is biased by the reflection.
        let k_lag = wavenumber_from_phases(g[0].phase, g[1].phase, g[1].x - g[0].x);
        assert!((k_lag / k - 1.0).abs() > 0.01, "{k_lag}");
    }

    #[test]
    fn a_flume_record_is_measured_against_its_theory() {
        // A probes.csv holding exactly the theory's wave plus a 5 % reflection.
        let (omega, k, h) = (2.0 * PI / 1.5, 2.2233, 0.0541);
        let theory = WaveTheory {
            depth: 0.5,
            omega,
            k,
            height: h,
            gauges: vec![
                ("G1".into(), 2.0),
                ("G2".into(), 2.7075),
                ("G3".into(), 3.415),
            ],
            window: (6.0, 12.0),
        };
        let mut csv = String::from("time,G1,G2,G3\n");
        for i in 0..=1200 {
            let t = i as f64 * 0.01;
            let eta = |x: f64| {
                0.5 * h * (omega * t - k * x).sin() + 0.025 * h * (omega * t + k * x).sin()
            };
            csv += &format!("{t},{},{},{}\n", eta(2.0), eta(2.7075), eta(3.415));
        }
        let path = std::env::temp_dir().join(format!("sph_waves_{}.csv", std::process::id()));
        std::fs::write(&path, csv).unwrap();
        let report = theory.measure(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        assert!(report.k_error().unwrap().abs() < 1e-6);
        assert!((report.reflection().unwrap() - 0.05).abs() < 1e-6);
        assert!((2.0 * report.split.unwrap().incident / h - 1.0).abs() < 1e-6);
        assert!(report.markdown().contains("| G2 | 2.7075 |"));
        assert!(theory
            .measure(Path::new("/nonexistent/probes.csv"))
            .is_err());
    }
}
