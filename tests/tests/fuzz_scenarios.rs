//! Mutated scenario files never panic the loader: thousands of random edits of the
//! shipped scenarios (deleted, inserted and swapped characters and lines, numbers
//! replaced by edge values, truncation) each load or fail with an error that names a
//! place (line and column) or a field, and none that loads holds a NaN or an infinity. The default count keeps this test to a few
//! seconds; `SPH_FUZZ_CASES=200000 cargo test --release -p sph-tests --test
//! fuzz_scenarios -- --nocapture` runs a longer campaign.

use sph_scenario::scenario::non_finite_number;
use sph_scenario::Scenario;
use std::panic::{catch_unwind, AssertUnwindSafe};

const SHIPPED: [(&str, &str); 10] = [
    (
        "scenarios/sloshing_paper.ron",
        include_str!("../../scenarios/sloshing_paper.ron"),
    ),
    (
        "scenarios/dam_break_paper.ron",
        include_str!("../../scenarios/dam_break_paper.ron"),
    ),
    (
        "scenarios/dam_break.ron",
        include_str!("../../scenarios/dam_break.ron"),
    ),
    (
        "scenarios/hydrostatic.ron",
        include_str!("../../scenarios/hydrostatic.ron"),
    ),
    (
        "scenarios/sloshing.ron",
        include_str!("../../scenarios/sloshing.ron"),
    ),
    (
        "scenarios/sloshing_high.ron",
        include_str!("../../scenarios/sloshing_high.ron"),
    ),
    (
        "scenarios/anti_roll_tank.ron",
        include_str!("../../scenarios/anti_roll_tank.ron"),
    ),
    (
        "scenarios/wave_maker.ron",
        include_str!("../../scenarios/wave_maker.ron"),
    ),
    (
        "scenarios/wave_breaking.ron",
        include_str!("../../scenarios/wave_breaking.ron"),
    ),
    (
        "scenarios/eagre_wavemaker.ron",
        include_str!("../../scenarios/eagre_wavemaker.ron"),
    ),
];

/// A small deterministic generator (SplitMix64): the same cases on every run.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const EDGE_NUMBERS: [&str; 14] = [
    "0",
    "-1",
    "0.0",
    "-0.0",
    "1e308",
    "-1e308",
    "1e-320",
    "NaN",
    "inf",
    "-inf",
    "18446744073709551616",
    "99999999999",
    "1e9",
    "3",
];
const NOISE: &[u8] = b"()[]{},:;\"'/*\\ \n\tx_0.-+eE9";

/// One random edit of `text`, on character boundaries.
fn mutate(text: &str, rng: &mut Rng) -> String {
    let chars: Vec<char> = text.chars().collect();
    if chars.is_empty() {
        return String::from("(");
    }
    let at = rng.below(chars.len() + 1);
    match rng.below(8) {
        0 => {
            // Delete a run of characters.
            let len = 1 + rng.below(8);
            let end = (at + len).min(chars.len());
            chars[..at].iter().chain(&chars[end..]).collect()
        }
        1 => {
            let c = NOISE[rng.below(NOISE.len())] as char;
            chars[..at]
                .iter()
                .chain(std::iter::once(&c))
                .chain(&chars[at..])
                .collect()
        }
        2 => {
            // Replace a number with an edge value.
            let numbers: Vec<usize> = (1..chars.len())
                .filter(|&i| {
                    chars[i].is_ascii_digit()
                        && !chars[i - 1].is_ascii_alphanumeric()
                        && chars[i - 1] != '.'
                })
                .collect();
            let Some(&start) = numbers.get(rng.below(numbers.len())) else {
                return text.to_string();
            };
            let end = (start..chars.len())
                .find(|&i| !(chars[i].is_ascii_digit() || chars[i] == '.' || chars[i] == 'e'))
                .unwrap_or(chars.len());
            let edge = EDGE_NUMBERS[rng.below(EDGE_NUMBERS.len())];
            chars[..start].iter().collect::<String>()
                + edge
                + &chars[end..].iter().collect::<String>()
        }
        3 => chars[..at].iter().collect(),
        4 | 5 => {
            // Delete or duplicate a line.
            let lines: Vec<&str> = text.lines().collect();
            if lines.is_empty() {
                return text.to_string();
            }
            let k = rng.below(lines.len());
            let mut out: Vec<&str> = lines.clone();
            if rng.below(2) == 0 {
                out.remove(k);
            } else {
                out.insert(k, lines[k]);
            }
            out.join("\n")
        }
        6 => {
            // Swap two characters.
            let mut c = chars.clone();
            let b = rng.below(c.len());
            if at < c.len() && b < c.len() {
                c.swap(at, b);
            }
            c.into_iter().collect()
        }
        _ => {
            // Replace an identifier-like word with another word from the file.
            let words: Vec<&str> = text
                .split(|c: char| !(c.is_alphanumeric() || c == '_'))
                .filter(|w| w.len() > 2)
                .collect();
            if words.is_empty() {
                return text.to_string();
            }
            let (a, b) = (words[rng.below(words.len())], words[rng.below(words.len())]);
            text.replacen(a, b, 1)
        }
    }
}

