//! Linear sloshing in a rectangular tank (docs/analytic.md section 4; Faltinsen & Timokha
//! 2009, ch. 4-5): natural frequencies, and the steady roll moment of the liquid on a
//! tank rolling harmonically, theta = theta_a sin(sigma t), about an axis on the tank's
//! centre line. Used for the sweep's reference curve and the tests; the exact moment of
//! a statically tilted tank checks it.

use std::f64::consts::PI;

/// Modes and series terms summed (odd n, odd j up to this); the terms fall as n^-4.
const TERMS: usize = 399;

#[derive(Clone, Copy, Debug)]
pub struct RectangularTank {
    /// Breadth L [m].
    pub breadth: f64,
    /// Still depth h [m].
    pub depth: f64,
    /// Density rho [kg/m^3].
    pub density: f64,
    /// Gravity g [m/s^2].
    pub gravity: f64,
    /// Kinematic viscosity nu [m^2/s] damping each mode's amplitude at the rate
    /// 2 nu k_n^2 (Lamb 1932, section 348; docs/analytic.md section 4); 0 for the undamped
    /// theory. For SPH with artificial viscosity, nu = alpha h c_0 / 8 (Monaghan 2005).
    pub viscosity: f64,
}

impl RectangularTank {
    /// sigma_n = sqrt(g k_n tanh(k_n h)), k_n = n pi / L.
    pub fn natural_frequency(&self, n: usize) -> f64 {
        let k = n as f64 * PI / self.breadth;
        (self.gravity * k * (k * self.depth).tanh()).sqrt()
    }

    /// Amplitude decay rate of mode k: gamma = 2 nu k^2.
    fn damping(&self, k: f64) -> f64 {
        2.0 * self.viscosity * k * k
    }

    /// Undamped steady-state roll moment about the roll axis R, per unit tank width, as
    /// the signed coefficient c of M_R(t) = c theta_a sin(sigma t) (per radian of roll
    /// amplitude): c > 0 in phase with the roll, c < 0 in antiphase. `axis_height` is
    /// R's height above the tank bottom. Diverges at each odd sigma_n. (With
    /// `viscosity` > 0 this is the in-phase part; see [`Self::roll_moment_response`].)
    pub fn roll_moment_per_radian(&self, sigma: f64, axis_height: f64) -> f64 {
        self.roll_moment_response(sigma, axis_height).0
    }

    /// Steady-state roll moment about R per radian of roll as a complex amplitude
    /// (in phase, quadrature): M_R(t) = re sin(sigma t) + im cos(sigma t). Each mode
    /// has beta_n = Im[B_n e^(i sigma t)] with B_n = C_n (sigma_n^2 - sigma^2) /
    /// (sigma_n^2 - sigma^2 + 2 i gamma_n sigma), C_n the undamped amplitude below.
    ///
    /// With O the centre of the still free surface and y_R = axis_height - h:
    ///   beta_n = C_n sin(sigma t),
    ///   C_n = (4 tanh(k_n h)/(k_n L)) [g - sigma^2 (y_R + (2/k_n) tanh(k_n h/2))] / (sigma_n^2 - sigma^2)
    ///   M_O = -rho g theta L h^2/2 - rho x''_O L h^2/2 - rho J0 theta'' - rho sum (J_n beta_n'' + g I_n beta_n)
    ///   F_x = -rho L h (x''_O + theta'' h/2) - rho sum I_n beta_n''
    ///   M_R = M_O + y_R F_x - y_R theta rho g L h,   x_O = y_R theta,
    /// with I_n = -2/k_n^2, J_n = -4 tanh(k_n h/2)/k_n^3 and J0 as in [`Self::j0`].
    pub fn roll_moment_response(&self, sigma: f64, axis_height: f64) -> (f64, f64) {
        let (l, h, g) = (self.breadth, self.depth, self.gravity);
        let y_r = axis_height - h;
        let s2 = sigma * sigma;
        // Per unit theta_a, coefficients of sin(sigma t):
        // Modal sums sum (J_n beta_n'' + g I_n beta_n) and sum I_n beta_n'', in phase
        // and in quadrature.
        let (mut modal_m, mut modal_f, mut modal_m_q, mut modal_f_q) = (0.0, 0.0, 0.0, 0.0);
        for n in (1..=TERMS).step_by(2) {
            let k = n as f64 * PI / l;
            let sn2 = self.natural_frequency(n).powi(2);
            let drive =
                4.0 * (k * h).tanh() / (k * l) * (g - s2 * (y_r + 2.0 / k * (k * h / 2.0).tanh()));
            // B = drive / (sn2 - s2 + 2 i gamma sigma), split into real and imaginary.
            let (re, im) = (sn2 - s2, 2.0 * self.damping(k) * sigma);
            let norm = re * re + im * im;
            let (b_re, b_im) = (drive * re / norm, -drive * im / norm);
            let (i_n, j_n) = (-2.0 / (k * k), -4.0 * (k * h / 2.0).tanh() / k.powi(3));
            // beta'' = -sigma^2 beta for each part.
            modal_m += (j_n * -s2 + g * i_n) * b_re;
            modal_m_q += (j_n * -s2 + g * i_n) * b_im;
            modal_f += i_n * -s2 * b_re;
            modal_f_q += i_n * -s2 * b_im;
        }
        // Per unit theta_a: theta = 1, theta'' = -sigma^2 in phase; the rigid terms
        // have no quadrature part.
        let j0 = self.j0();
        (
            self.axis_moment(j0, y_r, 1.0, -s2, y_r * -s2, modal_m, modal_f),
            self.axis_moment(j0, y_r, 0.0, 0.0, 0.0, modal_m_q, modal_f_q),
        )
    }

