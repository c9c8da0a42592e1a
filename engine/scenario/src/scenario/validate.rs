//! Validation of a parsed scenario: every value in range, the geometry consistent, the
//! pipeline's contracts met, with each error placed at its field.

use super::*;

/// Checks that need more than one field, and derives ds, h and c_0.
pub(crate) fn validate(
    spec: ScenarioSpec,
    at: &Locator,
    source: PathBuf,
) -> Result<Scenario, LoadError> {
    let first = spec.fluid_blocks.first().ok_or_else(|| {
        at.field(
            "fluid_blocks",
            if dim::DIM == 2 {
                "no fluid: give at least one block `(min: (x, y), size: (w, h))`".into()
            } else {
                "no fluid: give at least one block `(min: (x, y, z), size: (w, h, b))`".into()
            },
        )
    })?;
    let spacing = match spec.resolution {
        Resolution::Spacing(ds) => ds.0,
        Resolution::ParticlesAcross(n) if n >= 2 => first.size.0 .0 / n as f64,
        Resolution::ParticlesAcross(n) => {
            return Err(at.field(
                "resolution",
                format!("ParticlesAcross({n}) is out of range; accepted: 2 or more"),
            ))
        }
    };
    let count: f64 = spec
        .fluid_blocks
        .iter()
        .map(|b| {
            extent(&b.size)
                .to_array()
                .iter()
                .map(|l| (l / spacing + 1e-9).floor())
                .product::<f64>()
        })
        .sum();
    if count > MAX_PARTICLES {
        return Err(at.field(
            "resolution",
            format!("{count:.0} fluid particles would not fit; accepted: at most {MAX_PARTICLES:.0} (use a coarser resolution)"),
        ));
    }
    if count < 1.0 {
        return Err(at.field(
            "resolution",
            format!("spacing {spacing} m leaves the fluid blocks empty; use a finer resolution"),
        ));
    }
    let gravity = Vector::from(spec.fluid.gravity);
    // Where the errors that gravity causes point.
    let gravity_place = at
        .doc
        .key(&["fluid", "gravity"])
        .or_else(|| at.doc.key(&["fluid"]));
    if !gravity.is_finite() {
        return Err(at.error(
            "gravity",
            gravity_place,
            format!(
                "{} is out of range; accepted: {} finite numbers [m/s^2], e.g. {}",
                written(gravity),
                DIM_WORD,
                if dim::DIM == 2 {
                    "(0.0, -9.81)"
                } else {
                    "(0.0, -9.81, 0.0)"
                }
            ),
        ));
    }
    let g = gravity.length();
    let tallest = spec
        .fluid_blocks
        .iter()
        .map(|b| b.size.1 .0)
        .fold(0.0, f64::max);
    let sound_speed = match spec.fluid.sound_speed {
        Some(c) => c.0,
        None if g > 0.0 => 10.0 * (2.0 * g * tallest).sqrt(),
        None => {
            // The cause is the zero gravity: point there.
            return Err(at.error(
                "sound_speed",
                gravity_place,
                "cannot be derived without gravity; give `sound_speed: <m/s>`".into(),
            ));
        }
    };
    if !sound_speed.is_finite() {
        // Only a derived speed can be infinite (a given one is checked finite): the
        // gravity is too large for 10 sqrt(2 g H).
        return Err(at.error(
            "gravity",
            gravity_place,
            format!(
                "|g| = {g} m/s^2 gives the derived sound speed 10 sqrt(2 g H) = {sound_speed} m/s; give `sound_speed: <m/s>` or a smaller gravity"
            ),
        ));
    }
    // The Tait equation p = B ((rho/rho_0)^gamma - 1): gamma from the gas-like 1 to
    // beyond water's 7, and a stiffness B = rho_0 c_0^2 / gamma that is a number (a
    // density or sound speed near the largest float made it infinite, and the
    // pressures NaN).
    let fluid_place = |key: &str| {
        at.doc
            .key(&["fluid", key])
            .or_else(|| at.doc.key(&["fluid"]))
    };
    let gamma = spec.fluid.gamma.0;
    if !(1.0..=20.0).contains(&gamma) {
        return Err(at.error(
            "gamma",
            fluid_place("gamma"),
            format!(
                "{} is out of range; accepted: 1 to 20 (7 for water)",
                shown(gamma)
            ),
        ));
    }
    let stiffness = spec.fluid.density.0 * sound_speed * sound_speed / gamma;
    if !(stiffness.is_finite() && stiffness > 0.0) {
        return Err(at.error(
            "sound_speed",
            fluid_place("sound_speed"),
            format!(
                "density {} kg/m^3 and sound speed {} m/s give the Tait stiffness rho_0 c_0^2 / gamma = {} Pa; accepted: a finite, positive stiffness (water: 998 kg/m^3, 10-100 m/s)",
                shown(spec.fluid.density.0),
                shown(sound_speed),
                shown(stiffness)
            ),
        ));
    }
    let motion = match spec
        .tank
        .as_ref()
        .and_then(|t| t.motion.as_ref().map(|m| (t, m)))
    {
        Some((tank, m)) => Some(motion(tank, m, at, &source)?),
        None => None,
    };
    let piston = match &spec.piston {
        Some(p) => Some(piston(&spec, p, at, &source)?),
        None => None,
    };
    let scenario = Scenario {
        h: spec.h_over_dx.0 * spacing,
        spacing,
        sound_speed,
        motion,
        piston,
        spec,
        source,
    };
    let walls = scenario.walls();
    // The tank's walls come first, then the `walls` list's elements, the boxes' faces,
    // then the piston.
    let piston_walls = scenario.spec.piston.is_some() as usize;
    let box_walls: usize = (scenario.spec.boxes.iter())
        .map(|b| box_faces(b, scenario.spec.tank.as_ref()).len())
        .sum();
    let tank_walls = walls.len() - scenario.spec.walls.len() - box_walls - piston_walls;
    let wall_place = |i: usize, key: &str| {
        if i + piston_walls >= walls.len() && piston_walls > 0 {
            return at.doc.key(&["piston"]);
        }
        match i.checked_sub(tank_walls) {
            Some(k) if k < scenario.spec.walls.len() => at.element("walls", k, key),
            Some(_) => at.doc.key(&["boxes"]),
            None => at.doc.key(&["walls"]),
        }
    };
    for (i, w) in walls.iter().enumerate() {
        if w.length() == 0.0 {
            return Err(at.error(
                "walls",
                wall_place(i, "to"),
                format!("wall `{}` has zero length", w.name),
            ));
        }
        if walls[..i].iter().any(|o| o.name == w.name) {
            return Err(at.error(
                "walls",
                wall_place(i, "name"),
                format!("two walls are named `{}`; names must be unique", w.name),
            ));
        }
    }
    let blocks =
        (scenario.spec.fluid_blocks.iter().enumerate()).map(|(i, b)| ("fluid_blocks", i, b.min));
    let boxes = (scenario.spec.boxes.iter().enumerate()).map(|(i, b)| ("boxes", i, b.min));
    for (list, i, min) in blocks.chain(boxes) {
        if !Vector::from(min).is_finite() {
            return Err(at.error(
                "min",
                at.element(list, i, "min"),
                format!(
                    "{} is out of range; accepted: {DIM_WORD} finite coordinates [m]",
                    written(Vector::from(min))
                ),
            ));
        }
    }
    let lines: Vec<_> = walls
        .iter()
        .map(|w| sph_core::walls::WallLine::of(&w.at_rest()))
        .collect();
    let solids: Vec<(&str, Vector, Vector)> = (scenario.spec.boxes.iter())
        .map(|b| {
            (
                b.name.as_str(),
                Vector::from(b.min),
                Vector::from(b.min) + extent(&b.size),
            )
        })
        .collect();
    for (x, _, _) in scenario.initial_particles() {
        if let Some((name, _, _)) = solids
            .iter()
            .find(|(_, lo, hi)| x.cmpgt(*lo).all() && x.cmplt(*hi).all())
        {
            return Err(at.field(
                "fluid_blocks",
                format!("particle at {} m starts inside box `{name}`; blocks must lie outside the boxes", at4(x)),
            ));
        }
        // Walls bound the fluid on one side: behind at any depth is outside (a box's
        // faces are the box, checked above).
        let faces = tank_walls + scenario.spec.walls.len()..walls.len() - piston_walls;
        for (_, (w, line)) in
            (walls.iter().zip(&lines).enumerate()).filter(|(i, _)| !faces.contains(i))
        {
            if line.behind(x, f64::INFINITY) {
                return Err(at.field(
                    "fluid_blocks",
                    format!(
                        "particle at {} m starts outside wall `{}`; blocks must lie inside the walls",
                        at4(x),
                        w.name
                    ),
                ));
            }
        }
        if let Some(t) = &scenario.spec.tank {
            let outside = x.x < 0.0 || x.x > t.width.0 || x.y < 0.0 || x.y > t.height.0;
            #[cfg(feature = "dim3")]
            let outside = outside || x.z < 0.0 || x.z > t.breadth.0;
            if outside {
                return Err(at.field(
                    "fluid_blocks",
                    format!(
                        "particle at {} m lies outside the tank (0..{} m by 0..{} m{})",
                        at4(x),
                        t.width.0,
                        t.height.0,
                        if dim::DIM == 3 { " by its breadth" } else { "" }
                    ),
                ));
            }
        }
    }
    let names: Vec<&str> = walls.iter().map(|w| w.name.as_str()).collect();
    for (i, s) in scenario.spec.pressure_sensors.iter().enumerate() {
        let Some(w) = walls.iter().find(|w| w.name == s.wall) else {
            return Err(at.error(
                "pressure_sensors",
                at.element("pressure_sensors", i, "wall"),
                format!(
                    "sensor `{}` is on wall `{}`, which does not exist; walls are: {}",
                    s.name,
                    s.wall,
                    names.join(", ")
                ),
            ));
        };
        let p = Vector::from(s.at);
        // Written so that a NaN coordinate fails it.
        let on_wall =
            w.distance(p).abs() <= 1e-6 && w.abscissa(p) >= 0.0 && w.abscissa(p) <= w.length();
        #[cfg(feature = "dim3")]
        let on_wall = on_wall && {
            let (rest, t) = (w.at_rest(), w.at_rest().abscissa_across(p));
            t >= 0.0 && t <= rest.breadth()
        };
        if !on_wall {
            return Err(at.error(
                "pressure_sensors",
                at.element("pressure_sensors", i, "at"),
                format!(
                    "sensor `{}` at {} is not on wall `{}`; put `at` on the wall",
                    s.name,
                    written(p),
                    w.name
                ),
            ));
        }
    }
    for (i, g) in scenario.spec.wave_gauges.iter().enumerate() {
        #[cfg(not(feature = "dim3"))]
        let coordinates = [("x", g.x)];
        #[cfg(feature = "dim3")]
        let coordinates = [("x", g.x), ("z", g.z)];
        if let Some((key, v)) = coordinates.into_iter().find(|(_, v)| !v.is_finite()) {
            return Err(at.error(
                key,
                at.element("wave_gauges", i, key),
                format!(
                    "gauge `{}` at {key} = {v} is out of range; accepted: a finite coordinate [m]",
                    g.name
                ),
            ));
        }
    }
    if let Some(sweep) = &scenario.spec.sweep {
        let place = |key: &str| {
            at.doc
                .key(&["sweep", key])
                .or_else(|| at.doc.key(&["sweep"]))
        };
        let rolls = scenario
            .spec
            .tank
            .as_ref()
            .and_then(|t| t.motion.as_ref())
            .is_some_and(|m| m.roll.is_some());
        if !rolls {
            return Err(at.error(
                "sweep",
                place("omega"),
                "a sweep varies the roll frequency; give the tank a `motion: (roll: (amplitude: <deg>, period: <s>))`".into(),
            ));
        }
        if sweep.omega.is_empty() {
            return Err(at.error(
                "omega",
                place("omega"),
                "no frequencies; accepted: a list of roll frequencies [rad/s], e.g. [2.0, 2.5, 3.0]".into(),
            ));
        }
    }
    if let Some(r) = &scenario.spec.reference {
        let place = |key: &str| {
            at.doc
                .key(&["reference", key])
                .or_else(|| at.doc.key(&["reference"]))
        };
        let path = scenario.reference_file().unwrap_or_default();
        if !path.is_file() {
            return Err(at.error(
                "file",
                place("file"),
                format!(
                    "{} is not a file; accepted: a CSV file relative to the scenario",
                    path.display()
                ),
            ));
        }
        let (t0, t1) = r.window;
        if !(t0.is_finite() && t1.is_finite() && t0 < t1) {
            return Err(at.error(
                "window",
                place("window"),
                format!("({t0}, {t1}) is out of range; accepted: (t0, t1) with t0 < t1 [s]"),
            ));
        }
    }
    if scenario.spec.pipeline.is_empty() {
        return Err(at.field(
            "pipeline",
            "the pipeline is empty; list the stages to run".into(),
        ));
    }
    check_contracts(&scenario.spec.pipeline, at)?;
    // A number still NaN or infinite (a field without a range check of its own) is
    // refused at the first such token of the text, naming the field it stands in.
    if non_finite_number(&scenario.resolved_ron()) {
        // `NaN`, `inf`, or a literal beyond f64's range (1e309 reads as inf).
        let token = (0..at.doc.toks.len()).find(|&i| {
            let n = at.doc.name(i);
            matches!(n, "NaN" | "inf") || n.parse::<f64>().is_ok_and(|v| v.is_infinite())
        });
        let field = token
            .and_then(|i| at.doc.field_before(at.doc.toks[i].start))
            .unwrap_or_else(|| "fluid".into());
        let value = token.map_or("a non-finite number", |i| at.doc.name(i));
        return Err(at.error(
            &field,
            token,
            format!("{value} is out of range; accepted: a finite number"),
        ));
    }
    Ok(scenario)
}

