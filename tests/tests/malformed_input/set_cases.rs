//! Malformed `--set` arguments, and file errors beside them.

use super::cases::*;

/// The `--set` cases.
pub fn set_cases() -> Vec<Case> {
    use Field::*;
    use Place::*;
    vec![
        Case {
            overrides: &["fluidd.density=1200"],
            ..case(
                "unknown --set path",
                DAM.to_string(),
                Nowhere,
                AbsentOr(&[]),
                &[
                    "--set fluidd.density=1200",
                    "no field `fluidd`",
                    "did you mean `fluid`?",
                ],
            )
        },
        Case {
            overrides: &["pipeline.forcez.alpha=0.1"],
            ..case(
                "unknown --set stage",
                DAM.to_string(),
                Nowhere,
                AbsentOr(&[]),
                &[
                    "--set pipeline.forcez.alpha=0.1: ",
                    "no element `forcez`",
                    "neighbour_grid",
                    "did you mean `forces`?",
                ],
            )
        },
        Case {
            // A misspelt leaf is inserted into its struct, and the loader refuses it as
            // an unknown field: the error is the `--set` argument's, at no place in the
            // file (which does not hold that text).
            overrides: &["end_tme=1.0"],
            ..case(
                "misspelt --set field",
                DAM.to_string(),
                Nowhere,
                AbsentOr(&["end_tme"]),
                &[
                    "--set end_tme=1.0: ",
                    "`end_tme`",
                    "did you mean `end_time`?",
                ],
            )
        },
        Case {
            overrides: &["pipeline.forces.terms.artificial_viscosity.alfa=0.1"],
            ..case(
                "misspelt --set term parameter",
                DAM.to_string(),
                Nowhere,
                AbsentOr(&["alfa"]),
                &[
                    "--set pipeline.forces.terms.artificial_viscosity.alfa=0.1: ",
                    "`alfa`",
                    "`alpha` or `beta`",
                    "did you mean `alpha`?",
                ],
            )
        },
        Case {
            overrides: &["pipeline.reinitialise.filter=Shephard"],
            ..case(
                "misspelt --set variant",
                DAM.to_string(),
                Nowhere,
                Is("filter"),
                &[
                    "--set pipeline.reinitialise.filter=Shephard: ",
                    "did you mean `Shepard`?",
                ],
            )
        },
        Case {
            overrides: &["end_time=-1"],
            ..case(
                "out-of-range --set value",
                DAM.to_string(),
                Nowhere,
                Is("end_time"),
                &["--set end_time=-1: ", "-1 is out of range"],
            )
        },
        Case {
            // A stage's range check points at the end of the stage's parentheses,
            // outside the override's text: told as the override's by the field.
            overrides: &["pipeline.integrate.courant=2"],
            ..case(
                "out-of-range --set stage parameter",
                DAM.to_string(),
                Nowhere,
                Is("courant"),
                &["--set pipeline.integrate.courant=2: ", "2 is out of range"],
            )
        },
        Case {
            overrides: &["pipeline.integrate=Integrate(courant: 2)"],
            ..case(
                "out-of-range --set stage",
                DAM.to_string(),
                Nowhere,
                Is("courant"),
                &[
                    "--set pipeline.integrate=Integrate(courant: 2): ",
                    "2 is out of range",
                ],
            )
        },
        Case {
            // A term's check names the field `terms` and the term's own field.
            overrides: &["pipeline.forces.terms.artificial_viscosity.beta=-2"],
            ..case(
                "out-of-range --set term parameter",
                DAM.to_string(),
                Nowhere,
                Is("terms"),
                &[
                    "--set pipeline.forces.terms.artificial_viscosity.beta=-2: ",
                    "`beta` = -2 is out of range",
                ],
            )
        },
        Case {
            overrides: &["pipeline.integrate.courant=NaN"],
            ..case(
                "NaN --set stage parameter",
                DAM.to_string(),
                Nowhere,
                Is("courant"),
                &[
                    "--set pipeline.integrate.courant=NaN: ",
                    "NaN is out of range",
                ],
            )
        },
        Case {
            overrides: &["pipeline.forces.terms.artificial_viscosity.alpha=inf"],
            ..case(
                "inf --set term parameter",
                DAM.to_string(),
                Nowhere,
                Is("terms"),
                &["`alpha` = inf is out of range", "finite"],
            )
        },
        Case {
            overrides: &["pipeline.eos.min_pressure=Some(-inf)"],
            ..case(
                "-inf --set pressure floor",
                DAM.to_string(),
                Nowhere,
                Is("min_pressure"),
                &["-inf is out of range", "finite"],
            )
        },
        Case {
            overrides: &["pipeline.neighbour_grid.skin=NaN"],
            ..case(
                "NaN --set neighbour skin",
                DAM.to_string(),
                Nowhere,
                Is("skin"),
                &["NaN is out of range", "0 to 10"],
            )
        },
        Case {
            overrides: &["resolution=ParticlesAcross(-100)"],
            ..case(
                "out-of-range --set resolution",
                DAM.to_string(),
                Nowhere,
                Is("resolution"),
                &[
                    "--set resolution=ParticlesAcross(-100): ",
                    "ParticlesAcross(-100) is out of range",
                    "e.g. ParticlesAcross(40)",
                ],
            )
        },
        Case {
            // An error in the file itself, after an override on another field: still
            // the file's, at its place in the file (not told as the override's).
            overrides: &["pipeline.forces.terms.artificial_viscosity.alpha=0.1"],
            ..case(
                "file error beside an override",
                dam_stage(
                    "Forces",
                    "Forces(terms: [ArtificialViscosity(alpha: 0.03, beta: -1.0)])",
                ),
                LineOf("Forces(terms"),
                AbsentOr(&["terms"]),
                &["`beta` = -1 is out of range"],
            )
        },
    ]
}
