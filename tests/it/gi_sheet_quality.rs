//! Geometry-image synthesis quality on flat sheets, scored as `texsyn score`
//! scores a user's run: relief_cow's settings (nops, synthesis seed 1) grown over a flat
//! sheet at density offset 0, 7×7 patches, at most 20,000 queries, score seed 0.
//!
//! A square sheet maps to the geometry image without distortion, so the surface metric is the
//! identity, every texel takes the middle scale and the relief image is the synthesizer's
//! plain output: this pins what the synthesizer itself reaches (measured with the default
//! appearance synthesizer: ratio 0.539, coverage 0.723, largest offset 0.027, gradient 1.011;
//! the template synthesizer 0.627 / 0.653 / 0.017 / 0.972; the quality bar is 0.6, 0.4, 0.15
//! and 0.8).
//!
//! A 60° rhombus maps to the square affinely (its equal sides put its corners on the square's
//! corners), so the metric is one constant stretch, λ = 1.316 along the square's diagonal
//! (surface lengths 1.73 : 1), without curl. There the template synthesizer loses most of its
//! quality: along the surface 0.838 / 0.247 / 0.001 / 0.501 (ratio / coverage / largest
//! offset / gradient); the appearance synthesizer keeps it (0.722 / 0.688 / 0.019 / 0.968).
//! Even a perfect result scores more than 0 there: the sample laid out verbatim under each
//! patch's map (the field's turn included) and read back scores 0.691 / 1.163 (ratio /
//! gradient; the surface row's `floor`, which `texsyn score` reports). So the rhombus is held
//! to the relief goal: a ratio within 0.15 of the floor (0.031 measured), coverage ≥ 0.4 and a
//! gradient ratio ≥ 0.8 × the floor's, with the bar's largest offset.

use crate::common;
use common::cli::{succeeded, texsyn};
use common::repo;
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A flat parallelogram sheet spanned by `e1` (along each row) and `e2` (across the rows), of
/// `quads × quads` quads (two triangles each, counter-clockwise about +z), as OBJ text. Its
/// first vertex is a corner, where the parameterization starts spreading the boundary over
/// the square's sides by arc length: with equal sides every corner of the sheet lands on a
/// corner of the square, and the map is affine.
fn sheet_obj(e1: [f64; 2], e2: [f64; 2], quads: usize) -> String {
    let mut s = String::new();
    for i in 0..=quads {
        for j in 0..=quads {
            let (a, b) = (j as f64 / quads as f64, i as f64 / quads as f64);
            let (x, y) = (a * e1[0] + b * e2[0], a * e1[1] + b * e2[1]);
            writeln!(s, "v {x} {y} 0").unwrap();
        }
    }
    for i in 0..quads {
        for j in 0..quads {
            let a = i * (quads + 1) + j + 1;
            let (b, c) = (a + 1, a + quads + 1);
            writeln!(s, "f {a} {b} {}\nf {a} {} {c}", c + 1, c + 1).unwrap();
        }
    }
    s
}