/// The number of a point's coordinates, in words.
const DIM_WORD: &str = if dim::DIM == 2 { "two" } else { "three" };

/// `v` as a scenario writes it: `(x, y)` or `(x, y, z)`.
fn written(v: Vector) -> String {
    let parts: Vec<String> = v.to_array().iter().map(f64::to_string).collect();
    format!("({})", parts.join(", "))
}

/// `v` to four decimals, `(x, y)` or `(x, y, z)`.
fn at4(v: Vector) -> String {
    let parts: Vec<String> = v.to_array().iter().map(|c| format!("{c:.4}")).collect();
    format!("({})", parts.join(", "))
}

/// Whether RON `text` holds a NaN or an infinity as a number (the tokens `NaN` and
/// `inf` outside string quotes), e.g. [`Scenario::resolved_ron`]'s.
pub fn non_finite_number(text: &str) -> bool {
    let mut quoted = false;
    let mut token = String::new();
    for c in text.chars().chain(std::iter::once(' ')) {
        if c == '"' {
            quoted = !quoted;
        }
        if !quoted && (c.is_ascii_alphanumeric() || c == '_' || c == '.') {
            token.push(c);
            continue;
        }
        if token == "NaN" || token == "inf" {
            return true;
        }
        token.clear();
    }
    false
}

