use super::*;

const SAMPLE: &str = r##"#![enable(implicit_some)]
// Dam break (2D), with ) ] } , in a comment.
Scenario(
    name: "dam \"break\", (v2) ]", /* tricky /* nested ) */ , ] */
    dt: 1e-4,
    gravity: (0.0, -9.81),
    marker: 'x',
    escaped: '\'',
    quote: ''',
    materials: { "water": (density: 1000.0), "oil": (density: 900.0) },
    pipeline: [
        NeighbourGrid(cell: 0.02),
        GhostWalls(),
        Density(),
        Eos(gamma: 7.0, c0: 20.0),
        Forces(viscosity: 0.01 // ), ]
        ),
        Integrate,
        Reinitialise(every: 20),
        Probe(path: r#"out/"probe", (1).csv"#, every: 10),
    ],
)
"##;

fn set(src: &str, args: &[&str]) -> Result<String, OverrideError> {
    let overrides: Vec<Override> = args.iter().map(|a| a.parse().unwrap()).collect();
    apply_overrides(src, &overrides)
}

/// Applies the overrides, checks the result is still RON, and returns it.
fn patched(src: &str, args: &[&str]) -> String {
    let out = set(src, args).unwrap_or_else(|e| panic!("{e}"));
    if let Err(e) = ron::from_str::<ron::Value>(&out) {
        panic!("patched text is not RON ({e}):\n{out}");
    }
    out
}

fn error(src: &str, args: &[&str]) -> String {
    set(src, args).expect_err("expected an error").to_string()
}

#[test]
fn sample_is_ron() {
    ron::from_str::<ron::Value>(SAMPLE).unwrap();
}

#[test]
fn parses_override_arguments() {
    let ov: Override = " pipeline.3.gamma = 7.5 ".parse().unwrap();
    assert_eq!(ov.path, ["pipeline", "3", "gamma"]);
    assert_eq!(ov.value, "7.5");
    assert!("dt".parse::<Override>().is_err());
    assert!("a..b=1".parse::<Override>().is_err());
    assert!("=1".parse::<Override>().is_err());
    let e = "dt=1, x: 2".parse::<Override>().unwrap_err().to_string();
    assert!(e.contains("not a single RON value"), "{e}");
    assert!("dt=(1".parse::<Override>().is_err());
}

#[test]
fn replaces_top_level_number() {
    let out = patched(SAMPLE, &["dt=2.5e-5"]);
    assert!(out.contains("dt: 2.5e-5,"));
    assert_eq!(out.len(), SAMPLE.len() + 2);
}

#[test]
fn replaces_nested_field_in_named_element() {
    let out = patched(
        SAMPLE,
        &[
            "pipeline.reinitialise.every=5",
            "pipeline.neighbour_grid.cell=0.1",
        ],
    );
    assert!(out.contains("Reinitialise(every: 5)"));
    assert!(out.contains("NeighbourGrid(cell: 0.1)"));
    let out = patched(SAMPLE, &["pipeline.forces.viscosity=0.5"]);
    assert!(out.contains("Forces(viscosity: 0.5 // ), ]"), "{out}");
}

#[test]
fn inserts_missing_field() {
    let out = patched(SAMPLE, &["pipeline.density.every=5", "pipeline.eos.b=3"]);
    assert!(out.contains("Density(every: 5, )"));
    assert!(out.contains("Eos(b: 3, gamma: 7.0"));
    let out = patched(SAMPLE, &["pipeline.integrate.scheme=Euler", "steps=10"]);
    assert!(out.contains("Integrate(scheme: Euler),"));
    assert!(out.contains("Scenario(steps: 10, "));
    let out = patched(SAMPLE, &["materials.mud=(density: 1500.0)"]);
    assert!(out.contains(r#"{"mud": (density: 1500.0),  "water""#));
    assert_eq!(patched("(/* empty */)", &["a=1"]), "(a: 1, /* empty */)");
}

#[test]
fn numeric_index_and_tuple() {
    let out = patched(
        SAMPLE,
        &[
            "pipeline.3.gamma=1.4",
            "gravity.1=-1.62",
            "pipeline.5=Integrate(dt: 1)",
        ],
    );
    assert!(out.contains("Eos(gamma: 1.4, c0"));
    assert!(out.contains("gravity: (0.0, -1.62)"));
    assert!(out.contains("Integrate(dt: 1),"));
    let out = patched(
        SAMPLE,
        &[
            "pipeline.ghost_walls=GhostWalls(layers: 3)",
            "materials.oil.density=800",
        ],
    );
    assert!(out.contains("GhostWalls(layers: 3),"));
    assert!(out.contains(r#""oil": (density: 800)"#));
}

#[test]
fn comments_and_strings_do_not_confuse() {
    let out = patched(
        SAMPLE,
        &["name=\"x\"", "pipeline.probe.every=1", "marker='y'"],
    );
    assert!(out.contains(r#"name: "x", /* tricky"#));
    assert!(out.contains(r##"Probe(path: r#"out/"probe", (1).csv"#, every: 1)"##));
    assert!(out.contains("marker: 'y',"));
    let out = patched(SAMPLE, &["escaped='z'", "pipeline.probe.path=\"p.csv\""]);
    assert!(out.contains("escaped: 'z',"));
    assert!(out.contains(r#"Probe(path: "p.csv", every"#));
}

#[test]
fn unknown_names_suggest_nearest() {
    let e = error(SAMPLE, &["pipeline.reinitialize.every=5"]);
    assert_eq!(
            e,
            "--set pipeline.reinitialize.every=5: no element `reinitialize` in `pipeline`; elements are: \
             neighbour_grid, ghost_walls, density, eos, forces, integrate, reinitialise, probe; \
             did you mean `reinitialise`?"
        );
    let e = error(SAMPLE, &["pipelin.density.every=5"]);
    assert!(
        e.contains("no field `pipelin` in the scenario; fields are: name, dt,"),
        "{e}"
    );
    assert!(e.contains("; did you mean `pipeline`?"), "{e}");
    let e = error(SAMPLE, &["pipeline.eos.gama.x=1"]);
    assert!(
        e.contains(
            "no field `gama` in `pipeline.eos`; fields are: gamma, c0; did you mean `gamma`?"
        ),
        "{e}"
    );
    let e = error(SAMPLE, &["pipeline.9.every=1"]);
    assert!(
        e.contains("index 9 is out of range: `pipeline` has 8 elements"),
        "{e}"
    );
    let e = error(SAMPLE, &["dt.x=1"]);
    assert!(e.contains("`dt` is `1e-4`, not a struct"), "{e}");
    let e = error(SAMPLE, &["gravity.z=1"]);
    assert!(e.contains("fields are: 0, 1"), "{e}");
}

#[test]
fn patches_record_where_each_override_landed() {
    let args: Vec<Override> = [
        "pipeline.reinitialise.every=5",
        "pipeline.eos.b=3",
        "dt=2.5e-5",
        "pipeline.integrate.scheme=Euler",
    ]
    .iter()
    .map(|a| a.parse().unwrap())
    .collect();
    let (text, patches) = apply_overrides_traced(SAMPLE, &args).unwrap();
    let written: Vec<&str> = patches.iter().map(|p| &text[p.span.clone()]).collect();
    assert_eq!(
        written,
        ["5", "b: 3, ", "2.5e-5", "Integrate(scheme: Euler)"]
    );
    let eos = &patches[1];
    assert_eq!(eos.field(), Some("b"));
    let holders: Vec<(&str, &str)> = eos
        .holders
        .iter()
        .map(|(s, r)| (s.as_str(), &text[r.clone()]))
        .collect();
    assert_eq!(holders[1].0, "eos");
    assert!(
        holders[1].1.starts_with("[\n        NeighbourGrid"),
        "{holders:?}"
    );
    assert_eq!(holders[2], ("b", "Eos(b: 3, gamma: 7.0, c0: 20.0)"));
    // Text outside the patches maps back to the file: `gamma` after the insertion.
    let gamma = text.find("gamma: 7.0").unwrap();
    assert_eq!(
        source_offset(gamma, &patches),
        SAMPLE.find("gamma: 7.0").unwrap()
    );
    let probe = text.find("Probe(").unwrap();
    assert_eq!(
        source_offset(probe, &patches),
        SAMPLE.find("Probe(").unwrap()
    );
}

#[test]
fn overwritten_patches_are_dropped_and_holders_grow() {
    let args: Vec<Override> = [
        "pipeline.eos.gamma=1.4",
        "pipeline.eos=Eos(c0: 30.0)",
        "pipeline.eos.c0=40.0",
        "gravity.1=-1.62",
    ]
    .iter()
    .map(|a| a.parse().unwrap())
    .collect();
    let (text, patches) = apply_overrides_traced(SAMPLE, &args).unwrap();
    let written: Vec<(&str, &str)> = patches
        .iter()
        .map(|p| (p.raw.as_str(), &text[p.span.clone()]))
        .collect();
    // The first is overwritten by the second; the third lies inside the second.
    assert_eq!(
        written,
        [
            ("pipeline.eos=Eos(c0: 30.0)", "Eos(c0: 40.0)"),
            ("pipeline.eos.c0=40.0", "40.0"),
            ("gravity.1=-1.62", "-1.62"),
        ]
    );
    assert_eq!(patches[2].field(), Some("gravity"));
    let forces = text.find("Forces(").unwrap();
    assert_eq!(
        source_offset(forces, &patches),
        SAMPLE.find("Forces(").unwrap()
    );
}

#[test]
fn ambiguous_element_suggests_index() {
    let src = "(pipeline: [Density(every: 1), Eos(), Density()])";
    let e = error(src, &["pipeline.density.every=5"]);
    assert!(
        e.contains("`density` matches elements 0, 2 of `pipeline`"),
        "{e}"
    );
    assert!(e.contains("--set pipeline.0.every=5"), "{e}");
    assert!(patched(src, &["pipeline.2.every=5"]).contains("Density(every: 5, )"));
}

#[test]
fn malformed_input_errors() {
    for src in [
        "Scenario(dt: 1",
        "Scenario(dt: 1))",
        "Scenario(a: [1, 2)",
        "(a: \"open)",
        "(a: 1) /* open",
        "[1, 2]",
        "",
        "(a: r#\"x\")",
        "(a: 'x)",
        "(a: 1 2)",
        "(a: {1 2})",
        "#! (a: 1)",
    ] {
        match set(src, &["a=2"]) {
            Err(OverrideError::Malformed { .. }) => {}
            other => panic!("{src:?} gave {other:?}"),
        }
    }
    let e = error("Scenario(\n  dt: 1,\n  x: ]\n)", &["dt=2"]);
    assert!(
        e.contains("malformed at 3:6: expected a value, found `]`"),
        "{e}"
    );
    let deep = format!("(a: {}{})", "[".repeat(10_000), "]".repeat(10_000));
    assert!(set(&deep, &["a=1"]).is_err());
}

#[test]
fn random_mutations_never_panic() {
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut rand = |n: usize| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % n as u64) as usize
    };
    let pieces = [
        "(", ")", "[", "]", "{", "}", ",", ":", "\"", "'", "/*", "*/", "//", "\n", "r#\"", "\\",
        "#", "é", "x",
    ];
    let args: Vec<Override> = [
        "pipeline.density.every=5",
        "dt=1",
        "pipeline.3.gamma=2",
        "materials.water.density=1",
        "gravity.0=1",
    ]
    .iter()
    .map(|a| a.parse().unwrap())
    .collect();
    for round in 0..600 {
        let mut text = SAMPLE.to_owned();
        for _ in 0..1 + round % 4 {
            let mut at = rand(text.len() + 1);
            while !text.is_char_boundary(at) {
                at -= 1;
            }
            match rand(3) {
                0 => text.truncate(at),
                1 => text.insert_str(at, pieces[rand(pieces.len())]),
                _ => {
                    let end = (at + 1..=text.len())
                        .find(|&e| text.is_char_boundary(e))
                        .unwrap_or(at);
                    text.replace_range(at..end, "");
                }
            }
        }
        if let Ok((out, patches)) = apply_overrides_traced(&text, &args[rand(args.len())..]) {
            for p in &patches {
                assert!(out.get(p.span.clone()).is_some(), "{p:?} in {out:?}");
                for (_, r) in &p.holders {
                    assert!(r.start <= p.span.start && p.span.end <= r.end, "{p:?}");
                }
            }
        }
    }
}
