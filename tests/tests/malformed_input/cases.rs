//! The malformed scenarios and what their errors must say: the file's own mistakes
//! ([`cases`]) and those of `--set` arguments ([`set_cases`]).

pub const DAM: &str = include_str!("../../../scenarios/dam_break_paper.ron");

/// Where the error must point.
#[derive(Clone, Copy, Debug)]
pub enum Place {
    /// The first line of the constructed text that contains this string.
    LineOf(&'static str),
    /// The last line of the text (an error at the end of input).
    LastLine,
    /// Not tied to a place in the file: line and column 0.
    Nowhere,
}

/// What `LoadError::field` must be.
#[derive(Clone, Copy, Debug)]
pub enum Field {
    /// Not checked (the message names what matters).
    Any,
    /// Exactly this field.
    Is(&'static str),
    /// No field, or one of these: never an unrelated field.
    AbsentOr(&'static [&'static str]),
}

pub struct Case {
    pub name: &'static str,
    pub text: String,
    pub overrides: &'static [&'static str],
    pub place: Place,
    pub field: Field,
    /// Substrings the whole error (`Display`: file, place, field and message) must hold.
    pub expect: &'static [&'static str],
    /// The current engine does not yet give a good error here (see the comment at the
    /// case): the strict assertions are reported but not enforced — the case must still
    /// fail to load, without panicking. Remove the flag once the engine is fixed (the
    /// test prints a note when a flagged case passes).
    pub expect_known_gap: bool,
}

pub fn case(
    name: &'static str,
    text: String,
    place: Place,
    field: Field,
    expect: &'static [&'static str],
) -> Case {
    Case {
        name,
        text,
        overrides: &[],
        place,
        field,
        expect,
        expect_known_gap: false,
    }
}

/// The dam break with `from` (which must occur exactly once) replaced by `to`.
pub fn dam(from: &str, to: &str) -> String {
    assert_eq!(
        DAM.matches(from).count(),
        1,
        "`{from}` must occur exactly once in dam_break_paper.ron"
    );
    DAM.replacen(from, to, 1)
}

/// Offset of the first `name` in `text` that starts a word and is followed by `after`
/// (outside comments and strings).
pub fn find_word(text: &str, name: &str, after: char) -> usize {
    let b = text.as_bytes();
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'/' if b.get(i + 1) == Some(&b'/') => {
                i = text[i..].find('\n').map_or(b.len(), |n| i + n);
            }
            b'"' => i = text[i + 1..].find('"').map_or(b.len(), |n| i + n + 2),
            _ if text[i..].starts_with(name)
                && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'))
                && text[i + name.len()..].trim_start().starts_with(after) =>
            {
                return i
            }
            _ => i += 1,
        }
    }
    panic!("`{name}{after}` not in dam_break_paper.ron")
}

/// End of the RON value starting at `start`: the first `,` or closing bracket outside
/// brackets, strings and comments (trailing blanks excluded).
pub fn value_end(text: &str, start: usize) -> usize {
    let b = text.as_bytes();
    let (mut depth, mut i) = (0usize, start);
    while i < b.len() {
        match b[i] {
            b'/' if b.get(i + 1) == Some(&b'/') => {
                i = text[i..].find('\n').map_or(b.len(), |n| i + n);
                continue;
            }
            b'"' => {
                i = text[i + 1..].find('"').map_or(b.len(), |n| i + n + 2);
                continue;
            }
            b'(' | b'[' | b'{' => depth += 1,
            b')' | b']' | b'}' if depth > 0 => {
                depth -= 1;
                if depth == 0 {
                    return i + 1;
                }
            }
            b',' | b')' | b']' | b'}' if depth == 0 => {
                return start + text[start..i].trim_end().len()
            }
            _ => {}
        }
        i += 1;
    }
    b.len()
}

/// The dam break with the value of the top-level field `field` replaced by `value`.
pub fn dam_value(field: &str, value: &str) -> String {
    let key = find_word(DAM, field, ':');
    let colon = key + DAM[key..].find(':').expect("colon");
    let start = colon + 1 + (DAM[colon + 1..].len() - DAM[colon + 1..].trim_start().len());
    let end = value_end(DAM, start);
    format!("{}{value}{}", &DAM[..start], &DAM[end..])
}

/// The dam break with pipeline stage `Name(...)` replaced by `entry`.
pub fn dam_stage(name: &str, entry: &str) -> String {
    let start = find_word(DAM, name, '(');
    let end = value_end(DAM, start);
    format!("{}{entry}{}", &DAM[..start], &DAM[end..])
}