/// The declared contracts over the whole pipeline ([`sph_core::contract::check`]), as an
/// error placed at the offending stage's entry.
pub(crate) fn check_contracts(pipeline: &[PipelineEntry], at: &Locator) -> Result<(), LoadError> {
    let stages = pipeline.iter().map(|e| (&e.access, e.every));
    let Err(breach) = sph_core::contract::check(stages) else {
        return Ok(());
    };
    let entry = |k: usize| at.doc.element(&["pipeline"], k, "");
    let name = |k: usize| camel_case(&pipeline[k].name);
    let line = |k: usize| entry(k).map_or(0, |t| at.doc.line_col(t).0);
    let (k, field, message) = match breach {
        Breach::TwoWriters {
            quantity,
            first,
            second,
        } => (
            Some(second),
            "pipeline",
            format!(
                "{} writes `{}`, which {} (line {}) writes too; a quantity has one writer: remove one of them",
                name(second),
                quantity.name(),
                name(first),
                line(first)
            ),
        ),
        Breach::Unwritten {
            quantity,
            reader,
            update,
            later,
        } => {
            let how = if update { "updates" } else { "reads" };
            let fix = match later {
                Some(w) => format!(
                    "{} (line {}) writes it later in the step: put {} before {}",
                    name(w),
                    line(w),
                    name(w),
                    name(reader)
                ),
                None => format!(
                    "no stage of the pipeline writes it: add the stage that does before {}",
                    name(reader)
                ),
            };
            (
                Some(reader),
                "pipeline",
                format!(
                    "{} {how} `{}`, which no stage before it writes; {fix}",
                    name(reader),
                    quantity.name()
                ),
            )
        }
        Breach::ClockNotEveryStep { stage, every } => {
            let place = at.doc.element(&["pipeline"], stage, "every");
            return Err(at.error(
                "every",
                place.or_else(|| at.doc.key(&["pipeline"])),
                format!(
                    "{0}(every: {every}) would leave the clock standing on the other steps; accepted: {0} runs every step (every: 1), as the stage that advances the clock",
                    name(stage)
                ),
            ));
        }
        Breach::NoClock => (
            None,
            "pipeline",
            "no stage advances the clock (none declares it among its writes): add Integrate() to the pipeline".into(),
        ),
    };
    let place = k.and_then(entry).or_else(|| at.doc.key(&["pipeline"]));
    Err(at.error(field, place, message))
}

