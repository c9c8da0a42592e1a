//! Prescribed rigid-body motion of the tank: a constant tilt plus harmonic roll about a
//! pivot, with optional sway and heave, and in 3D a harmonic pitch, all brought in by a
//! smooth start; or a measured time series (time, angle[, x, y]) read from CSV.
//!
//! The tank frame is the frame the scenario's geometry is written in. A point q of the
//! tank is at x = P + (s, hv) + R(theta) (q - P) in the world, P the pivot, (s, hv) the
//! sway and heave, theta the roll angle (counter-clockwise positive). In 3D the roll
//! turns about the z axis through P and the pitch phi then turns the rolled tank about
//! the x axis through P: x = P + (s, hv, 0) + R_x(phi) R_z(theta) (q - P).

use crate::dim::{self, Vector};
use crate::units::Positive;
use glam::DVec2;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::path::Path;

/// The shortest period or ramp [s] a motion accepts: below it 1/T^2 in the
/// acceleration overflows towards infinity (a period of 1e-320 s made the tank's
/// acceleration infinite), and no flow resolves it anyway.
pub const SHORTEST_TIME: f64 = 1e-6;

/// A harmonic component `amplitude sin(2 pi t / period + phase)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HarmonicSpec {
    /// Amplitude: degrees for roll, metres for sway and heave.
    pub amplitude: f64,
    /// Period [s].
    pub period: Positive,
    /// Phase [deg]. Default 0.
    #[serde(default)]
    pub phase: f64,
}

/// The tank's motion as written in the scenario (`tank: (..., motion: (...))`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotionSpec {
    /// Roll axis in the tank frame [m]. Default: the centre of the tank bottom.
    pub pivot: Option<(f64, f64)>,
    /// Constant tilt [deg], counter-clockwise, reached through the ramp. Default 0.
    pub tilt: f64,
    /// Roll theta(t) = amplitude [deg] sin(2 pi t / period + phase).
    pub roll: Option<HarmonicSpec>,
    /// Pitch phi(t) = amplitude [deg] sin(2 pi t / period + phase) about the x axis
    /// through the pivot, after the roll (3D only: a 2D scene has no x axis to turn
    /// about). Positive turns +y towards +z. Left out of a resolved scenario when
    /// absent, so that 2D files read as before.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pitch: Option<HarmonicSpec>,
    /// Horizontal displacement of the pivot [m].
    pub sway: Option<HarmonicSpec>,
    /// Vertical displacement of the pivot [m].
    pub heave: Option<HarmonicSpec>,
    /// Smooth start [s]: tilt, roll, pitch, sway and heave are multiplied by
    /// r(t) = (1 - cos(pi t / ramp)) / 2 until t = ramp. Default: the longest period
    /// given (0, a sudden start, when there is none).
    pub ramp: Option<f64>,
    /// A CSV time series instead of the harmonics: columns time [s], angle [deg] and
    /// optionally x, y [m] (pivot displacement); `#` comments and one header line
    /// allowed; relative to the scenario file. Interpolated by cubic Hermite splines;
    /// held at its end values outside its time range. No ramp applies: the liquid
    /// starts moving with the tank at the series' first velocity.
    pub series: Option<String>,
}

/// Position, velocity and acceleration of the tank frame at one instant.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RigidState {
    /// Roll angle theta [rad], its rate [rad/s] and acceleration [rad/s^2].
    pub angle: f64,
    pub omega: f64,
    pub alpha: f64,
    /// Displacement of the pivot [m], its velocity and acceleration (in the x-y
    /// plane: sway and heave).
    pub offset: Vector,
    pub velocity: Vector,
    pub acceleration: Vector,
    /// Pitch phi [rad], its rate [rad/s] and acceleration [rad/s^2] (3D).
    #[cfg(feature = "dim3")]
    pub pitch: Pitch,
}

/// A pitch phi [rad] about the x axis, its rate [rad/s] and acceleration [rad/s^2],
/// with the pitched z axis k = R_x(phi) z worked out once, not at every point whose
/// velocity is asked for (3D).
#[cfg(feature = "dim3")]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pitch {
    values: [f64; 3],
    k: Vector,
}

#[cfg(feature = "dim3")]
impl Default for Pitch {
    fn default() -> Self {
        Self::new([0.0; 3])
    }
}

