//! The generic term loop against the loops compiled for a set.

use super::tests::{constants, jittered_world, neighbours, packed, H};
use super::{Fixed, RateTerms, TermBit, TermSpec};
use sph_core::kernel::{Kernel, Wendland};
use sph_core::pair::{EquationsOfMotion, Isa, Layouts, PairTerm, Pass, RateTerm};

use super::set_of as bits;

/// The generic loop ([`RateTerms`], a test of each term's `Option` per group) and the
/// loop compiled for the set ([`Fixed`]) add the same terms in the same order: the
/// same bits on every instruction set; with `wall_shear` the viscous terms read the
/// ghosts' no-slip velocities, and the compiled loop is [`Layouts::SHEAR`]'s.
fn same_bits_as_compiled<const SET: u16>(text: &str, wall_shear: bool) {
    let world = jittered_world();
    let k = Wendland::new(H);
    let specs: Vec<TermSpec> = sph_core::registry::ron_options().from_str(text).unwrap();
    RateTerms::check(&specs).unwrap();
    let terms = RateTerms::build(&specs, &constants(), wall_shear);
    assert_eq!(terms.set(), SET, "{text}");
    if wall_shear {
        assert_eq!(Layouts::of(terms.reads()), Layouts::SHEAR, "{text}");
        assert!(<Fixed<SET> as RateTerm>::LAYOUTS.has(Layouts::SHEAR));
    }
    let r = packed(&world, terms.reads());
    let options = EquationsOfMotion(terms);
    let compiled = EquationsOfMotion(Fixed::<SET>::of(&terms).unwrap());
    assert_eq!(compiled.reads(), options.reads());
    for isa in Isa::available().into_iter().chain([Isa::SCALAR]) {
        for i in [20, 70, 100] {
            let js = neighbours(&r, i, k.support());
            let a = Pass::with_isa(&options, k, &r, isa).unwrap().sum(i, &js);
            let c = Pass::with_isa(&compiled, k, &r, isa).unwrap().sum(i, &js);
            assert!(
                a.acc.length() > 0.0 && a.drho != 0.0,
                "{text}: nothing summed at {i}"
            );
            assert_eq!(
                a, c,
                "{text}, {isa:?}, particle {i}: generic against compiled"
            );
        }
    }
}

#[test]
fn the_generic_loop_sums_the_riemann_set_as_compiled() {
    use TermBit::*;
    const SET: u16 = bits(&[RiemannPressure, Continuity, RiemannDiffusion]);
    same_bits_as_compiled::<SET>(
        "[RiemannPressure(), Continuity(), RiemannDiffusion()]",
        false,
    );
}

/// The same against wall particles (or mirrors that do not slip), whose viscous
/// velocities are a column of their own.
#[test]
fn the_generic_loop_sums_the_riemann_set_with_wall_shear_as_compiled() {
    use TermBit::*;
    const SET: u16 = bits(&[RiemannPressure, Continuity, RiemannDiffusion]);
    same_bits_as_compiled::<SET>(
        "[RiemannPressure(), Continuity(), RiemannDiffusion()]",
        true,
    );
}

#[test]
fn the_generic_loop_sums_the_papers_set_as_compiled() {
    use TermBit::*;
    const SET: u16 = bits(&[
        PressureGradient,
        ArtificialViscosity,
        ArtificialPressure,
        Continuity,
    ]);
    same_bits_as_compiled::<SET>(
        "[PressureGradient(), ArtificialViscosity(), ArtificialPressure(), Continuity()]",
        false,
    );
    same_bits_as_compiled::<SET>(
        "[PressureGradient(), ArtificialViscosity(), ArtificialPressure(), Continuity()]",
        true,
    );
}
