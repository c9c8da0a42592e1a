//! The plugin term against Akinci et al. (2013), summed through the engine's pair layer
//! as `Forces` sums it (behind a `PluginTerm`, after a compiled term set), on every
//! instruction set the processor has.

use cohesion::{Cohesion, Params};
use glam::DVec2;
use sph_core::components::{Density, Fluid, Mass, Position, Pressure, Velocity};
use sph_core::kernel::{Kernel, KernelKind, Wendland};
use sph_core::pair::{EquationsOfMotion, Field, Isa, NoTerms, Pass, PluginTerm};
use sph_core::pair::{RateTerm, Records, WithPlugins};
use sph_core::sim::{Constants, Tait};
use sph_core::terms::Term;
use sph_core::world::Particles;
use std::f64::consts::PI;

const DS: f64 = 0.01;
const H: f64 = 1.3 * DS;
const RHO0: f64 = 1000.0;

fn constants() -> Constants {
    Constants {
        eos: Tait::new(RHO0, 30.0, 7.0),
        gravity: DVec2::ZERO,
        spacing: DS,
        h: H,
        kernel: KernelKind::Wendland,
        fluid_height: 0.1,
        domain: (DVec2::splat(-1.0), DVec2::splat(1.0)),
    }
}

fn term(gamma: f64) -> Cohesion {
    Cohesion::build(&Params { gamma }, &constants())
}

/// Fluid particles at `at`, of mass rho_0 DS^2, densities varying by a few per cent
/// (so K_ij differs from 1), at rest.
fn world(at: &[DVec2]) -> hecs::World {
    let mut world = hecs::World::new();
    for (k, &x) in at.iter().enumerate() {
        let rho = RHO0 * (1.0 + 0.03 * ((k * 7 % 11) as f64 / 11.0 - 0.5));
        world.spawn((
            Fluid,
            Position(x),
            Velocity(DVec2::ZERO),
            Density(rho),
            Mass(RHO0 * DS * DS),
            Pressure(0.0),
        ));
    }
    world
}

/// dv_i/dt of every particle, all pairs within the support as neighbours, summed by
/// `Forces`' loop with the term behind a pointer, on instruction set `isa`.
fn accelerations(world: &hecs::World, t: Cohesion, isa: Isa) -> Vec<DVec2> {
    let plugins = [PluginTerm::new("Cohesion", t)];
    let terms = WithPlugins {
        base: NoTerms,
        plugins: &plugins,
    };
    let mut r = Records::default();
    r.pack(
        &Particles::of(world).unwrap(),
        terms.reads(),
        &constants().eos,
    )
    .unwrap();
    let k = Wendland::new(H);
    let eom = EquationsOfMotion(terms);
    let pass = Pass::with_isa(&eom, k, &r, isa).unwrap();
    let at = |j: usize| DVec2::new(r.get(j, Field::X), r.get(j, Field::Y));
    (0..r.len())
        .map(|i| {
            let js: Vec<u32> = (0..r.len() as u32)
                .filter(|&j| j as usize != i && (at(i) - at(j as usize)).length() < k.support())
                .collect();
            pass.sum(i, &js).acc
        })
        .collect()
}

/// Eqs. (1), (2) and (4) of the paper, by hand: a plain loop over pairs.
fn by_hand(world: &hecs::World, gamma: f64) -> Vec<DVec2> {
    let h = constants().support();
    let c = |r: f64| {
        let s = (h - r).powi(3) * r.powi(3);
        let v = if r > h / 2.0 {
            s
        } else {
            2.0 * s - h.powi(6) / 64.0
        };
        32.0 / (PI * h.powi(9)) * v
    };
    let p: Vec<(DVec2, f64, f64)> = world
        .query::<(&Position, &Density, &Mass)>()
        .iter()
        .map(|(x, rho, m)| (x.0, rho.0, m.0))
        .collect();
    p.iter()
        .map(|&(xi, rhoi, _)| {
            p.iter()
                .map(|&(xj, rhoj, mj)| {
                    let x = xi - xj;
                    let r = x.length();
                    if r == 0.0 || r >= h {
                        return DVec2::ZERO;
                    }
                    -gamma * mj * (2.0 * RHO0 / (rhoi + rhoj)) * c(r) * x / r
                })
                .sum()
        })
        .collect()
}