#[cfg(feature = "dim3")]
impl Pitch {
    /// The pitch [phi, phi', phi''] [rad, rad/s, rad/s^2], with its k.
    pub fn new(values: [f64; 3]) -> Self {
        let (s, c) = values[0].sin_cos();
        Self {
            values,
            k: Vector::new(0.0, -s, c),
        }
    }
    /// [phi, phi', phi''].
    pub fn values(&self) -> [f64; 3] {
        self.values
    }
}

/// Where the tank frame is: maps tank-frame points to the world and back, and gives the
/// rigid velocity and acceleration of any world point attached to the tank.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose {
    /// The pivot in the tank frame (and in the world at rest); in 3D the roll axis is
    /// the line through it along z, the pitch axis the line through it along x.
    pub pivot: Vector,
    pub state: RigidState,
}

/// A [`Pose`]'s map from the tank frame to the world ([`Pose::placement`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    centre: Vector,
    pivot: Vector,
    /// (cos, sin) of the angle.
    rotation: DVec2,
    /// (cos, sin) of the pitch (3D).
    #[cfg(feature = "dim3")]
    pitch: DVec2,
}

impl Placement {
    /// A tank-frame point in the world.
    pub fn to_world(&self, q: Vector) -> Vector {
        let rolled = dim::rotate_z(self.rotation, q - self.pivot);
        #[cfg(feature = "dim3")]
        let rolled = rotate_x(self.pitch, rolled);
        self.centre + rolled
    }
}

/// `v` turned about the x axis by the angle whose (cos, sin) is `rotation` (+y towards
/// +z): the pitch.
#[cfg(feature = "dim3")]
fn rotate_x(rotation: DVec2, v: Vector) -> Vector {
    let (c, s) = (rotation.x, rotation.y);
    Vector::new(v.x, c * v.y - s * v.z, s * v.y + c * v.z)
}

impl Pose {
    pub fn at_rest(pivot: Vector) -> Self {
        Self {
            pivot,
            state: RigidState::default(),
        }
    }
    /// The pivot's world position.
    pub fn centre(&self) -> Vector {
        self.pivot + self.state.offset
    }
    /// A tank-frame point in the world.
    pub fn to_world(&self, q: Vector) -> Vector {
        self.placement().to_world(q)
    }
    /// The map from the tank frame to the world, its rotation worked out once (for
    /// placing many points).
    pub fn placement(&self) -> Placement {
        Placement {
            centre: self.centre(),
            pivot: self.pivot,
            rotation: DVec2::from_angle(self.state.angle),
            #[cfg(feature = "dim3")]
            pitch: DVec2::from_angle(self.state.pitch.values()[0]),
        }
    }
    /// A world point in the tank frame.
    pub fn to_body(&self, x: Vector) -> Vector {
        let r = x - self.centre();
        #[cfg(feature = "dim3")]
        let r = rotate_x(DVec2::from_angle(-self.state.pitch.values()[0]), r);
        self.pivot + dim::rotate_z(DVec2::from_angle(-self.state.angle), r)
    }
    /// Velocity of the tank at world point x: V + omega k x r.
    pub fn velocity_at(&self, x: Vector) -> Vector {
        #[cfg(feature = "dim3")]
        if let Some((omega, _)) = self.spin() {
            return self.state.velocity + omega.cross(x - self.centre());
        }
        self.state.velocity + self.state.omega * dim::z_cross(x - self.centre())
    }
    /// Acceleration of the tank at world point x: A + alpha k x r - omega^2 r, r's part
    /// in the x-y plane (the distance from the z axis through the pivot).
    pub fn acceleration_at(&self, x: Vector) -> Vector {
        let r = x - self.centre();
        #[cfg(feature = "dim3")]
        if let Some((omega, alpha)) = self.spin() {
            return self.state.acceleration + alpha.cross(r) + omega.cross(omega.cross(r));
        }
        self.state.acceleration + self.state.alpha * dim::z_cross(r)
            - self.state.omega.powi(2) * dim::in_xy(r)
    }
    /// A pitching tank's angular velocity and acceleration, world vectors; `None`
    /// without pitch, where the roll's formulas above are these with omega along z.
    /// The roll turns about the pitched z axis k = R_x(phi) z, so with e_x the pitch
    /// axis: omega = phi' e_x + theta' k, alpha = phi'' e_x + theta'' k + theta' phi'
    /// (e_x x k).
    #[cfg(feature = "dim3")]
    fn spin(&self) -> Option<(Vector, Vector)> {
        let Pitch { values, k } = self.state.pitch;
        let [_, rate, accel] = values;
        if values == [0.0; 3] {
            return None;
        }
        let e_x = Vector::X;
        let st = &self.state;
        let omega = rate * e_x + st.omega * k;
        let alpha = accel * e_x + st.alpha * k + st.omega * rate * e_x.cross(k);
        Some((omega, alpha))
    }
}

