//! What makes a pressure sensor read like a transducer (docs/validation.md, "Pressure
//! sensors"): a face of finite diameter, over which the pressure is averaged, and a
//! time filter, the mean of the readings of every step over a window ending at the
//! sample time (a box filter: what a transducer and its amplifier of about that
//! response time record, or a record sampled at 1/window).

use std::collections::VecDeque;

/// Points across a face of `diameter`, as offsets along the wall from its centre:
/// one point per quarter particle spacing `ds` (at least 3, at most 17), ends
/// included; the centre alone for a point sensor.
pub fn face_offsets(diameter: f64, ds: f64) -> Vec<f64> {
    if !(diameter > 0.0 && ds > 0.0) {
        return vec![0.0];
    }
    let n = ((diameter / (0.25 * ds)).ceil() as usize + 1).clamp(3, 17);
    (0..n)
        .map(|k| diameter * (k as f64 / (n - 1) as f64 - 0.5))
        .collect()
}

/// Points across a face of `diameter` as (along, across) offsets on the wall from its
/// centre: in 2D [`face_offsets`] along the wall (across 0); in 3D the face is a disc,
/// and its points are those of the square grid of the same offsets in both directions
/// that lie in the disc (a grid point every quarter spacing, at most 9 a side, the
/// ends of each axis included), so their mean is the disc's area mean. The centre
/// alone for a point sensor.
pub fn face_points(diameter: f64, ds: f64) -> Vec<(f64, f64)> {
    #[cfg(not(feature = "dim3"))]
    return face_offsets(diameter, ds)
        .into_iter()
        .map(|o| (o, 0.0))
        .collect();
    #[cfg(feature = "dim3")]
    {
        if !(diameter > 0.0 && ds > 0.0) {
            return vec![(0.0, 0.0)];
        }
        // At most 9 a side: 69 points in the disc, each reading a neighbour sum.
        let n = ((diameter / (0.25 * ds)).ceil() as usize + 1).clamp(3, 9);
        let axis: Vec<f64> = (0..n)
            .map(|k| diameter * (k as f64 / (n - 1) as f64 - 0.5))
            .collect();
        let r2 = 0.25 * diameter * diameter * (1.0 + 1e-12);
        axis.iter()
            .flat_map(|&u| axis.iter().map(move |&v| (u, v)))
            .filter(|(u, v)| u * u + v * v <= r2)
            .collect()
    }
}

/// A box filter over the last `window` seconds of readings, each weighted by the
/// time since the reading before it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BoxFilter {
    window: f64,
    /// (time, weight, reading), oldest first.
    readings: VecDeque<(f64, f64, f64)>,
}

impl BoxFilter {
    pub fn new(window: f64) -> Self {
        Self {
            window,
            readings: VecDeque::new(),
        }
    }

    /// Adds the reading at time `t` (times increase), and drops those older than the
    /// window.
    pub fn push(&mut self, t: f64, reading: f64) {
        let weight = self.readings.back().map_or(0.0, |&(last, _, _)| t - last);
        self.readings.push_back((t, weight.max(0.0), reading));
        while self
            .readings
            .front()
            .is_some_and(|&(t0, _, _)| t0 < t - self.window)
        {
            self.readings.pop_front();
        }
    }