/// The relief_cow config on the sheet spanned by `e1` and `e2`, written into `dir`.
fn sheet_config(dir: &Path, e1: [f64; 2], e2: [f64; 2]) -> PathBuf {
    std::fs::write(dir.join("sheet.obj"), sheet_obj(e1, e2, 30)).unwrap();
    let nops = repo().join("configs/assets/nops.png");
    let text = std::fs::read_to_string(repo().join("configs/relief_cow.toml"))
        .unwrap()
        .replace("\"assets/cow.obj\"", "\"sheet.obj\"")
        .replace(
            "\"assets/nops.png\"",
            &format!("{:?}", nops.to_str().unwrap()),
        );
    assert!(
        text.contains("\"sheet.obj\"") && !text.contains("\"assets/nops.png\""),
        "relief_cow.toml names its mesh and sample"
    );
    let path = dir.join("sheet.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// `texsyn score` of the sheet at density offset 0: the grid row, the surface row and the
/// surface row's floor (what a perfect result scores there).
fn sheet_scores(e1: [f64; 2], e2: [f64; 2], sets: &[&str]) -> (Value, Value, Value) {
    let d = tempfile::tempdir().unwrap();
    let config = sheet_config(d.path(), e1, e2);
    let mut args = vec![
        "score",
        config.to_str().unwrap(),
        "--set",
        "field.density_offset=0",
        "--set",
        "reconstruct.preview_size=32",
        "--cache",
        "c",
        "--json",
    ];
    for s in sets {
        args.extend(["--set", s]);
    }
    let o = succeeded(texsyn(&args, d.path()));
    let v: Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    assert_eq!(v["patch"].as_u64(), Some(7), "{v}");
    let items = v["items"].as_array().expect("items");
    assert_eq!(items.len(), 2, "{v}");
    (
        items[0]["score"].clone(),
        items[1]["score"].clone(),
        items[1]["extra"]["floor"].clone(),
    )
}

fn measures(s: &Value) -> [f64; 4] {
    ["ratio", "coverage", "largest_offset", "gradient_ratio"]
        .map(|k| s[k].as_f64().unwrap_or_else(|| panic!("{k} in {s}")))
}

#[test]
fn an_undistorted_sheet_is_synthesized_near_the_quality_bar() {
    let (template, _, _) = sheet_scores(
        [1.0, 0.0],
        [0.0, 1.0],
        &["synthesize.algorithm=\"template\""],
    );
    let [ratio, coverage, offset, gradient] = measures(&template);
    assert!(
        ratio <= 0.7 && coverage >= 0.4 && offset <= 0.15 && gradient >= 0.8,
        "template: {template}"
    );
    let (grid, surface, floor) = sheet_scores([1.0, 0.0], [0.0, 1.0], &[]);
    let [ratio, coverage, offset, gradient] = measures(&grid);
    // The quality bar: coverage, largest offset and gradient; the ratio 0.6 for the default
    // appearance synthesizer (0.539 measured), within 0.1 of it for the template one (0.627),
    // so that a regression of either synthesizer's core shows here.
    assert!(ratio <= 0.6, "ratio {ratio}: {grid}");
    assert!(coverage >= 0.4, "coverage {coverage}: {grid}");
    assert!(offset <= 0.15, "largest offset {offset}: {grid}");
    assert!(gradient >= 0.8, "gradient ratio {gradient}: {grid}");
    assert_eq!(grid["queries"].as_u64(), Some(20_000), "{grid}");
    // Without distortion the surface row reads the grid as it is, and a perfect result would
    // be an exact copy.
    assert_eq!(floor["ratio"].as_f64(), Some(0.0), "{floor}");
    let s = measures(&surface);
    for (a, b) in s.iter().zip([ratio, coverage, offset, gradient]) {
        assert!(
            (a - b).abs() < 0.05,
            "surface {surface} against grid {grid}"
        );
    }
}

/// The rhombus's floor without the surface metric is 0 (the variants' texels land on the
/// grid and are read back on it), and with it lies near what `examples/frame_score_floor.rs`
/// finds for a whole grid laid out under a symmetric stretch of the same λ (0.674; the row's
/// map also turns by the field's angle, measured 0.691). This keeps the yardstick below,
/// which is relative to the floor, from loosening if the floor drifts up.
#[test]
fn the_rhombus_floor_comes_from_the_stretch_alone() {
    let e2 = [0.5, 0.75f64.sqrt()];
    let (_, _, flat) = sheet_scores([1.0, 0.0], e2, &["synthesize.anisotropic=false"]);
    assert_eq!(flat["ratio"].as_f64(), Some(0.0), "{flat}");
    let (_, _, stretched) = sheet_scores([1.0, 0.0], e2, &[]);
    let r = stretched["ratio"].as_f64().expect("a floor");
    assert!((r - 0.674).abs() < 0.1, "floor {stretched}");
    assert!(
        stretched["patches"].as_u64().unwrap_or(0) > 15_000,
        "{stretched}"
    );
}

/// On the rhombus the appearance synthesizer meets the relief goal along the surface: a ratio
/// within 0.15 of the floor (0.031 measured), coverage ≥ 0.4, gradient ratio ≥ 0.8 × the
/// floor's (0.968 against 0.93), and the bar's largest offset; the template synthesizer loses
/// coverage and gradient there (0.247 / 0.501 against 0.688 / 0.968).
#[test]
fn on_a_rhombus_the_appearance_synthesizer_comes_near_the_floor() {
    let e2 = [0.5, 0.75f64.sqrt()];
    let (_, surface, floor) = sheet_scores([1.0, 0.0], e2, &[]);
    let [ratio, coverage, offset, gradient] = measures(&surface);
    let floor_ratio = floor["ratio"].as_f64().expect("a floor");
    assert!(coverage >= 0.4, "coverage {coverage}: {surface}");
    assert!(offset <= 0.15, "largest offset {offset}: {surface}");
    let floor_gradient = floor["gradient_ratio"].as_f64().expect("a floor");
    assert!(
        gradient >= 0.8 * floor_gradient,
        "gradient ratio {gradient}: {surface}, floor {floor}"
    );
    assert!(ratio <= floor_ratio + 0.15, "{surface}, floor {floor}");
    let (_, template, _) = sheet_scores([1.0, 0.0], e2, &["synthesize.algorithm=\"template\""]);
    let [_, t_coverage, _, t_gradient] = measures(&template);
    assert!(
        t_coverage < coverage && t_gradient < gradient,
        "template {template} against appearance {surface}"
    );
}