/// A harmonic a sin(w t + phi) with its first two derivatives.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Wave {
    amplitude: f64,
    omega: f64,
    phase: f64,
}

impl Wave {
    fn from_spec(s: &HarmonicSpec, scale: f64) -> Self {
        Self {
            amplitude: s.amplitude * scale,
            omega: 2.0 * PI / s.period.0,
            phase: s.phase.to_radians(),
        }
    }
    /// (value, first derivative, second derivative) at t.
    fn at(&self, t: f64) -> [f64; 3] {
        let (s, c) = (self.omega * t + self.phase).sin_cos();
        let (a, w) = (self.amplitude, self.omega);
        [a * s, a * w * c, -a * w * w * s]
    }
}

/// A tabulated motion: time, angle [rad], x, y [m].
#[derive(Clone, Debug, PartialEq)]
pub struct MotionSeries {
    t: Vec<f64>,
    /// Columns angle, x, y.
    values: [Vec<f64>; 3],
}

impl MotionSeries {
    /// Reads `time, angle[deg][, x, y]` rows (a tank), or with `positions` `time, x`
    /// rows (a piston's displacement [m]). Errors name the line.
    pub fn read(path: &Path, positions: bool) -> Result<Self, SeriesError> {
        let text = std::fs::read_to_string(path).map_err(|e| SeriesError::Read {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        let parsed = if positions {
            Self::parse_positions(&text)
        } else {
            Self::parse(&text)
        };
        parsed.map_err(|e| SeriesError::In {
            path: path.to_path_buf(),
            error: Box::new(e),
        })
    }

    /// `time [s], x [m]` rows: a horizontal displacement, no rotation.
    pub fn parse_positions(text: &str) -> Result<Self, SeriesError> {
        let (t, rows) = parse_rows(text, &[2], "time [s], position [m]")?;
        let x = rows.iter().map(|r| r[1]).collect();
        Ok(Self {
            values: [vec![0.0; t.len()], x, vec![0.0; t.len()]],
            t,
        })
    }

    /// `time [s], angle [deg][, x [m], y [m]]` rows.
    pub fn parse(text: &str) -> Result<Self, SeriesError> {
        let (t, rows) = parse_rows(text, &[2, 4], "time [s], angle [deg][, x [m], y [m]]")?;
        let col = |k: usize| rows.iter().map(move |r| r.get(k).copied().unwrap_or(0.0));
        Ok(Self {
            values: [
                col(1).map(f64::to_radians).collect(),
                col(2).collect(),
                col(3).collect(),
            ],
            t,
        })
    }
}

/// A motion table refused: where, and what is accepted.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SeriesError {
    #[error("cannot read motion series {}: {message}", path.display())]
    Read {
        path: std::path::PathBuf,
        message: String,
    },
    #[error("{}: {error}", path.display())]
    In {
        path: std::path::PathBuf,
        error: Box<SeriesError>,
    },
    #[error("line {line}: `{text}` is not a row of numbers; accepted: {columns}")]
    NotNumbers {
        line: usize,
        text: String,
        columns: &'static str,
    },
    #[error("line {line}: {found} values; accepted: {columns} ({widths} finite numbers)")]
    Width {
        line: usize,
        found: usize,
        columns: &'static str,
        /// The accepted counts, "2 or 4".
        widths: String,
    },
    #[error("line {line}: time {time} does not increase")]
    NotIncreasing { line: usize, time: f64 },
    #[error("a motion series needs at least two rows")]
    TooShort,
}

/// Numeric rows of a motion table with one of the `widths` (time first, strictly
/// increasing); `#` comments and one header line allowed. Errors name the line and say
/// what is accepted (`columns`).
fn parse_rows(
    text: &str,
    widths: &[usize],
    columns: &'static str,
) -> Result<(Vec<f64>, Vec<Vec<f64>>), SeriesError> {
    let mut t = Vec::new();
    let mut rows = Vec::new();
    let mut header_seen = false;
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let cells: Vec<&str> = line
            .split([',', ';', '\t', ' '])
            .filter(|c| !c.is_empty())
            .collect();
        let numbers: Result<Vec<f64>, _> = cells.iter().map(|c| c.parse::<f64>()).collect();
        let Ok(numbers) = numbers else {
            if t.is_empty() && !header_seen {
                header_seen = true;
                continue;
            }
            return Err(SeriesError::NotNumbers {
                line: n + 1,
                text: line.to_string(),
                columns,
            });
        };
        if !widths.contains(&numbers.len()) || numbers.iter().any(|v| !v.is_finite()) {
            return Err(SeriesError::Width {
                line: n + 1,
                found: numbers.len(),
                columns,
                widths: widths
                    .iter()
                    .map(|w| w.to_string())
                    .collect::<Vec<_>>()
                    .join(" or "),
            });
        }
        if t.last().is_some_and(|&last| numbers[0] <= last) {
            return Err(SeriesError::NotIncreasing {
                line: n + 1,
                time: numbers[0],
            });
        }
        t.push(numbers[0]);
        rows.push(numbers);
    }
    if t.len() < 2 {
        return Err(SeriesError::TooShort);
    }
    Ok((t, rows))
}