    /// The weighted mean of the readings in the window (the plain mean while the
    /// weights are all zero, at the first reading); 0 without readings.
    pub fn mean(&self) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for &(_, w, r) in &self.readings {
            num += w * r;
            den += w;
        }
        if den > 0.0 {
            num / den
        } else if self.readings.is_empty() {
            0.0
        } else {
            self.readings.iter().map(|r| r.2).sum::<f64>() / self.readings.len() as f64
        }
    }

    /// The readings, for a checkpoint.
    pub fn readings(&self) -> impl Iterator<Item = (f64, f64, f64)> + '_ {
        self.readings.iter().copied()
    }

    /// Restores readings saved from [`BoxFilter::readings`].
    pub fn restore(&mut self, readings: impl IntoIterator<Item = (f64, f64, f64)>) {
        self.readings = readings.into_iter().collect();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sine of period T averaged over a window T reads 0; over a window much
    /// shorter than T it follows the sine, delayed by half the window.
    #[test]
    fn the_box_filter_averages_over_its_window() {
        let period = 0.1;
        let dt = 1e-4;
        let mut long = BoxFilter::new(period);
        let mut short = BoxFilter::new(period / 50.0);
        for k in 0..5000 {
            let t = k as f64 * dt;
            let s = (std::f64::consts::TAU * t / period).sin();
            long.push(t, s);
            short.push(t, s);
            if t > 2.0 * period {
                // One reading more or less in the window: dt/T of the amplitude.
                assert!(
                    long.mean().abs() < 2.0 * dt / period,
                    "t {t}: {}",
                    long.mean()
                );
                let delayed = (std::f64::consts::TAU * (t - period / 100.0) / period).sin();
                assert!((short.mean() - delayed).abs() < 0.01, "t {t}");
            }
        }
    }

    #[test]
    fn faces_have_their_points_across_the_diameter() {
        assert_eq!(face_offsets(0.0, 0.01), vec![0.0]);
        let f = face_offsets(0.01, 0.01);
        assert_eq!(f.len(), 5);
        assert!((f[0] + 0.005).abs() < 1e-15 && (f[4] - 0.005).abs() < 1e-15);
        assert_eq!(face_offsets(1.0, 0.01).len(), 17);
        assert_eq!(face_offsets(f64::NAN, 0.01), vec![0.0]);
        // No spacing (or a negative one): the centre alone.
        assert_eq!(face_offsets(0.01, 0.0), vec![0.0]);
        assert_eq!(face_offsets(0.01, -0.01), vec![0.0]);
        // A quarter spacing apart: diameter 0.75 over ds/4 = 0.125 is 6 intervals, 7
        // points, equally spaced by diameter/6 and symmetric about 0 (binary
        // fractions: exact but for the round-off of k/6, below 1e-15 here).
        let f = face_offsets(0.75, 0.5);
        assert_eq!(f.len(), 7);
        for (k, x) in f.iter().enumerate() {
            let want = -0.375 + 0.125 * k as f64;
            assert!((x - want).abs() < 1e-15, "point {k}: {x} vs {want}");
        }
        // Small faces still take 3 points.
        assert_eq!(face_offsets(0.001, 0.01), vec![-0.0005, 0.0, 0.0005]);
    }

    /// The weighted mean by hand: each reading weighs the time since the one before
    /// it, the first nothing (exact in binary: the weights and readings are small
    /// whole numbers and halves).
    #[test]
    fn the_box_filter_weighs_each_reading_by_its_interval() {
        let mut f = BoxFilter::new(10.0);
        assert_eq!(f.mean(), 0.0, "no readings");
        f.push(0.0, 1.0);
        assert_eq!(f.mean(), 1.0, "one reading, weight 0: the plain mean");
        f.push(1.0, 3.0);
        f.push(3.0, 5.0);
        // Weights 0, 1, 2: (0 * 1 + 1 * 3 + 2 * 5) / 3.
        assert_eq!(f.mean(), 13.0 / 3.0);
        // Readings at one time weigh nothing: their plain mean.
        let mut same = BoxFilter::new(1.0);
        same.push(2.0, 1.0);
        same.push(2.0, 4.0);
        assert_eq!(same.mean(), 2.5);
    }

    /// A reading exactly `window` old stays in the window; an older one leaves it.
    #[test]
    fn the_box_filter_keeps_the_readings_of_its_window() {
        let mut f = BoxFilter::new(1.0);
        f.push(0.0, 8.0);
        f.push(1.0, 2.0);
        f.push(2.0, 4.0);
        // t = 0 left (older than 2 - 1); t = 1 (weight 1) and t = 2 (weight 1) remain.
        assert_eq!(f.readings().count(), 2);
        assert_eq!(f.mean(), 3.0);
        f.push(3.5, 6.0);
        // Only t = 3.5 remains, with weight 1.5.
        assert_eq!(f.readings().collect::<Vec<_>>(), vec![(3.5, 1.5, 6.0)]);
        assert_eq!(f.mean(), 6.0);
    }

    /// A checkpoint's readings restore the same filter, which then goes on alike.
    #[test]
    fn a_restored_box_filter_is_the_one_saved() {
        let mut f = BoxFilter::new(0.75);
        for (t, r) in [(0.0, -1.0), (0.25, 2.0), (0.5, 7.0), (0.625, -3.0)] {
            f.push(t, r);
        }
        let saved: Vec<_> = f.readings().collect();
        assert_eq!(saved.len(), 4);
        let mut g = BoxFilter::new(0.75);
        g.restore(saved);
        assert_eq!(g, f);
        f.push(0.875, 1.0);
        g.push(0.875, 1.0);
        assert_eq!(g, f);
        assert_eq!(g.mean(), f.mean());
    }
}