    /// M_R = M_O + y_R F_x - y_R theta rho g L h from the roll (theta, theta''), the
    /// axis O's acceleration x''_O and the modal sums sum (J_n beta_n'' + g I_n beta_n)
    /// and sum I_n beta_n'' (see [`Self::roll_moment_response`]).
    #[allow(clippy::too_many_arguments)]
    fn axis_moment(
        &self,
        j0: f64,
        y_r: f64,
        theta: f64,
        theta_dd: f64,
        x_dd: f64,
        modal_m: f64,
        modal_f: f64,
    ) -> f64 {
        let (l, h, rho, g) = (self.breadth, self.depth, self.density, self.gravity);
        let m_o = -rho * g * theta * l * h * h / 2.0
            - rho * x_dd * l * h * h / 2.0
            - rho * j0 * theta_dd
            - rho * modal_m;
        let f_x = -rho * l * h * (x_dd + theta_dd * h / 2.0) - rho * modal_f;
        m_o + y_r * f_x - y_r * theta * rho * g * l * h
    }

    /// The linear roll moment about the axis over time for a prescribed motion that
    /// starts from rest, with the fluid at rest: each odd mode's equation
    ///   beta_n'' + sigma_n^2 beta_n = (4 tanh(k_n h)/(k_n L)) [x_O'' + g theta + (2/k_n) tanh(k_n h/2) theta'']
    /// is integrated from beta_n = beta_n' = 0 (the Duhamel response, by RK4 steps of at
    /// most a fiftieth of the shortest period), and the moment assembled as in
    /// [`Self::roll_moment_response`], with damping 2 gamma_n beta_n' for a positive
    /// `viscosity`. `motion(t)` gives (theta, theta'', sway''), with x_O = y_R theta +
    /// sway; `times` must increase. Heave is second order and left out.
    pub fn roll_moment_history(
        &self,
        axis_height: f64,
        motion: impl Fn(f64) -> (f64, f64, f64),
        times: &[f64],
    ) -> Vec<f64> {
        const MODES: usize = 61;
        let (l, h, g) = (self.breadth, self.depth, self.gravity);
        let y_r = axis_height - h;
        // Per mode: sigma_n^2, gain, lever, I_n, J_n, 2 gamma_n.
        let modes: Vec<(f64, f64, f64, f64, f64, f64)> = (1..=MODES)
            .step_by(2)
            .map(|n| {
                let k = n as f64 * PI / l;
                let gain = 4.0 * (k * h).tanh() / (k * l);
                let lever = 2.0 / k * (k * h / 2.0).tanh();
                let (i_n, j_n) = (-2.0 / (k * k), -4.0 * (k * h / 2.0).tanh() / k.powi(3));
                let sn2 = self.natural_frequency(n).powi(2);
                (sn2, gain, lever, i_n, j_n, 2.0 * self.damping(k))
            })
            .collect();
        let max_step = 2.0 * PI / modes.last().map_or(1.0, |m| m.0.sqrt()) / 50.0;
        let forcing = |t: f64, m: &(f64, f64, f64, f64, f64, f64)| {
            let (theta, theta_dd, sway_dd) = motion(t);
            m.1 * (y_r * theta_dd + sway_dd + g * theta + m.2 * theta_dd)
        };
        let j0 = self.j0();
        let mut state = vec![(0.0f64, 0.0f64); modes.len()];
        let mut t = times.first().copied().unwrap_or(0.0).min(0.0);
        let mut out = Vec::with_capacity(times.len());
        for &target in times {
            let steps = ((target - t) / max_step).ceil().max(0.0) as usize;
            let dt = if steps > 0 {
                (target - t) / steps as f64
            } else {
                0.0
            };
            for _ in 0..steps {
                for (m, (b, v)) in modes.iter().zip(state.iter_mut()) {
                    // RK4 on (beta, beta').
                    let acc = |tt: f64, bb: f64, vv: f64| forcing(tt, m) - m.0 * bb - m.5 * vv;
                    let (k1b, k1v) = (*v, acc(t, *b, *v));
                    let (b2, v2) = (*b + 0.5 * dt * k1b, *v + 0.5 * dt * k1v);
                    let (k2b, k2v) = (v2, acc(t + 0.5 * dt, b2, v2));
                    let (b3, v3) = (*b + 0.5 * dt * k2b, *v + 0.5 * dt * k2v);
                    let (k3b, k3v) = (v3, acc(t + 0.5 * dt, b3, v3));
                    let (b4, v4) = (*b + dt * k3b, *v + dt * k3v);
                    let (k4b, k4v) = (v4, acc(t + dt, b4, v4));
                    *b += dt / 6.0 * (k1b + 2.0 * k2b + 2.0 * k3b + k4b);
                    *v += dt / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
                }
                t += dt;
            }
            let (theta, theta_dd, sway_dd) = motion(target);
            let x_dd = y_r * theta_dd + sway_dd;
            let (mut modal_m, mut modal_f) = (0.0, 0.0);
            for (m, (b, v)) in modes.iter().zip(&state) {
                let b_dd = forcing(target, m) - m.0 * b - m.5 * v;
                modal_m += m.4 * b_dd + g * m.3 * b;
                modal_f += m.3 * b_dd;
            }
            out.push(self.axis_moment(j0, y_r, theta, theta_dd, x_dd, modal_m, modal_f));
        }
        out
    }