impl MotionSeries {
    /// (value, d/dt, d2/dt2) of column `k` at time `s`: cubic Hermite interpolation with
    /// finite-difference (Catmull-Rom) slopes, so velocity is continuous.
    fn at(&self, k: usize, s: f64) -> [f64; 3] {
        let (t, y) = (&self.t, &self.values[k]);
        let n = t.len();
        if s < t[0] {
            return [y[0], 0.0, 0.0];
        }
        if s >= t[n - 1] {
            return [y[n - 1], 0.0, 0.0];
        }
        let i = t.partition_point(|&ti| ti <= s) - 1;
        let slope = |j: usize| {
            let (a, b) = (j.saturating_sub(1), (j + 1).min(n - 1));
            (y[b] - y[a]) / (t[b] - t[a])
        };
        let hstep = t[i + 1] - t[i];
        let u = (s - t[i]) / hstep;
        let (p0, p1, m0, m1) = (y[i], y[i + 1], slope(i) * hstep, slope(i + 1) * hstep);
        let (u2, u3) = (u * u, u * u * u);
        let value = (2.0 * u3 - 3.0 * u2 + 1.0) * p0
            + (u3 - 2.0 * u2 + u) * m0
            + (-2.0 * u3 + 3.0 * u2) * p1
            + (u3 - u2) * m1;
        let d1 = (6.0 * u2 - 6.0 * u) * p0
            + (3.0 * u2 - 4.0 * u + 1.0) * m0
            + (-6.0 * u2 + 6.0 * u) * p1
            + (3.0 * u2 - 2.0 * u) * m1;
        let d2 = (12.0 * u - 6.0) * p0
            + (6.0 * u - 4.0) * m0
            + (-12.0 * u + 6.0) * p1
            + (6.0 * u - 2.0) * m1;
        [value, d1 / hstep, d2 / (hstep * hstep)]
    }

    fn max_abs(&self, k: usize) -> f64 {
        self.values[k].iter().fold(0.0, |m, v| m.max(v.abs()))
    }
}

/// The tank's prescribed motion: a component of the tank entity.
#[derive(Clone, Debug, PartialEq)]
pub struct Motion {
    pub pivot: Vector,
    tilt: f64,
    roll: Option<Wave>,
    pitch: Option<Wave>,
    sway: Option<Wave>,
    heave: Option<Wave>,
    ramp: f64,
    series: Option<MotionSeries>,
}

