//! The wall-pressure extraction methods II and III (Method I, the Shepard
//! interpolation, is `Probe::shepard`), and the roll moment: functions of the fluid's
//! positions and pressures.

use super::*;

/// Hydrostatic carry of a pressure in the (possibly accelerating) tank frame:
/// p(to) = p(from) + rho_0 g_eff . (to - from).
#[derive(Clone, Copy)]
pub(crate) struct Carry {
    pub(crate) rho0: f64,
    pub(crate) g: DVec2,
}

impl Carry {
    pub(crate) fn carry(self, p: f64, from: DVec2, to: DVec2) -> f64 {
        p + self.rho0 * self.g.dot(to - from)
    }
}

/// M = sum_i m_i (x_i - centre) x (g - a_i), counter-clockwise positive (module docs).
pub fn roll_moment(x: &[Position], a: &[Acceleration], m: &[Mass], centre: DVec2, g: DVec2) -> f64 {
    x.iter()
        .zip(a)
        .zip(m)
        .map(|((x, a), m)| m.0 * (x.0 - centre).perp_dot(g - a.0))
        .sum()
}

/// The neighbour grid when it indexes exactly these fluid particles (it is built
/// after the positions of the step a probe reads), for point queries instead of a scan
/// of every particle (two sensors, read every step for their time filters, scanned
/// 21 ns per particle-step at 80k).
pub(crate) fn grid_of(sim: &Sim, n_fluid: usize) -> Option<&Neighbours> {
    sim.resources
        .get::<Neighbours>()
        .filter(|nb| nb.n_fluid == n_fluid && !nb.grid.start.is_empty())
}

/// Method II: the nearest fluid particle within the kernel support (the lowest index
/// among equally near ones).
pub(crate) fn nearest(sim: &Sim, x: &[Position], p: &[Pressure], at: DVec2, carry: Carry) -> f64 {
    let support2 = sim.constants.support().powi(2);
    let mut best: Option<(f64, usize)> = None;
    let mut consider = |i: usize| {
        let d2 = (x[i].0 - at).length_squared();
        if d2 < support2 && best.is_none_or(|b| (d2, i) < b) {
            best = Some((d2, i));
        }
    };
    match grid_of(sim, x.len()) {
        // Every particle within the support of `at` is in the cells around it.
        Some(nb) => nb.grid.for_each_near(at, |j| {
            if (j as usize) < x.len() {
                consider(j as usize)
            }
        }),
        None => (0..x.len()).for_each(consider),
    }
    best.map_or(0.0, |(_, i)| carry.carry(p[i].0, x[i].0, at))
}

/// Method III's candidates and samples.
#[derive(Default)]
pub(crate) struct Scratch {
    pub(crate) candidates: Vec<u32>,
    pub(crate) samples: Vec<(f64, f64)>,
}

/// Method III: Oger's pseudo-sensor.
pub(crate) fn averaged(
    sim: &Sim,
    x: &[Position],
    p: &[Pressure],
    wall: &WallPose,
    s: &PressureSensor,
    carry: Carry,
    scratch: &mut Scratch,
) -> f64 {
    let reach = 1.5 * sim.constants.h;
    let centre = s.along;
    // A face cannot reach past the wall's ends: near a corner it is narrowed about its
    // centre to fit (else the fluid-less part past the corner moves the face's mean
    // pressure off the sensor's height: -1.1 % at 0.5 ds above a still floor).
    let fit = (0.5 * s.width).min(centre).min(wall.length() - centre);
    let half = if fit > 0.0 { fit } else { 0.5 * s.width };
    let (lo, hi) = (centre - half, centre + half);
    let sample = |i: usize| {
        let q = x[i].0;
        let (d, a) = (wall.distance(q), wall.abscissa(q));
        ((0.0..reach).contains(&d) && (lo..=hi).contains(&a)).then(|| {
            let on_wall = q - d * wall.normal();
            (a, carry.carry(p[i].0, q, on_wall))
        })
    };
    let Scratch {
        samples,
        candidates,
    } = scratch;
    samples.clear();
    match grid_of(sim, x.len()) {
        // The cells around points every h/2 along the face hold every particle within
        // 1.5 h of it (a cell is at least a support wide); taken in index order, as the
        // scan of all particles takes them, so the stable sort below gives the same list.
        Some(nb) => {
            candidates.clear();
            let points = ((hi - lo) / (0.5 * sim.constants.h)).ceil().clamp(1.0, 1e4) as usize;
            for k in 0..=points {
                let at = wall.point(lo + (hi - lo) * k as f64 / points as f64);
                nb.grid.for_each_near(at, |j| {
                    if (j as usize) < x.len() {
                        candidates.push(j)
                    }
                });
            }
            candidates.sort_unstable();
            candidates.dedup();
            samples.extend(candidates.iter().filter_map(|&i| sample(i as usize)));
        }
        None => samples.extend((0..x.len()).filter_map(sample)),
    }
    let samples = &mut samples[..];
    if samples.is_empty() {
        return 0.0;
    }
    samples.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let q = |k: isize| -> f64 {
        if k < 0 {
            lo
        } else if k as usize >= samples.len() {
            hi
        } else {
            samples[k as usize].0
        }
    };
    let (mut num, mut den) = (0.0, 0.0);
    for (k, &(_, pk)) in samples.iter().enumerate() {
        let k = k as isize;
        let ds = 0.5 * (q(k + 1) - q(k - 1));
        num += pk * ds;
        den += ds;
    }
    if den > 0.0 {
        num / den
    } else {
        samples.iter().map(|s| s.1).sum::<f64>() / samples.len() as f64
    }
}