    /// J0 = h L^3/12 + (64/h) sum_{j odd} tanh(j pi L / (2h)) / (j pi / h)^5, the
    /// squared gradient integral of the Stokes-Joukowski potential of the rectangle.
    pub fn j0(&self) -> f64 {
        let (l, h) = (self.breadth, self.depth);
        let series: f64 = (1..=TERMS)
            .step_by(2)
            .map(|j| {
                let mu = j as f64 * PI / h;
                (mu * l / 2.0).tanh() / mu.powi(5)
            })
            .sum();
        h * l.powi(3) / 12.0 + 64.0 / h * series
    }
}

/// Exact moment, per unit width, of the weight of liquid at rest in a rectangular tank
/// of breadth `l` and still depth `h` tilted by `theta` (counter-clockwise, radians)
/// about the point `axis_height` above the centre of its bottom: the free surface is
/// horizontal, the liquid's area L h is kept, M = -rho g A (x_c - x_R) (x_c the
/// world abscissa of the liquid's centroid). Valid while the surface meets both side
/// walls and stays below the roof.
pub fn tilted_tank_moment(l: f64, h: f64, theta: f64, axis_height: f64, rho: f64, g: f64) -> f64 {
    // Tank frame, origin at the axis: the liquid is the trapezoid under the line
    // y = c - tan(theta) x (horizontal in the world), -L/2 <= x <= L/2, above the
    // bottom y = -axis_height. Keeping the area fixes c = h - axis_height.
    let t = theta.tan();
    let bottom = -axis_height;
    let c = h + bottom;
    let depth = |x: f64| c - t * x - bottom;
    // Centroid of the trapezoid by exact integrals of a linear depth d(x) = d0 - t x.
    let a = l * h;
    let mx = (-t) * l.powi(3) / 12.0; // integral of x d(x) dx
    let my = {
        // integral over x of (y_top^2 - y_bottom^2)/2
        let f = |x: f64| {
            let top = bottom + depth(x);
            // antiderivative of (top(x)^2 - bottom^2)/2 with top linear in x
            -(top.powi(3)) / (6.0 * t) - bottom * bottom * x / 2.0
        };
        if t == 0.0 {
            (c * c - bottom * bottom) / 2.0 * l
        } else {
            f(l / 2.0) - f(-l / 2.0)
        }
    };
    let (xc, yc) = (mx / a, my / a);
    // World abscissa of the centroid relative to the axis.
    let xw = xc * theta.cos() - yc * theta.sin();
    -rho * g * a * xw
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spheric_low() -> RectangularTank {
        RectangularTank {
            breadth: 0.9,
            depth: 0.093,
            density: 1000.0,
            gravity: 9.81,
            viscosity: 0.0,
        }
    }

    #[test]
    fn natural_period_matches_the_test10_document() {
        // docs/analytic.md: T1 = 1.917 s for L = 0.9 m, h = 0.093 m; 1.167 s for h = 0.3556 m.
        let t1 = 2.0 * PI / spheric_low().natural_frequency(1);
        assert!((t1 - 1.917).abs() < 1e-3, "{t1}");
        let high = RectangularTank {
            depth: 0.3556,
            ..spheric_low()
        };
        assert!((2.0 * PI / high.natural_frequency(1) - 1.167).abs() < 1e-3);
    }

    #[test]
    fn quasi_static_limit_is_the_tilted_tank_moment() {
        // sigma -> 0: M_R = rho g theta (L^3/12 + L h^2/2) about the bottom centre
        // (docs/analytic.md's check), and the exact tilted moment agrees for small theta.
        let t = spheric_low();
        let (l, h) = (t.breadth, t.depth);
        let linear = t.roll_moment_per_radian(1e-4, 0.0);
        let expected = t.density * t.gravity * (l.powi(3) / 12.0 + l * h * h / 2.0);
        assert!(
            (linear / expected - 1.0).abs() < 1e-6,
            "{linear} vs {expected}"
        );
        let theta = 1e-4;
        let exact = tilted_tank_moment(l, h, theta, 0.0, t.density, t.gravity) / theta;
        assert!(
            (exact / expected - 1.0).abs() < 1e-3,
            "{exact} vs {expected}"
        );
    }

    #[test]
    fn tilted_moment_matches_a_polygon_centroid() {
        // Independent check at a finite angle: centroid of the liquid polygon in the
        // world frame, by the shoelace formula.
        let (l, h, theta, axis) = (0.5, 0.2, 8f64.to_radians(), 0.0);
        let t = theta.tan();
        let poly = [
            (-l / 2.0, 0.0),
            (l / 2.0, 0.0),
            (l / 2.0, h - t * l / 2.0),
            (-l / 2.0, h + t * l / 2.0),
        ];
        let world: Vec<(f64, f64)> = poly
            .iter()
            .map(|&(x, y)| {
                (
                    x * theta.cos() - y * theta.sin(),
                    x * theta.sin() + y * theta.cos(),
                )
            })
            .collect();
        let (mut a, mut cx) = (0.0, 0.0);
        for i in 0..4 {
            let (p, q) = (world[i], world[(i + 1) % 4]);
            let cross = p.0 * q.1 - q.0 * p.1;
            a += cross / 2.0;
            cx += (p.0 + q.0) * cross / 6.0;
        }
        let polygon = -1000.0 * 9.81 * cx;
        let exact = tilted_tank_moment(l, h, theta, axis, 1000.0, 9.81);
        assert!((a - l * h).abs() < 1e-12);
        assert!(
            (exact - polygon).abs() < 1e-9 * polygon.abs(),
            "{exact} vs {polygon}"
        );
    }

    #[test]
    fn slow_roll_history_follows_the_quasi_static_moment() {
        // A roll ten times slower than the first mode, brought in over many periods:
        // the response from rest tracks c(sigma) theta(t) (the free modes are barely
        // excited by the smooth start).
        let t = spheric_low();
        let sigma = 0.1 * t.natural_frequency(1);
        let ramp = 3.0 * 2.0 * PI / sigma;
        let motion = |s: f64| {
            let r = if s < ramp {
                0.5 * (1.0 - (PI * s / ramp).cos())
            } else {
                1.0
            };
            // theta'' of the ramped roll is dominated by -sigma^2 theta once ramped.
            let theta = 0.01 * r * (sigma * s).sin();
            (theta, -sigma * sigma * theta, 0.0)
        };
        let times: Vec<f64> = (0..400).map(|i| ramp + i as f64 * 0.05).collect();
        let history = t.roll_moment_history(0.0, motion, &times);
        let c = t.roll_moment_per_radian(sigma, 0.0);
        let scale = c * 0.01;
        for (s, m) in times.iter().zip(&history) {
            let expected = c * motion(*s).0;
            assert!(
                (m - expected).abs() < 0.01 * scale,
                "t = {s}: {m} vs {expected}"
            );
        }
    }

    #[test]
    fn moment_changes_sign_across_resonance() {
        let t = spheric_low();
        let s1 = t.natural_frequency(1);
        let below = t.roll_moment_per_radian(0.9 * s1, 0.0);
        let above = t.roll_moment_per_radian(1.1 * s1, 0.0);
        assert!(below > 0.0 && above < 0.0, "{below} {above}");
        assert!(t.roll_moment_per_radian(0.99 * s1, 0.0) > 5.0 * below);
    }
}