impl Motion {
    /// From the scenario's spec; `series` is the already-read table when the spec names one.
    pub fn new(spec: &MotionSpec, pivot: Vector, series: Option<MotionSeries>) -> Self {
        let wave = |s: &Option<HarmonicSpec>, scale| s.as_ref().map(|s| Wave::from_spec(s, scale));
        let longest = [&spec.roll, &spec.pitch, &spec.sway, &spec.heave]
            .into_iter()
            .flatten()
            .map(|h| h.period.0)
            .fold(0.0, f64::max);
        Self {
            pivot,
            tilt: spec.tilt.to_radians(),
            roll: wave(&spec.roll, PI / 180.0),
            pitch: wave(&spec.pitch, PI / 180.0),
            sway: wave(&spec.sway, 1.0),
            heave: wave(&spec.heave, 1.0),
            ramp: spec.ramp.unwrap_or(longest).max(0.0),
            series,
        }
    }

    /// The ramp r(t) = (1 - cos(pi t / T_r)) / 2 and its two derivatives.
    fn ramp(&self, t: f64) -> [f64; 3] {
        if t >= self.ramp {
            return [1.0, 0.0, 0.0];
        }
        let k = PI / self.ramp;
        let (s, c) = (k * t.max(0.0)).sin_cos();
        [0.5 * (1.0 - c), 0.5 * k * s, 0.5 * k * k * c]
    }

    /// Ramped value r f with derivatives (product rule).
    fn ramped(r: [f64; 3], f: [f64; 3]) -> [f64; 3] {
        [
            r[0] * f[0],
            r[1] * f[0] + r[0] * f[1],
            r[2] * f[0] + 2.0 * r[1] * f[1] + r[0] * f[2],
        ]
    }

    pub fn state(&self, t: f64) -> RigidState {
        let zero = [0.0; 3];
        let r = self.ramp(t);
        let w = |w: &Option<Wave>| w.map_or(zero, |w| w.at(t));
        let (angle, x, y) = match &self.series {
            Some(s) => (s.at(0, t), s.at(1, t), s.at(2, t)),
            None => {
                let roll = w(&self.roll);
                let angle = [self.tilt + roll[0], roll[1], roll[2]];
                (
                    Self::ramped(r, angle),
                    Self::ramped(r, w(&self.sway)),
                    Self::ramped(r, w(&self.heave)),
                )
            }
        };
        // The loader refuses a pitch beside a series, and in 2D.
        #[cfg(feature = "dim3")]
        let pitch = Pitch::new(match self.pitch {
            Some(_) => Self::ramped(r, w(&self.pitch)),
            None => zero,
        });
        RigidState {
            angle: angle[0],
            omega: angle[1],
            alpha: angle[2],
            offset: dim::xy(x[0], y[0]),
            velocity: dim::xy(x[1], y[1]),
            acceleration: dim::xy(x[2], y[2]),
            #[cfg(feature = "dim3")]
            pitch,
        }
    }

    pub fn pose(&self, t: f64) -> Pose {
        Pose {
            pivot: self.pivot,
            state: self.state(t),
        }
    }

    /// Largest pivot displacement over the run [m] (a bound).
    pub fn max_offset(&self) -> f64 {
        match &self.series {
            Some(s) => s.max_abs(1).hypot(s.max_abs(2)),
            None => {
                let a = |w: &Option<Wave>| w.map_or(0.0, |w| w.amplitude.abs());
                a(&self.sway).hypot(a(&self.heave))
            }
        }
    }

    /// Largest |angle| over the run [rad] (a bound).
    pub fn max_angle(&self) -> f64 {
        match &self.series {
            Some(s) => s.max_abs(0),
            None => self.tilt.abs() + self.roll.map_or(0.0, |w| w.amplitude.abs()),
        }
    }

    /// Largest |pitch| over the run [rad] (a bound; 0 without pitch).
    pub fn max_pitch(&self) -> f64 {
        self.pitch.map_or(0.0, |w| w.amplitude.abs())
    }