/// The piston's motion, checked against the tank.
pub(crate) fn piston(
    spec: &ScenarioSpec,
    p: &PistonSpec,
    at: &Locator,
    source: &Path,
) -> Result<Motion, LoadError> {
    let place = |key: &str| {
        at.doc
            .key(&["piston", key])
            .or_else(|| at.doc.key(&["piston"]))
    };
    let Some(tank) = &spec.tank else {
        return Err(at.error(
            "piston",
            place("x"),
            "a piston needs a `tank` (it stands on the tank's floor)".into(),
        ));
    };
    if tank.motion.is_some() {
        return Err(at.error(
            "piston",
            place("x"),
            "a piston in a moving tank is not supported; remove the tank's `motion` or the piston"
                .into(),
        ));
    }
    if !(p.x > 0.0 && p.x < tank.width.0) {
        return Err(at.error(
            "x",
            place("x"),
            format!(
                "{} is out of range; accepted: inside the tank, 0 < x < {} m",
                p.x, tank.width.0
            ),
        ));
    }
    if p.height.is_some_and(|h| h.0 > tank.height.0) {
        return Err(at.error(
            "height",
            place("height"),
            format!("accepted: up to the tank's height, {} m", tank.height.0),
        ));
    }
    let m = p
        .motion(source)
        .map_err(|(field, message)| at.error(field, place(field), message))?;
    // The paddle must stay in the tank: behind it is the tank's left wall.
    if m.max_offset() >= p.x {
        return Err(at.error(
            "stroke",
            place("stroke"),
            format!(
                "the paddle would travel {:.4} m back from x = {} m, through the tank's left wall; move `x` right or reduce the stroke",
                m.max_offset(),
                p.x
            ),
        ));
    }
    Ok(m)
}

