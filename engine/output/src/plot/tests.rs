use super::*;
use std::fs;

pub fn test_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sph_core_{name}_{}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(&dir).unwrap();
    dir
}

/// Decodes `path`, asserting it is a PNG of the given size with something drawn on
/// its white background.
pub fn assert_png(path: &Path, size: (u32, u32)) -> image::RgbImage {
    let bytes = fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}", path.display());
    let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8();
    assert_eq!(img.dimensions(), size, "{}", path.display());
    let drawn = img.pixels().filter(|p| p.0 != [255, 255, 255]).count();
    assert!(drawn > 0, "{}: blank picture", path.display());
    img
}

/// The pixels of exactly `colour` inside `frame`'s plotting area, as (column, row).
pub fn pixels_of(img: &image::RgbImage, frame: &Frame, colour: RGBColor) -> Vec<(i32, i32)> {
    let mut out = Vec::new();
    for x in frame.left..=frame.right {
        for y in frame.top..=frame.bottom {
            if img.get_pixel(x as u32, y as u32).0 == [colour.0, colour.1, colour.2] {
                out.push((x, y));
            }
        }
    }
    out
}

fn only_file(dir: &Path) -> Vec<String> {
    let mut v: Vec<_> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    v.sort();
    v
}

#[test]
fn plots_several_series() {
    let dir = test_dir("plot");
    let n = 200;
    let t: Vec<f64> = (0..n).map(|i| f64::from(i) * 0.01).collect();
    let series = [
        Series {
            name: "kinetic energy".into(),
            points: t.iter().map(|&t| (t, 1000.0 * (-t).exp())).collect(),
            style: Style::Line,
        },
        Series {
            name: "reference".into(),
            points: t
                .iter()
                .step_by(10)
                .map(|&t| (t, 1000.0 * (-t).exp() + 30.0))
                .collect(),
            style: Style::Points,
        },
        Series {
            name: "with gap".into(),
            points: t
                .iter()
                .map(|&t| {
                    (
                        t,
                        if (0.8..1.0).contains(&t) {
                            f64::NAN
                        } else {
                            500.0 + 200.0 * t
                        },
                    )
                })
                .collect(),
            style: Style::Line,
        },
    ];
    let path = dir.join("energy.png");
    let frame = draw_series_plot(&path, "dam_break: energy", "t [s]", "E [J]", &series).unwrap();
    let img = assert_png(&path, PLOT_SIZE);
    // Every series is drawn in the plotting area, in its colour.
    for (i, s) in series.iter().enumerate() {
        let n = pixels_of(&img, &frame, PALETTE[i]).len();
        assert!(n > 100, "series `{}`: {n} pixels of its colour", s.name);
    }
    // The gap in the third series is left blank: no green between t = 0.8 and 1.0
    // (0.81 to 0.99, clear of the line's last and first columns).
    let gap = (frame.column(0.81).ceil() as i32)..=(frame.column(0.99).floor() as i32);
    assert!(pixels_of(&img, &frame, PALETTE[2])
        .iter()
        .all(|p| !gap.contains(&p.0)));
    assert_eq!(only_file(&dir), ["energy.png"]);
    if std::env::var_os("SPH_KEEP_TEST_OUTPUT").is_none() {
        fs::remove_dir_all(&dir).unwrap();
    }
}

/// Reads the drawn line of colour `colour` back: per pixel column, the top and
/// bottom row holding that colour.
fn drawn_columns(img: &image::RgbImage, frame: &Frame, colour: RGBColor) -> Vec<(i32, i32, i32)> {
    let mut columns = std::collections::BTreeMap::<i32, (i32, i32)>::new();
    for (x, y) in pixels_of(img, frame, colour) {
        let e = columns.entry(x).or_insert((y, y));
        *e = (e.0.min(y), e.1.max(y));
    }
    columns.into_iter().map(|(x, (t, b))| (x, t, b)).collect()
}