#[test]
fn the_non_finite_check_finds_ron_numbers_not_names() {
    assert!(non_finite_number("(end_time: NaN, x: 1.0)"));
    assert!(non_finite_number("(gravity: (0.0, -inf))"));
    assert!(!non_finite_number(
        "(name: \"inf\", info: 2.0, width: 1e308)"
    ));
}

#[test]
fn mutated_scenarios_give_located_errors_never_panics() {
    let cases: usize = std::env::var("SPH_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20_000);
    let registry = sph_stages::standard_registry();
    let mut rng = Rng(0x5EED);
    let (mut loaded, mut refused) = (0usize, 0usize);
    let start = std::time::Instant::now();
    // Silence the default panic message; a panic is reported below with its input.
    std::panic::set_hook(Box::new(|_| {}));
    let mut problem = None;
    for n in 0..cases {
        let (file, base) = SHIPPED[n % SHIPPED.len()];
        let mut text = base.to_string();
        for _ in 0..1 + rng.below(3) {
            text = mutate(&text, &mut rng);
        }
        let result = catch_unwind(AssertUnwindSafe(|| {
            Scenario::from_str(&text, file, &[], &registry)
        }));
        match result {
            Err(_) => {
                problem = Some(format!(
                    "case {n}: the loader panicked on this input:\n{text}"
                ))
            }
            Ok(Ok(scenario)) => {
                loaded += 1;
                // A number the loader let through non-finite would reach the run: the
                // scenario as resolved (every default filled in) holds none.
                let resolved = scenario.resolved_ron();
                if non_finite_number(&resolved) {
                    problem = Some(format!(
                        "case {n}: loaded with a NaN or an infinity:\n{resolved}\ninput:\n{text}"
                    ));
                }
            }
            Ok(Err(e)) => {
                refused += 1;
                if !(e.line > 0 || e.field.is_some()) || !e.to_string().starts_with(file) {
                    problem = Some(format!(
                        "case {n}: error without a place or field: {e}\ninput:\n{text}"
                    ));
                }
            }
        }
        if problem.is_some() {
            break;
        }
    }
    let _ = std::panic::take_hook();
    if let Some(p) = problem {
        panic!("{p}");
    }
    eprintln!(
        "{cases} mutated scenarios in {:.1} s: {loaded} loaded, {refused} refused with a located error",
        start.elapsed().as_secs_f64()
    );
    assert!(
        refused > cases / 4,
        "too few mutations were errors: {refused}"
    );
}

/// Fluid particles a loaded scenario would spawn (the loader's own count).
fn fluid_count(s: &Scenario) -> f64 {
    s.spec
        .fluid_blocks
        .iter()
        .map(|b| {
            (b.size.0 .0 / s.spacing + 1e-9).floor() * (b.size.1 .0 / s.spacing + 1e-9).floor()
        })
        .sum()
}

/// Every mutant that loads is run for five steps on one thread: it runs them, or stops
/// with a diagnostic (a setup error, or an unstable step naming its stage), and never
/// panics; no CSV or JSON it writes holds a NaN or an infinity (a run that goes
/// non-finite must stop before writing one). Mutants of more than 20,000 fluid
/// particles are loaded but not run; 300 runs take about 12 s;
/// `SPH_FUZZ_RUNS=2000` runs more.
#[test]
fn loaded_mutants_run_five_steps_or_stop_with_a_diagnostic() {
    let runs: usize = std::env::var("SPH_FUZZ_RUNS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(300);
    let registry = sph_stages::standard_registry();
    let mut rng = Rng(0xF00D);
    let (mut ran, mut stopped, mut refused, mut large) = (0usize, 0usize, 0usize, 0usize);
    let start = std::time::Instant::now();
    let mut n = 0usize;
    while ran + stopped + refused < runs {
        n += 1;
        assert!(n < 100 * runs.max(1), "too few mutants load");
        let (file, base) = SHIPPED[n % SHIPPED.len()];
        let mut text = base.to_string();
        for _ in 0..1 + rng.below(2) {
            text = mutate(&text, &mut rng);
        }
        let Ok(scenario) = Scenario::from_str(&text, file, &[], &registry) else {
            continue;
        };
        if fluid_count(&scenario) > 20_000.0 {
            large += 1;
            continue;
        }
        let out = sph_tests::support::temp_out("fuzz_run");
        let opts = sph_run::runner::RunOptions {
            max_steps: Some(5),
            ..sph_run::runner::RunOptions::quiet(&out, 1)
        };
        let result = catch_unwind(AssertUnwindSafe(|| {
            sph_run::runner::run_keeping_state(scenario, &opts)
        }));
        let fail = |why: String| {
            let changed: Vec<&str> = text.lines().filter(|l| !base.contains(*l)).collect();
            panic!(
                "mutant {n} of {file}: {why}\nlines not in the file:\n{}",
                changed.join("\n")
            );
        };
        match result {
            Err(_) => fail("the run panicked".into()),
            Ok(Ok((summary, _))) => {
                ran += 1;
                if !(summary.status.starts_with("stopped after 5 steps")
                    || summary.status == "completed")
                {
                    fail(format!("status {}", summary.status));
                }
            }
            Ok(Err(e)) => {
                let shown = e.to_string();
                match e {
                    sph_run::runner::RunError::Setup(_) => refused += 1,
                    sph_run::runner::RunError::Step { .. } => stopped += 1,
                    _ => fail(format!(
                        "stopped without a step or setup diagnostic: {shown}"
                    )),
                }
                if shown.trim().is_empty() {
                    fail("an empty error".into());
                }
            }
        }
        for entry in std::fs::read_dir(&out).into_iter().flatten().flatten() {
            let path = entry.path();
            let text_file = path.extension().is_some_and(|e| e == "csv" || e == "json");
            if text_file {
                // summary.json's status quotes a stopped run's diagnostic, which may
                // name the NaN it stopped on; the numbers must hold none.
                let written: String = std::fs::read_to_string(&path)
                    .unwrap_or_default()
                    .lines()
                    .filter(|l| !l.trim_start().starts_with("\"status\""))
                    .collect::<Vec<_>>()
                    .join("\n");
                let bad = written
                    .split(|c: char| !(c.is_alphanumeric() || c == '-'))
                    .any(|w| {
                        matches!(
                            w.to_ascii_lowercase().trim_start_matches('-'),
                            "nan" | "inf" | "infinity"
                        )
                    });
                if bad {
                    fail(format!("{} holds a NaN or an infinity", path.display()));
                }
            }
        }
        let _ = std::fs::remove_dir_all(&out);
    }
    eprintln!(
        "{} loaded mutants in {:.1} s: {ran} ran five steps, {stopped} stopped with a step diagnostic, {refused} refused at setup; {large} larger than 20,000 particles not run",
        ran + stopped + refused,
        start.elapsed().as_secs_f64()
    );
    assert!(ran > runs / 2, "only {ran} of {runs} mutants ran");
}