/// A jittered 9 x 9 patch: the pairs span every branch of the spline.
fn patch() -> Vec<DVec2> {
    let mut at = Vec::new();
    for a in 0..9 {
        for b in 0..9 {
            let k = (a * 9 + b) as f64;
            let jitter = DVec2::new((k * 0.37).sin(), (k * 0.73).cos()) * 0.2 * DS;
            at.push(DVec2::new(a as f64, b as f64) * DS + jitter);
        }
    }
    at
}

/// The plugin's sums are the paper's formula to round-off on every instruction set:
/// 1e-12 of the largest acceleration (the paths add the same pair terms in different
/// orders, so they differ in the last bits only).
#[test]
fn cohesion_sums_what_akinci_writes_on_every_instruction_set() {
    let w = world(&patch());
    let gamma = 2.0;
    let want = by_hand(&w, gamma);
    let scale = want.iter().map(|a| a.length()).fold(0.0, f64::max);
    assert!(scale > 0.0);
    let mut isas = vec![Isa::SCALAR];
    isas.extend(Isa::available());
    for isa in isas {
        let got = accelerations(&w, term(gamma), isa);
        for (i, (g, e)) in got.iter().zip(&want).enumerate() {
            assert!(
                (*g - *e).length() <= 1e-12 * scale,
                "{}: particle {i}: {g} against {e}",
                isa.name()
            );
        }
    }
}

/// Newton's third law: the pair force -gamma m_i m_j K_ij C x_ij / r is antisymmetric,
/// so the patch's total force, sum_i m_i a_i, vanishes to round-off (1e-12 of the sum
/// of the force magnitudes).
#[test]
fn cohesion_conserves_momentum() {
    let w = world(&patch());
    let a = accelerations(&w, term(2.0), Isa::detect());
    let m = RHO0 * DS * DS;
    let total: DVec2 = a.iter().map(|a| m * *a).sum();
    let magnitude: f64 = a.iter().map(|a| m * a.length()).sum();
    assert!(
        total.length() <= 1e-12 * magnitude,
        "{total} of {magnitude}"
    );
}

/// Two particles: attracted at r = 3 h_s / 4, repelled at r = h_s / 8, and nothing at
/// or beyond h_s; the spline's peak is 1 / (2 pi h_s^3) at h_s / 2 (the paper's Fig. 2).
#[test]
fn a_pair_attracts_beyond_a_quarter_support_and_repels_within() {
    let t = term(1.0);
    let hs = constants().support();
    let peak = 1.0 / (2.0 * PI * hs.powi(3));
    assert!((t.spline(hs / 2.0) - peak).abs() <= 1e-12 * peak);
    assert!((t.spline(1e-9 * hs) + peak).abs() <= 1e-6 * peak);
    assert_eq!(t.spline(hs), 0.0);
    assert_eq!(t.spline(0.0), 0.0);
    // Particle 0 sits left of particle 1: attraction pulls it right (+x).
    for (r, towards) in [(0.75 * hs, 1), (hs / 8.0, -1), (1.01 * hs, 0)] {
        let w = world(&[DVec2::ZERO, DVec2::new(r, 0.0)]);
        let a = accelerations(&w, t, Isa::detect());
        let sign = (a[0].x > 0.0) as i32 - (a[0].x < 0.0) as i32;
        assert_eq!(sign, towards, "r = {r}: {}", a[0]);
        assert_eq!(a[0].y, 0.0);
        assert_eq!(a[0], -a[1], "r = {r}: equal masses, opposite accelerations");
    }
}

#[test]
fn gamma_out_of_range_is_refused_naming_the_field() {
    for gamma in [-1.0, f64::NAN, f64::INFINITY] {
        let e = Cohesion::check(&Params { gamma }).unwrap_err();
        assert_eq!(e.field, "gamma");
    }
    assert!(Cohesion::check(&Params { gamma: 0.0 }).is_ok());
}

/// `register` adds the term under the name a scenario writes (the full run through
/// Forces is `tests/tests/plugin.rs`).
#[test]
fn register_adds_the_term_under_its_name() {
    let mut registry = sph_core::StageRegistry::new();
    assert!(!registry.terms().contains("Cohesion"));
    cohesion::register(&mut registry);
    assert!(registry.terms().contains("Cohesion"));
    assert_eq!(registry.terms().list().count(), 1);
}
