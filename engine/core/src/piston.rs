//! A piston wave maker: a vertical paddle wall that moves horizontally with its own
//! prescribed motion, a sinusoidal stroke brought in by a ramp or a measured
//! displacement series. It is a [`Wall`](crate::components::Wall) entity that carries
//! its own [`Motion`] (a sway without roll) and the [`Piston`] marker, so the
//! kinematics ([`crate::kinematics`]) moves it independently of the tank, ghost walls
//! mirror across it with its velocity, and a probe finds it by its component.

use crate::dim::{self, Vector};
use crate::motion::{HarmonicSpec, Motion, MotionSeries, MotionSpec, SHORTEST_TIME};
use crate::units::shown;
use crate::units::Positive;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The piston as written in the scenario (`piston: (...)`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PistonSpec {
    /// Rest position of the paddle face [m]; the fluid lies on its right.
    pub x: f64,
    /// Paddle height [m]. Default: the tank's height.
    #[serde(default)]
    pub height: Option<Positive>,
    /// Stroke S [m]: the paddle is at x + (S/2) sin(2 pi t / period + phase), times the
    /// ramp. Give `stroke` and `period`, or `series`.
    #[serde(default)]
    pub stroke: Option<f64>,
    /// Period of the stroke [s].
    #[serde(default)]
    pub period: Option<Positive>,
    /// Phase [deg]. Default 0.
    #[serde(default)]
    pub phase: f64,
    /// Smooth start [s]: the stroke is multiplied by (1 - cos(pi t / ramp)) / 2 until
    /// t = ramp. Default: two periods.
    #[serde(default)]
    pub ramp: Option<f64>,
    /// A CSV of the paddle's displacement from `x`: columns time [s], position [m]
    /// (relative to the scenario file); cubic Hermite interpolation, held at its end
    /// values outside its time range.
    #[serde(default)]
    pub series: Option<String>,
}

impl PistonSpec {
    /// The wall's ends: from the top to the floor, so the fluid is on its right (in
    /// 3D the wall's a and b, at z = 0).
    pub fn ends(&self, tank_height: f64) -> (Vector, Vector) {
        let h = self.height.map_or(tank_height, |h| h.0);
        (dim::xy(self.x, h), dim::xy(self.x, 0.0))
    }

    /// The paddle's motion; `source` is the scenario file (for the series path). The
    /// error names the field at fault.
    pub fn motion(&self, source: &Path) -> Result<Motion, (&'static str, String)> {
        let pivot = dim::xy(self.x, 0.0);
        if let Some(file) = &self.series {
            if self.stroke.is_some() || self.period.is_some() {
                return Err((
                    "series",
                    "a piston series replaces `stroke` and `period`; give one or the other".into(),
                ));
            }
            let path = source.parent().unwrap_or(Path::new(".")).join(file);
            let series = MotionSeries::read(&path, true).map_err(|e| ("series", e.to_string()))?;
            return Ok(Motion::new(&MotionSpec::default(), pivot, Some(series)));
        }
        let (Some(stroke), Some(period)) = (self.stroke, self.period) else {
            return Err((
                "stroke",
                "a piston needs `stroke: <m>` and `period: <s>`, or `series: \"<file.csv>\"`"
                    .into(),
            ));
        };
        if !stroke.is_finite() || !self.phase.is_finite() {
            return Err(("stroke", "stroke and phase must be finite numbers".into()));
        }
        if period.0 < SHORTEST_TIME {
            return Err((
                "period",
                format!(
                    "{} s is out of range; accepted: seconds from {}",
                    shown(period.0),
                    shown(SHORTEST_TIME)
                ),
            ));
        }
        let ramp = self.ramp.unwrap_or(2.0 * period.0);
        if !(ramp == 0.0 || (ramp >= SHORTEST_TIME && ramp.is_finite())) {
            return Err((
                "ramp",
                format!(
                    "{} is out of range; accepted: 0 (no ramp) or seconds from {}",
                    shown(ramp),
                    shown(SHORTEST_TIME)
                ),
            ));
        }
        let spec = MotionSpec {
            sway: Some(HarmonicSpec {
                amplitude: 0.5 * stroke,
                period,
                phase: self.phase,
            }),
            ramp: Some(ramp),
            ..MotionSpec::default()
        };
        Ok(Motion::new(&spec, pivot, None))
    }
}

/// The piston wall's name in the scenario (sensors can sit on it: `wall: "piston"`).
pub const PISTON_WALL: &str = "piston";

/// Marks the wall entity that is the piston (its [`Motion`] is on the same entity).
#[derive(Clone, Copy, Debug, Default)]
pub struct Piston;

/// Biesel's first-order transfer function of a piston wave maker: wave height over
/// stroke, H/S = 2 (cosh 2kd - 1) / (sinh 2kd + 2kd) = 4 sinh^2(kd) / (2kd + sinh 2kd)
/// (docs/analytic.md section 5; Dean & Dalrymple 1991, ch. 6).
pub fn biesel_height_over_stroke(kd: f64) -> f64 {
    4.0 * kd.sinh().powi(2) / (2.0 * kd + (2.0 * kd).sinh())
}

/// The wavenumber k of the linear dispersion relation omega^2 = g k tanh(k d), by
/// Newton's method from the deep-water guess.
pub fn wavenumber(omega: f64, depth: f64, g: f64) -> f64 {
    let mut k = (omega * omega / g).max(omega / (g * depth).sqrt());
    for _ in 0..50 {
        let t = (k * depth).tanh();
        let f = g * k * t - omega * omega;
        let df = g * t + g * k * depth * (1.0 - t * t);
        let step = f / df;
        k -= step;
        if step.abs() < 1e-14 * k {
            break;
        }
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dispersion_and_biesel_limits() {
        let (g, d) = (9.81, 0.25);
        let w = 2.0 * std::f64::consts::PI;
        let k = wavenumber(w, d, g);
        assert!((g * k * (k * d).tanh() - w * w).abs() < 1e-10);
        // Shallow water: omega = k sqrt(g d); deep water: omega^2 = g k.
        let ks = wavenumber(0.01, 1.0, g);
        assert!((ks * (g * 1.0_f64).sqrt() / 0.01 - 1.0).abs() < 1e-4);
        let kd = wavenumber(30.0, 10.0, g);
        assert!((kd * g / 900.0 - 1.0).abs() < 1e-10);
        // Biesel: H/S -> kd in shallow water, -> 2 in deep water.
        assert!((biesel_height_over_stroke(1e-3) / 1e-3 - 1.0).abs() < 1e-3);
        assert!((biesel_height_over_stroke(20.0) - 2.0).abs() < 1e-6);
    }
}