    /// The period of the roll harmonic, if any [s].
    pub fn roll_period(&self) -> Option<f64> {
        self.roll.map(|w| 2.0 * PI / w.omega)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(text: &str) -> MotionSpec {
        ron::Options::default()
            .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
            .from_str(text)
            .unwrap()
    }

    /// Central differences of the value match the derivatives the motion reports.
    fn check_derivatives(m: &Motion, times: &[f64]) {
        let e = 1e-5;
        for &t in times {
            let (a, b, c) = (m.state(t - e), m.state(t), m.state(t + e));
            let d_angle = (c.angle - a.angle) / (2.0 * e);
            let d_omega = (c.omega - a.omega) / (2.0 * e);
            let d_off = (c.offset - a.offset) / (2.0 * e);
            let d_vel = (c.velocity - a.velocity) / (2.0 * e);
            assert!((d_angle - b.omega).abs() < 1e-6, "omega at {t}");
            assert!((d_omega - b.alpha).abs() < 1e-4, "alpha at {t}");
            assert!((d_off - b.velocity).length() < 1e-6, "velocity at {t}");
            assert!(
                (d_vel - b.acceleration).length() < 1e-4,
                "acceleration at {t}"
            );
        }
    }

    #[test]
    fn harmonic_roll_with_ramp_is_smooth_and_consistent() {
        let m = Motion::new(
            &spec("(roll: (amplitude: 4.0, period: 1.5), sway: (amplitude: 0.01, period: 0.7, phase: 30.0), tilt: 2.0)"),
            dim::xy(0.45, 0.0),
            None,
        );
        // Starts at rest (the cosine ramp starts with a finite acceleration), reaches
        // the full harmonic after one (the longest) period.
        let s0 = m.state(0.0);
        assert_eq!((s0.angle, s0.omega), (0.0, 0.0));
        assert_eq!((s0.offset, s0.velocity), (Vector::ZERO, Vector::ZERO));
        let late = m.state(10.0);
        let expected = (2.0f64 + 4.0 * (2.0 * PI * 10.0 / 1.5).sin()).to_radians();
        assert!((late.angle - expected).abs() < 1e-12);
        check_derivatives(&m, &[0.3, 0.74, 1.2, 3.3]);
    }

    #[test]
    fn pose_round_trips_and_gives_rigid_velocity() {
        let m = Motion::new(
            &spec("(roll: (amplitude: 10.0, period: 2.0), ramp: 0.0)"),
            dim::xy(0.5, 0.0),
            None,
        );
        let pose = m.pose(0.3);
        // Off the x-y plane in 3D: a turn about z keeps z.
        let q = dim::xy(0.1, 0.4) + 0.3 * (Vector::ONE - dim::in_xy(Vector::ONE));
        let x = pose.to_world(q);
        assert!((pose.to_body(x) - q).length() < 1e-12);
        // Distance to the pivot is kept; velocity is the derivative of the world position.
        assert!(((x - pose.centre()).length() - (q - m.pivot).length()).abs() < 1e-12);
        let e = 1e-6;
        let dx = (m.pose(0.3 + e).to_world(q) - m.pose(0.3 - e).to_world(q)) / (2.0 * e);
        assert!((dx - pose.velocity_at(x)).length() < 1e-8);
        let d2x =
            (m.pose(0.3 + 1e-4).to_world(q) - 2.0 * x + m.pose(0.3 - 1e-4).to_world(q)) / 1e-8;
        assert!((d2x - pose.acceleration_at(x)).length() < 1e-4);
    }

    /// Roll, pitch and sway together: the pose round-trips, keeps distances, and its
    /// velocity and acceleration at a point are the derivatives of where the point is.
    #[cfg(feature = "dim3")]
    #[test]
    fn a_pitching_and_rolling_pose_moves_points_rigidly() {
        let m = Motion::new(
            &spec("(roll: (amplitude: 8.0, period: 1.3), pitch: (amplitude: 12.0, period: 0.9, phase: 40.0), sway: (amplitude: 0.02, period: 0.7), ramp: 0.5)"),
            Vector::new(0.5, 0.0, 0.3),
            None,
        );
        for t in [0.2, 0.61, 1.37] {
            let pose = m.pose(t);
            assert!(pose.state.pitch.values()[0] != 0.0 && pose.state.angle != 0.0);
            for q in [Vector::new(0.1, 0.4, 0.05), Vector::new(0.9, 0.2, 0.55)] {
                let x = pose.to_world(q);
                assert!((pose.to_body(x) - q).length() < 1e-12, "round trip at {t}");
                let d = (x - pose.centre()).length() - (q - m.pivot).length();
                assert!(d.abs() < 1e-12, "distance to the pivot at {t}");
                let at = |dt: f64| m.pose(t + dt).to_world(q);
                // Central differences: O(e^2) truncation, round-off ~1e-16/e (1e-10
                // for the velocity) and ~1e-16/e^2 (1e-8 for the acceleration).
                let e = 1e-6;
                let v = (at(e) - at(-e)) / (2.0 * e);
                let want = pose.velocity_at(x);
                assert!((v - want).length() < 1e-7, "velocity at {t}: {v} vs {want}");
                let e = 1e-4;
                let a = (at(e) - 2.0 * x + at(-e)) / (e * e);
                let want = pose.acceleration_at(x);
                assert!(
                    (a - want).length() < 1e-4,
                    "acceleration at {t}: {a} vs {want}"
                );
            }
        }
        // The pitch's own derivatives, as the roll's.
        let e = 1e-5;
        for t in [0.3, 0.74] {
            let (a, b, c) = (m.state(t - e), m.state(t), m.state(t + e));
            assert!(
                ((c.pitch.values()[0] - a.pitch.values()[0]) / (2.0 * e) - b.pitch.values()[1])
                    .abs()
                    < 1e-6
            );
            assert!(
                ((c.pitch.values()[1] - a.pitch.values()[1]) / (2.0 * e) - b.pitch.values()[2])
                    .abs()
                    < 1e-4
            );
        }
        // Without pitch the pose is the roll's (the pitch terms vanish exactly).
        let roll = Motion::new(
            &spec("(roll: (amplitude: 8.0, period: 1.3), ramp: 0.0)"),
            m.pivot,
            None,
        );
        assert_eq!(roll.state(0.4).pitch.values(), [0.0; 3]);
        assert_eq!(m.max_pitch(), 12f64.to_radians());
        assert_eq!(roll.max_pitch(), 0.0);
    }

    #[test]
    fn series_interpolates_and_differentiates() {
        // A sampled sine: the spline reproduces it and its derivatives closely.
        let mut text = String::from("time,angle,x,y\n");
        for i in 0..=400 {
            let t = i as f64 * 0.01;
            text += &format!("{t},{},{},0\n", 5.0 * (2.0 * t).sin(), 0.02 * t * t);
        }
        let s = MotionSeries::parse(&text).unwrap();
        let m = Motion::new(&MotionSpec::default(), Vector::ZERO, Some(s));
        let st = m.state(1.234);
        assert!((st.angle - (5.0 * (2.0f64 * 1.234).sin()).to_radians()).abs() < 1e-6);
        assert!((st.omega - (10.0 * (2.0f64 * 1.234).cos()).to_radians()).abs() < 1e-4);
        assert!((st.velocity.x - 0.04 * 1.234).abs() < 1e-6);
        assert!((st.acceleration.x - 0.04).abs() < 1e-3);
        check_derivatives(&m, &[0.505, 2.0051]);
        assert_eq!(m.state(100.0).omega, 0.0);
    }

    #[test]
    fn bad_series_rows_are_reported_by_line() {
        let e = MotionSeries::parse("t,a\n0,1\n1,x\n").unwrap_err();
        assert!(matches!(e, SeriesError::NotNumbers { line: 3, .. }), "{e}");
        let e = MotionSeries::parse("0,1\n0,2\n").unwrap_err();
        assert_eq!(e, SeriesError::NotIncreasing { line: 2, time: 0.0 });
        assert!(e.to_string().contains("does not increase"), "{e}");
        let e = MotionSeries::parse("0,1,2\n").unwrap_err();
        assert!(
            matches!(&e, SeriesError::Width { line: 1, found: 3, widths, .. } if widths == "2 or 4"),
            "{e}"
        );
        assert!(
            e.to_string().contains("line 1") && e.to_string().contains("2 or 4"),
            "{e}"
        );
        assert_eq!(MotionSeries::parse("0,1\n"), Err(SeriesError::TooShort));
        // A piston series takes exactly (time, position).
        let e = MotionSeries::parse_positions("0,0\n1,0.1,3\n").unwrap_err();
        assert!(
            matches!(
                e,
                SeriesError::Width {
                    line: 2,
                    found: 3,
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("position"), "{e}");
    }
}