/// The tank's motion, with its CSV series read (relative to the scenario file).
pub(crate) fn motion(
    tank: &TankSpec,
    m: &MotionSpec,
    at: &Locator,
    source: &Path,
) -> Result<Motion, LoadError> {
    let place = |key: &str| {
        at.doc
            .key(&["tank", "motion", key])
            .or_else(|| at.doc.key(&["tank", "motion"]))
    };
    if m.pitch.is_some() && dim::DIM == 2 {
        return Err(at.error(
            "pitch",
            place("pitch"),
            "a pitch turns the tank about its x axis, out of a 2D scene's plane; accepted in scenes with `dimensions: 3` (in 2D the tank rolls: `roll`)".into(),
        ));
    }
    let series = match &m.series {
        Some(file) => {
            if m.roll.is_some()
                || m.pitch.is_some()
                || m.sway.is_some()
                || m.heave.is_some()
                || m.tilt != 0.0
            {
                return Err(at.error(
                    "series",
                    place("series"),
                    "a motion series replaces tilt, roll, pitch, sway and heave; give either the series or the harmonics".into(),
                ));
            }
            let path = source.parent().unwrap_or(Path::new(".")).join(file);
            Some(
                MotionSeries::read(&path, false)
                    .map_err(|e| at.error("series", place("series"), e.to_string()))?,
            )
        }
        None => None,
    };
    if let Some(r) = m.ramp {
        if !(r == 0.0 || (r >= SHORTEST_TIME && r.is_finite())) {
            return Err(at.error(
                "ramp",
                place("ramp"),
                format!(
                    "{} is out of range; accepted: 0 (no ramp) or seconds from {}",
                    shown(r),
                    shown(SHORTEST_TIME)
                ),
            ));
        }
    }
    for (key, h) in [
        ("roll", &m.roll),
        ("pitch", &m.pitch),
        ("sway", &m.sway),
        ("heave", &m.heave),
    ] {
        if h.as_ref()
            .is_some_and(|h| !h.amplitude.is_finite() || !h.phase.is_finite())
        {
            return Err(at.error(
                key,
                place(key),
                "amplitude and phase must be finite numbers".into(),
            ));
        }
        if let Some(period) = h
            .as_ref()
            .map(|h| h.period.0)
            .filter(|p| *p < SHORTEST_TIME)
        {
            return Err(at.error(
                key,
                place(key),
                format!(
                    "period {} s is out of range; accepted: seconds from {}",
                    shown(period),
                    shown(SHORTEST_TIME)
                ),
            ));
        }
    }
    if !m.tilt.is_finite() || m.tilt.abs() >= 90.0 {
        return Err(at.error(
            "tilt",
            place("tilt"),
            format!(
                "{} is out of range; accepted: degrees between -90 and 90",
                m.tilt
            ),
        ));
    }
    Ok(Motion::new(m, tank.pivot(), series))
}