/// A long noisy series with one spike and one dip of known size (the sloshing
/// probes' case): the drawn line reaches the spike's and the dip's values at their
/// times, to within a pixel, stays inside the plotting area, has no gaps, and passes
/// through every sample's pixel.
#[test]
fn long_series_are_drawn_with_their_true_extremes() {
    let dir = test_dir("plot_spikes");
    let n = 100_000;
    let (spike_at, spike) = (61_803, 97_500.0);
    let (dip_at, dip) = (23_456, -140.0);
    let mut seed = 12_345u64;
    let mut noise = || {
        seed = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let points: Vec<(f64, f64)> = (0..n)
        .map(|i| {
            let t = f64::from(i) * 1.6295e-4;
            let y = match i {
                _ if i == spike_at => spike,
                _ if i == dip_at => dip,
                // Hydrostatic-like base with noise and, every 10,000 samples, a
                // burst of impacts up to 60 kPa.
                _ if i % 10_000 < 40 => 1000.0 + 60_000.0 * noise(),
                _ => 1000.0 + 300.0 * (t * 4.0).sin() + 200.0 * noise(),
            };
            (t, y)
        })
        .collect();
    let (data_lo, data_hi) = (dip, spike);
    let series = [Series {
        name: "S1.shepard".into(),
        points: points.clone(),
        style: Style::Line,
    }];
    let path = dir.join("spikes.png");
    let f = draw_series_plot(&path, "spikes", "time [s]", "pressure [Pa]", &series).unwrap();
    let img = assert_png(&path, PLOT_SIZE);

    // The axes cover the data's true extremes.
    let t_end = points.last().unwrap().0;
    assert!(f.x.0 <= 0.0 && f.x.1 >= t_end, "{f:?}");
    assert!(f.y.0 < data_lo && f.y.1 > data_hi, "{f:?}");

    let value_of_row =
        |r: i32| f.y.0 + f64::from(f.bottom - r) / f64::from(f.bottom - f.top) * (f.y.1 - f.y.0);
    let time_of_column =
        |c: i32| f.x.0 + f64::from(c - f.left) / f64::from(f.right - f.left) * (f.x.1 - f.x.0);
    let value_px = (f.y.1 - f.y.0) / f64::from(f.bottom - f.top);
    let time_px = (f.x.1 - f.x.0) / f64::from(f.right - f.left);

    let line = PALETTE[0];
    let columns = drawn_columns(&img, &f, line);
    let top = columns.iter().map(|c| c.1).min().unwrap();
    let bottom = columns.iter().map(|c| c.2).max().unwrap();
    let drawn_max = value_of_row(top);
    let drawn_min = value_of_row(bottom);
    assert!(
        (drawn_max - data_hi).abs() <= value_px,
        "drawn max {drawn_max:.0} Pa, data max {data_hi} Pa (one pixel = {value_px:.0} Pa)"
    );
    assert!(
        (drawn_min - data_lo).abs() <= value_px,
        "drawn min {drawn_min:.0} Pa, data min {data_lo} Pa (one pixel = {value_px:.0} Pa)"
    );
    // The spike's column (the first reaching the top row) is at its time.
    let spike_column = columns.iter().find(|c| c.1 == top).unwrap().0;
    let (t_spike, t_drawn) = (points[spike_at as usize].0, time_of_column(spike_column));
    assert!(
        (t_drawn - t_spike).abs() <= time_px,
        "spike drawn at t = {t_drawn:.4} s, data at {t_spike:.4} s (one pixel = {time_px:.4} s)"
    );
    let dip_column = columns.iter().find(|c| c.2 == bottom).unwrap().0;
    let (t_dip, t_drawn) = (points[dip_at as usize].0, time_of_column(dip_column));
    assert!(
        (t_drawn - t_dip).abs() <= time_px,
        "dip drawn at t = {t_drawn:.4} s, data at {t_dip:.4} s"
    );

    // One connected line: every column from the first sample's to the last's.
    let (first, last) = (f.column(0.0).round() as i32, f.column(t_end).round() as i32);
    let drawn: std::collections::BTreeSet<i32> = columns.iter().map(|c| c.0).collect();
    let missing: Vec<i32> = (first..=last).filter(|c| !drawn.contains(c)).collect();
    assert!(missing.is_empty(), "columns without the line: {missing:?}");
    // Every sample's own pixel is on the line.
    let on_line = |&(t, y): &(f64, f64)| {
        let (c, r) = (f.column(t).round(), f.row(y).round());
        img.get_pixel(c as u32, r as u32).0 == [line.0, line.1, line.2]
    };
    let off: Vec<_> = points.iter().filter(|p| !on_line(p)).take(5).collect();
    assert!(off.is_empty(), "samples off the drawn line: {off:?}");
    if std::env::var_os("SPH_KEEP_TEST_OUTPUT").is_none() {
        fs::remove_dir_all(&dir).unwrap();
    }
}

/// A few samples far apart: the segments between them are drawn (connected, at
/// most a pixel's step between neighbouring columns) and no higher or lower than
/// their end points.
#[test]
fn sparse_series_are_connected_and_bounded_by_their_samples() {
    let dir = test_dir("plot_sparse");
    let points = vec![
        (0.0, 0.0),
        (1.0, 10.0),
        (1.5, -3.0),
        (4.0, 2.0),
        (4.01, 9.0),
    ];
    let series = [Series {
        name: "zigzag".into(),
        points: points.clone(),
        style: Style::Line,
    }];
    let path = dir.join("sparse.png");
    let f = draw_series_plot(&path, "sparse", "x", "y", &series).unwrap();
    let img = assert_png(&path, PLOT_SIZE);
    let columns = drawn_columns(&img, &f, PALETTE[0]);
    for w in columns.windows(2) {
        let ((c0, t0, b0), (c1, t1, b1)) = (w[0], w[1]);
        assert_eq!(c1, c0 + 1, "gap between columns {c0} and {c1}");
        // Neighbouring spans touch or overlap (8-connected).
        assert!(t1 <= b0 + 1 && t0 <= b1 + 1, "{:?} {:?}", w[0], w[1]);
    }
    let top = columns.iter().map(|c| c.1).min().unwrap();
    let bottom = columns.iter().map(|c| c.2).max().unwrap();
    assert_eq!(top, f.row(10.0).round() as i32);
    assert_eq!(bottom, f.row(-3.0).round() as i32);
    fs::remove_dir_all(&dir).unwrap();
}

/// Point markers at the data's extremes are drawn whole, inside the plotting area
/// (the x axis is padded for point series), while a line's x axis ends at its data.
#[test]
fn markers_at_the_extremes_are_drawn_whole() {
    let dir = test_dir("plot_markers");
    let series = [
        Series {
            name: "cases".into(),
            points: vec![(1.0, 0.27), (4.4, 0.267), (17.7, 0.27)],
            style: Style::Points,
        },
        Series {
            name: "front".into(),
            points: vec![(1.0, 0.27), (4.4, 0.267)],
            style: Style::Line,
        },
    ];
    let path = dir.join("markers.png");
    let f = draw_series_plot(&path, "markers", "wall time [s]", "error", &series).unwrap();
    let img = assert_png(&path, PLOT_SIZE);
    let columns: Vec<i32> = pixels_of(&img, &f, PALETTE[0])
        .into_iter()
        .map(|p| p.0)
        .collect();
    for x in [1.0, 17.7] {
        let c = f.column(x).round() as i32;
        // The marker's radius is 3 px: columns c - 2 and c + 2 both drawn.
        for d in [-2, 2] {
            assert!(
                columns.contains(&(c + d)),
                "marker at x = {x}: column {} not drawn (frame {:?})",
                c + d,
                f.x
            );
        }
    }
    let line = [Series {
        name: "line".into(),
        points: vec![(1.0, 0.0), (17.7, 1.0)],
        style: Style::Line,
    }];
    let f = draw_series_plot(&dir.join("line.png"), "line", "t", "y", &line).unwrap();
    assert_eq!(f.x, (1.0, 17.7));
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn degenerate_inputs_do_not_panic() {
    let dir = test_dir("plot_degenerate");
    let cases: Vec<Vec<Series>> = vec![
        vec![],
        vec![Series {
            name: "empty".into(),
            points: vec![],
            style: Style::Line,
        }],
        vec![Series {
            name: "one".into(),
            points: vec![(1.0, 2.0)],
            style: Style::Line,
        }],
        vec![Series {
            name: "constant".into(),
            points: (0..10).map(|i| (f64::from(i), 3.0)).collect(),
            style: Style::Points,
        }],
        vec![Series {
            name: "zeros".into(),
            points: vec![(0.0, 0.0), (0.0, 0.0)],
            style: Style::Line,
        }],
        vec![Series {
            name: "nan".into(),
            points: vec![
                (f64::NAN, 1.0),
                (1.0, f64::INFINITY),
                (f64::NEG_INFINITY, 0.0),
            ],
            style: Style::Line,
        }],
        vec![Series {
            name: "huge".into(),
            points: vec![(0.0, -f64::MAX), (1.0, f64::MAX), (2.0, 1e-300)],
            style: Style::Line,
        }],
    ];
    for (i, series) in cases.iter().enumerate() {
        let path = dir.join(format!("case{i}.png"));
        plot_series(&path, "degenerate", "x", "y", series).unwrap();
        assert_png(&path, PLOT_SIZE);
    }
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn missing_folder_error_names_the_file() {
    let path = std::env::temp_dir().join("sph_core_no_such_dir_plot/p.png");
    let err = plot_series(&path, "t", "x", "y", &[]).unwrap_err();
    assert!(err.to_string().contains("p.png"), "{err}");
}

#[test]
fn ranges_and_numbers() {
    assert_eq!(axis_range([].into_iter(), 0.1), (0.0, 1.0));
    assert_eq!(axis_range([2.0, 2.0].into_iter(), 0.1), (1.8, 2.2));
    assert_eq!(axis_range([0.0].into_iter(), 0.1), (-1.0, 1.0));
    assert_eq!(
        axis_range([0.0, 10.0, f64::NAN].into_iter(), 0.1),
        (-1.0, 11.0)
    );
    let (lo, hi) = axis_range([-f64::MAX, f64::MAX].into_iter(), 0.05);
    assert!(lo.is_finite() && hi.is_finite() && lo < hi);

    assert_eq!(format_number(0.5, 1.0), "0.5");
    assert_eq!(format_number(250.0, 1000.0), "250");
    assert_eq!(format_number(-1e-17, 1.0), "0");
    assert_eq!(format_number(-0.0001, 1.0), "0.0");
    assert_eq!(format_number(0.012, 0.02), "0.012");
    assert_eq!(format_number(250000.0, 1e6), "2.5e5");
    assert_eq!(format_number(2e-5, 1e-4), "2.0e-5");
}