/// 1-based line of the first occurrence of `needle` in `text`.
pub fn line_of(text: &str, needle: &str) -> usize {
    let at = text
        .find(needle)
        .unwrap_or_else(|| panic!("marker `{needle}` not in the case text"));
    text[..at].matches('\n').count() + 1
}

/// Every malformed input: the file's and the `--set` arguments'.
pub fn cases() -> Vec<Case> {
    use Field::*;
    use Place::*;
    let mut all = vec![
        case(
            "missing comma",
            {
                let text = dam_value("end_time", "2.0");
                let comma = text.find("end_time: 2.0,").expect("end_time") + 13;
                format!("{}{}", &text[..comma], &text[comma + 1..])
            },
            LineOf("fluid: ("),
            Any,
            &["Expected comma"],
        ),
        case(
            "unbalanced paren",
            dam_value("fluid_blocks", "[(min: (0.0, 0.0), size: (1.2, 0.6)]"),
            LineOf("fluid_blocks:"),
            Any,
            &["Expected comma"],
        ),
        case(
            "unterminated file",
            DAM.trim_end()
                .strip_suffix(')')
                .expect("the scenario ends with `)`")
                .trim_end()
                .to_string(),
            LastLine,
            AbsentOr(&["Scenario"]),
            &["end of RON"],
        ),
        case(
            "unknown stage",
            dam_stage("Forces", "Forcez(alpha: 0.03)"),
            LineOf("Forcez("),
            AbsentOr(&["pipeline"]),
            &[
                "unknown stage `Forcez`; did you mean `Forces`?",
                "known stages:",
                "GhostWalls",
                "NeighbourGrid",
                "Integrate",
            ],
        ),
        case(
            "unknown top-level field",
            dam("Scenario(\n", "Scenario(\n    viscosity: 0.1,\n"),
            LineOf("viscosity:"),
            AbsentOr(&["viscosity"]),
            &["`viscosity`", "end_time", "h_over_dx", "fluid_blocks"],
        ),
        case(
            "unknown field in fluid",
            dam("    fluid: (\n", "    fluid: (\n        gama: 7.0,\n"),
            LineOf("gama:"),
            AbsentOr(&["fluid", "gama"]),
            &["`gama`", "gamma", "sound_speed"],
        ),
        case(
            "unknown stage parameter",
            dam_stage("Forces", "Forces(alfa: 0.1)"),
            LineOf("Forces(alfa"),
            AbsentOr(&["alfa", "pipeline"]),
            &["`alfa`", "terms"],
        ),
        case(
            "unknown pair-term parameter",
            dam_stage("Forces", "Forces(terms: [ArtificialViscosity(alfa: 0.1)])"),
            LineOf("Forces(terms"),
            AbsentOr(&["alfa", "pipeline"]),
            &["`alfa`", "alpha", "beta", "did you mean `alpha`?"],
        ),
        case(
            "unknown pair term",
            dam_stage("Forces", "Forces(terms: [Viscosity()])"),
            LineOf("Forces(terms"),
            AbsentOr(&["pipeline", "terms"]),
            &["`Viscosity`", "ArtificialViscosity", "LaminarViscosity"],
        ),
        case(
            "pair term out of range",
            dam_stage("Forces", "Forces(terms: [ArtificialViscosity(alpha: -1.0)])"),
            LineOf("Forces(terms"),
            AbsentOr(&["terms"]),
            &["ArtificialViscosity", "`alpha`", "accepted"],
        ),
        case(
            "pair term named twice",
            dam_stage("Forces", "Forces(terms: [Continuity(), Continuity()])"),
            LineOf("Forces(terms"),
            AbsentOr(&["terms"]),
            &["Continuity", "twice"],
        ),
        case(
            "wrong type",
            dam_value("end_time", "\"two\""),
            LineOf("end_time:"),
            Is("end_time"),
            &["Expected float"],
        ),
        case(
            "wrong type in a stage",
            dam_stage("Reinitialise", "Reinitialise(every: \"often\")"),
            LineOf("Reinitialise("),
            Is("every"),
            &["Expected integer"],
        ),
        case(
            "h_over_dx out of range",
            dam_value("h_over_dx", "5.0"),
            LineOf("h_over_dx:"),
            Is("h_over_dx"),
            &["5 is out of range", "0.5 to 3.0"],
        ),
        // NaN, inf and -inf in every class of numeric field (issue 28): a top-level
        // number, a fluid property, a pair, a resolution, a block size, a sensor's and
        // a gauge's place, and (below, through --set) a stage's and a term's parameter.
        case(
            "end_time NaN",
            dam("    end_time: 2.0,", "    end_time: NaN,"),
            LineOf("end_time: NaN"),
            Is("end_time"),
            &["NaN is out of range", "finite"],
        ),
        case(
            "sound_speed inf",
            dam("    fluid: (\n", "    fluid: (\n        sound_speed: inf,\n"),
            LineOf("sound_speed: inf"),
            Is("sound_speed"),
            &["inf is out of range", "finite"],
        ),
        case(
            "gravity NaN",
            dam("gravity: (0.0, -9.81)", "gravity: (0.0, NaN)"),
            LineOf("gravity: (0.0, NaN)"),
            Is("gravity"),
            &["(0, NaN) is out of range", "two finite numbers"],
        ),
        case(
            "spacing -inf",
            dam("resolution: ParticlesAcross(100)", "resolution: Spacing(-inf)"),
            LineOf("resolution: Spacing(-inf)"),
            Is("resolution"),
            &["-inf is out of range"],
        ),
        case(
            "block size inf",
            dam("size: (1.2, 0.6)", "size: (inf, 0.6)"),
            LineOf("size: (inf, 0.6)"),
            Is("size"),
            &["inf is out of range"],
        ),
        case(
            "sensor at NaN",
            dam("at: (3.22, 0.096)", "at: (3.22, NaN)"),
            LineOf("at: (3.22, NaN)"),
            Is("pressure_sensors"),
            &["at (3.22, NaN) is not on wall `right`"],
        ),
        case(
            "gauge at inf",
            dam("x: 2.725", "x: inf"),
            LineOf("x: inf"),
            Is("x"),
            &["x = inf is out of range", "finite"],
        ),
        case(
            "sound_speed zero",
            dam("    fluid: (\n", "    fluid: (\n        sound_speed: 0.0,\n"),
            LineOf("sound_speed: 0.0"),
            Is("sound_speed"),
            &["0 is out of range", "> 0"],
        ),
        case(
            "sound_speed negative",
            dam("    fluid: (\n", "    fluid: (\n        sound_speed: -34.3,\n"),
            LineOf("sound_speed: -34.3"),
            Is("sound_speed"),
            &["-34.3 is out of range", "> 0"],
        ),
        case(
            "end_time zero",
            dam_value("end_time", "0.0"),
            LineOf("end_time:"),
            Is("end_time"),
            &["0 is out of range", "> 0"],
        ),
        case(
            "end_time negative",
            dam_value("end_time", "-1"),
            LineOf("end_time:"),
            Is("end_time"),
            &["-1 is out of range", "> 0"],
        ),
        case(
            "fluid beyond the tank",
            dam_value("fluid_blocks", "[(min: (2.5, 0.0), size: (1.2, 0.6))]"),
            LineOf("fluid_blocks:"),
            Is("fluid_blocks"),
            &["outside wall `right`", "inside the walls"],
        ),
        case(
            "fluid below the floor",
            dam_value("fluid_blocks", "[(min: (0.0, -0.3), size: (1.2, 0.6))]"),
            LineOf("fluid_blocks:"),
            Is("fluid_blocks"),
            &["outside wall `bottom`"],
        ),
        case(
            "sensor on a nonexistent wall",
            dam_value(
                "pressure_sensors",
                "[\n        (name: \"P1\", wall: \"right\", at: (3.22, 0.096)),\n        \
                 (name: \"P2\", wall: \"rigth\", at: (3.22, 0.584)),\n    ]",
            ),
            LineOf("wall: \"rigth\""),
            Is("pressure_sensors"),
            &[
                "sensor `P2`",
                "`rigth`",
                "does not exist",
                "left, bottom, right",
            ],
        ),
        case(
            "negative ParticlesAcross",
            dam_value("resolution", "ParticlesAcross(-100)"),
            LineOf("resolution:"),
            Is("resolution"),
            &[
                "ParticlesAcross(-100) is out of range",
                "ParticlesAcross takes a whole number of particles across the first fluid block, 2 or more",
                "e.g. ParticlesAcross(40)",
            ],
        ),
        case(
            "fractional ParticlesAcross",
            dam_value("resolution", "ParticlesAcross(40.5)"),
            LineOf("resolution:"),
            Is("resolution"),
            &["ParticlesAcross(40.5) is not a whole number", "e.g. ParticlesAcross(40)"],
        ),
        case(
            "ParticlesAcross beyond u32",
            dam_value("resolution", "ParticlesAcross(99999999999)"),
            LineOf("resolution:"),
            Is("resolution"),
            &["ParticlesAcross(99999999999) is out of range", "2 or more"],
        ),
        case(
            "ParticlesAcross(1)",
            dam_value("resolution", "ParticlesAcross(1)"),
            LineOf("resolution:"),
            Is("resolution"),
            &["ParticlesAcross(1) is out of range", "2 or more"],
        ),
        case(
            "too many particles",
            dam_value("resolution", "ParticlesAcross(10000)"),
            LineOf("resolution:"),
            Is("resolution"),
            &["50000000 fluid particles", "at most 20000000", "coarser"],
        ),
        case(
            "too many particles by spacing",
            dam_value("resolution", "Spacing(1e-5)"),
            LineOf("resolution:"),
            Is("resolution"),
            &["7200000000 fluid particles", "at most 20000000"],
        ),
        case(
            "field named in a comment",
            format!(
                "// resolution: chosen for speed\n{}",
                dam_value("resolution", "ParticlesAcross(1)")
            ),
            LineOf("resolution: ParticlesAcross"),
            Is("resolution"),
            &["ParticlesAcross(1) is out of range"],
        ),
        case(
            "sound speed without gravity",
            dam_value("gravity", "(0.0, 0.0)"),
            LineOf("gravity:"),
            Is("sound_speed"),
            &["without gravity", "give `sound_speed"],
        ),
        case(
            "duplicate wall name",
            dam(
                "    fluid_blocks:",
                "    walls: [(name: \"left\", from: (2.0, 0.0), to: (2.0, 1.0))],\n    fluid_blocks:",
            ),
            LineOf("walls: [("),
            Is("walls"),
            &["two walls are named `left`"],
        ),
        case(
            "every: 0",
            dam_stage("Reinitialise", "Reinitialise(every: 0)"),
            LineOf("Reinitialise("),
            Is("every"),
            &["`every` is out of range", "1 or more"],
        ),
        case(
            "courant 2.0",
            dam_stage("Integrate", "Integrate(courant: 2.0)"),
            LineOf("Integrate("),
            Is("courant"),
            &["2 is out of range", "0 < C <= 1"],
        ),
        case(
            "wall particles that both mirror and follow the fluid",
            dam_stage(
                "Eos",
                "Eos(),\n        WallPressure(mirror: true, separation: true)",
            ),
            LineOf("WallPressure("),
            Is("mirror"),
            &["false when `separation` is true"],
        ),
        case(
            "stage without parentheses",
            dam_stage("NeighbourGrid", "NeighbourGrid"),
            LineOf("NeighbourGrid,"),
            AbsentOr(&["pipeline"]),
            &["NeighbourGrid()"],
        ),
        case(
            "empty pipeline",
            dam_value("pipeline", "[]"),
            LineOf("pipeline:"),
            Is("pipeline"),
            &["the pipeline is empty"],
        ),
        case(
            "no fluid blocks",
            dam_value("fluid_blocks", "[]"),
            LineOf("fluid_blocks:"),
            Is("fluid_blocks"),
            &["no fluid"],
        ),
        case(
            "integrate not every step",
            dam_stage("Integrate", "Integrate(every: 2, courant: 0.25)"),
            LineOf("Integrate(every: 2"),
            Is("every"),
            &["Integrate runs every step"],
        ),
        case(
            "misspelt extraction method",
            dam(
                "methods: [Shepard, Nearest, Averaged]",
                "methods: [Shepard, Nearest, Averagd]",
            ),
            LineOf("Averagd"),
            Is("methods"),
            &[
                "unknown variant `Averagd`",
                "`Averaged`, `Nearest`, `Shepard`",
                "did you mean `Averaged`?",
            ],
        ),
        case(
            "extraction method named twice",
            dam(
                "methods: [Shepard, Nearest, Averaged]",
                "methods: [Shepard, Nearest, Shepard]",
            ),
            LineOf("methods: [Shepard, Nearest, Shepard]"),
            Is("methods"),
            &["`Shepard` is listed twice; name each method once"],
        ),
        case(
            "two writers of the density rate",
            dam("        Forces(", "        Continuity(),\n        Forces("),
            LineOf("Forces(terms"),
            Is("pipeline"),
            &[
                "Forces writes `DensityRate`",
                "which Continuity (line",
                "one writer: remove one of them",
            ],
        ),
        case(
            "two writers of the density rate, the other order",
            dam("        Probe(", "        Continuity(), // a second writer\n        Probe("),
            LineOf("Continuity(), // a second writer"),
            Is("pipeline"),
            &[
                "Continuity writes `DensityRate`",
                "which Forces (line",
                "remove one of them",
            ],
        ),
        case(
            "reader before its writer",
            dam("        NeighbourGrid(),\n", "").replacen(
                "        Probe(",
                "        NeighbourGrid(),\n        Probe(",
                1,
            ),
            LineOf("Reinitialise("),
            Is("pipeline"),
            &[
                "Reinitialise reads `Neighbours`, which no stage before it writes",
                "NeighbourGrid (line",
                "put NeighbourGrid before Reinitialise",
            ],
        ),
        case(
            "reader without a writer",
            dam("        NeighbourGrid(),\n", ""),
            LineOf("Reinitialise("),
            Is("pipeline"),
            &[
                "Reinitialise reads `Neighbours`",
                "no stage of the pipeline writes it",
            ],
        ),
        case(
            "nothing advances the clock",
            dam("        Integrate(courant: 0.25),\n", ""),
            LineOf("pipeline:"),
            Is("pipeline"),
            &["no stage advances the clock", "add Integrate()"],
        ),
        case(
            "tilt out of range",
            dam_value("tank", "(width: 3.22, height: 1.8, motion: (tilt: 95.0))"),
            LineOf("tank:"),
            Is("tilt"),
            &["95", "accepted: degrees between -90 and 90"],
        ),
        case(
            "roll period not positive",
            dam_value(
                "tank",
                "(width: 3.22, height: 1.8, motion: (roll: (amplitude: 4.0, period: -1.0)))",
            ),
            LineOf("tank:"),
            Is("period"),
            &["-1", "accepted: a finite number > 0"],
        ),
        // Found by the fuzzer's runs (issue 28): each loaded, and the first run's
        // pressures or the tank's acceleration went to NaN or infinity.
        case(
            "roll period below a microsecond",
            dam_value(
                "tank",
                "(width: 3.22, height: 1.8, motion: (roll: (amplitude: 4.0, period: 1e-320)))",
            ),
            LineOf("tank:"),
            Is("roll"),
            &["period 1e-320 s is out of range", "seconds from 1e-6"],
        ),
        case(
            "ramp below a microsecond",
            dam_value(
                "tank",
                "(width: 3.22, height: 1.8, motion: (roll: (amplitude: 4.0, period: 1.0), ramp: 1e-320))",
            ),
            LineOf("tank:"),
            Is("ramp"),
            &["1e-320 is out of range", "0 (no ramp) or seconds from 1e-6"],
        ),
        case(
            "gamma near the largest float",
            dam("gamma: 7.0,", "gamma: 1e308,"),
            LineOf("gamma: 1e308"),
            Is("gamma"),
            &["1e308 is out of range", "1 to 20"],
        ),
        case(
            "a stiffness that overflows",
            dam("density: 1000.0,", "density: 1e307,"),
            LineOf("fluid:"),
            Is("sound_speed"),
            &["Tait stiffness", "inf Pa", "finite, positive stiffness"],
        ),
        case(
            "motion series file missing",
            dam_value(
                "tank",
                "(width: 3.22, height: 1.8, motion: (series: \"no_such_roll.csv\"))",
            ),
            LineOf("tank:"),
            Is("series"),
            &["no_such_roll.csv", "cannot read motion series"],
        ),
        case(
            "series and harmonics together",
            dam_value(
                "tank",
                "(width: 3.22, height: 1.8, motion: (series: \"a.csv\", roll: (amplitude: 1.0, period: 1.0)))",
            ),
            LineOf("tank:"),
            Is("series"),
            &["either the series or the harmonics"],
        ),
        case(
            "pitch in 2D",
            dam_value(
                "tank",
                "(width: 3.22, height: 1.8, motion: (pitch: (amplitude: 2.0, period: 1.0)))",
            ),
            LineOf("tank:"),
            Is("pitch"),
            &["x axis", "dimensions: 3", "roll"],
        ),
        case(
            "sweep without roll",
            dam_value("pipeline", "[]").replacen(
                "pipeline: [],",
                "sweep: (omega: [2.0]),\n    pipeline: [Integrate()],",
                1,
            ),
            LineOf("sweep:"),
            Is("sweep"),
            &["give the tank a `motion: (roll:"],
        ),
        case(
            "empty file",
            String::new(),
            LastLine,
            AbsentOr(&[]),
            &["Expected opening `(`", "Scenario"],
        ),
    ];
    all.extend(super::set_cases::set_cases());
    all
}
