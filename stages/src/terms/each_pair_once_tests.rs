//! Each pair once ([`Pass::sum_both`]) against each side's own sum ([`Pass::sum`]):
//! for every shipped term, every particle's rates, neighbour count and the energy
//! rates' totals are the same to round-off, on every instruction set. A share of j
//! with a wrong sign, mass, density or hydrostatic correction changes particle j's
//! sum by the size of one pair's term, far beyond the 1e-12 allowed.

use super::tests::{constants, jittered_world_with, neighbours, packed, H};
use super::{RateTerms, TermSpec};
use glam::DVec2;
use sph_core::kernel::{Kernel, Wendland};
use sph_core::pair::{Counted, EquationsOfMotion, Isa, Pass, RateTerm, Shares, SHARE};

/// One list of each kind the shipped scenarios and studies run, together covering
/// every shipped term (and the artificial viscosity's quadratic part).
const LISTS: &[&str] = &[
    "[PressureGradient(), ArtificialViscosity(), ArtificialPressure(), Continuity()]",
    "[PressureGradient(), ArtificialViscosity(alpha: 0.1, beta: 0.2), Continuity(), MolteniColagrossi()]",
    "[PressureGradient(), LaminarViscosity(nu: 1e-3), Continuity(), Fourtakas(delta: 0.2)]",
    "[PressureGradient(), ArtificialViscosity(), Continuity(), DeltaSph()]",
    "[RiemannPressure(), Continuity(), RiemannDiffusion()]",
    "[RiemannPressure(limiter: 10.0), Continuity(), RiemannDiffusion(remove_hydrostatic: false)]",
];

#[test]
fn each_pair_once_sums_what_each_side_sums() {
    // Masses that differ, so that a share weighted by the wrong particle's mass shows.
    let world = jittered_world_with(|u| 0.1 * (0.7 + 0.6 * u));
    let n = sph_core::world::count::<sph_core::components::Fluid>(&world);
    let k = Wendland::new(H);
    for text in LISTS {
        let specs: Vec<TermSpec> = sph_core::registry::ron_options().from_str(text).unwrap();
        RateTerms::check(&specs).unwrap();
        let terms = RateTerms::build(&specs, &constants(), false);
        let r = packed(&world, terms.reads());
        let eom = Counted::<_, false> {
            term: EquationsOfMotion(terms),
            radius: k.support(),
        };
        let lists: Vec<Vec<u32>> = (0..n).map(|i| neighbours(&r, i, k.support())).collect();
        for isa in Isa::available().into_iter().chain([Isa::SCALAR]) {
            let pass = Pass::with_isa(&eom, k, &r, isa).unwrap();
            let mut records = vec![[0.0; SHARE]; n];
            let mut shares = Shares {
                start: 0,
                records: &mut records,
            };
            let once: Vec<_> = (0..n)
                .map(|i| {
                    let list = &lists[i];
                    let upper: Vec<u32> = list
                        .iter()
                        .copied()
                        .filter(|&j| j as usize > i && (j as usize) < n)
                        .collect();
                    let ghosts: Vec<u32> =
                        list.iter().copied().filter(|&j| j as usize >= n).collect();
                    let (s, c, _) = pass.sum_both(i, &upper, &mut shares);
                    let (w, cw, _) = pass.sum(i, &ghosts);
                    (s + w, c + cw)
                })
                .collect();
            let (mut power, mut diffusion) = ([0.0; 2], [0.0; 2]);
            let scale = (0..n)
                .map(|i| pass.sum(i, &lists[i]).0.acc.length())
                .fold(0.0, f64::max);
            let rate_scale = (0..n)
                .map(|i| pass.sum(i, &lists[i]).0.drho.abs())
                .fold(0.0, f64::max);
            for i in 0..n {
                let (two, count, _) = pass.sum(i, &lists[i]);
                let (one, own_count) = once[i];
                let rec = records[i];
                let acc = one.acc + DVec2::new(rec[0], rec[1]);
                let drho = one.drho + rec[2];
                let what = format!("{text} on {}, particle {i}", isa.name());
                assert!(
                    (acc - two.acc).length() <= 1e-12 * scale,
                    "{what}: dv/dt {acc} against {}",
                    two.acc
                );
                assert!(
                    (drho - two.drho).abs() <= 1e-12 * rate_scale,
                    "{what}: d rho/dt {drho} against {}",
                    two.drho
                );
                assert_eq!(own_count + rec[3] as u32, count, "{what}: count");
                power[0] += one.power;
                power[1] += two.power;
                diffusion[0] += one.diffusion;
                diffusion[1] += two.diffusion;
            }
            for (name, [a, b]) in [("viscous", power), ("diffusion", diffusion)] {
                assert!(
                    (a - b).abs() <= 1e-12 * b.abs().max(1e-300),
                    "{text} on {}: {name} power {a} against {b}",
                    isa.name()
                );
            }
        }
    }
}
