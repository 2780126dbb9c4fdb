//! Geometry-image synthesis quality on flat sheets (issue 12 §2), scored as `texsyn score`
//! scores a user's run: nops grown over a flat rectangle at density offset 0, 7×7 patches, at
//! most 20,000 queries, seed 0.
//!
//! A square sheet maps to the geometry image without distortion, so the surface metric is the
//! identity, every texel takes the middle scale and the relief image is the synthesizer's
//! plain output: this pins what the synthesizer itself reaches (measured 2026-12-03: ratio
//! 0.627, coverage 0.653, largest offset 0.017, gradient 0.972; the issue's bar is 0.6, 0.4,
//! 0.15 and 0.8).
//!
//! A 3:1 sheet stretches the grid uniformly (a grid step along the long side covers three
//! times the surface of one across), and there the default loses most of that quality: read
//! along the surface, 0.753 / 0.229 / 0.001 / 0.346 (ratio / coverage / largest offset /
//! gradient), the correction pass blurring what the scanline pass laid out noisily (0.0
//! correction passes: 1.042 / 0.298 / 0.001 / 0.810). Along a stretched map the surface row
//! cannot reach the issue's ratio of 0.6 by much even for a perfect result: the sample laid
//! out verbatim under this sheet's stretch (1.73) and read back scores 0.583 when copied texel
//! by texel (`examples/frame_score_floor.rs`). So that test asks for a ratio near that floor
//! (≤ 0.65) with the issue's coverage and gradient. Main does not meet it yet: it is ignored,
//! and run with `cargo test --release --test gi_sheet_quality -- --ignored`.

mod common;
use common::cli::{succeeded, texsyn};
use common::repo;
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A flat `width × height` sheet of `nx × ny` quads (two triangles each) as OBJ text.
fn sheet_obj(width: f64, height: f64, nx: usize, ny: usize) -> String {
    let mut s = String::new();
    for i in 0..=ny {
        for j in 0..=nx {
            let (x, y) = (width * j as f64 / nx as f64, height * i as f64 / ny as f64);
            writeln!(s, "v {x} {y} 0").unwrap();
        }
    }
    for i in 0..ny {
        for j in 0..nx {
            let a = i * (nx + 1) + j + 1;
            let (b, c) = (a + 1, a + nx + 1);
            writeln!(s, "f {a} {b} {}\nf {a} {} {c}", c + 1, c + 1).unwrap();
        }
    }
    s
}

/// The relief_cow config on a `width × height` sheet, written into `dir`.
fn sheet_config(dir: &Path, width: f64, height: f64) -> PathBuf {
    let (nx, ny) = if width >= height {
        (((30.0 * width / height).round() as usize).max(1), 30)
    } else {
        (30, ((30.0 * height / width).round() as usize).max(1))
    };
    std::fs::write(dir.join("sheet.obj"), sheet_obj(width, height, nx, ny)).unwrap();
    let nops = repo().join("configs/assets/nops.png");
    let text = std::fs::read_to_string(repo().join("configs/relief_cow.toml"))
        .unwrap()
        .replace("assets/cow.obj", "sheet.obj")
        .replace("assets/nops.png", nops.to_str().unwrap());
    assert!(text.contains("sheet.obj"), "relief_cow.toml names its mesh");
    let path = dir.join("sheet.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// `texsyn score` of the sheet at density offset 0: the grid row and the surface row.
fn sheet_scores(width: f64, height: f64) -> (Value, Value) {
    let d = tempfile::tempdir().unwrap();
    let config = sheet_config(d.path(), width, height);
    let o = succeeded(texsyn(
        &[
            "score",
            config.to_str().unwrap(),
            "--set",
            "field.density_offset=0",
            "--cache",
            "c",
            "--json",
        ],
        d.path(),
    ));
    let v: Value = serde_json::from_slice(&o.stdout).expect("JSON on stdout");
    let items = v["items"].as_array().expect("items");
    assert_eq!(items.len(), 2, "{v}");
    (items[0]["score"].clone(), items[1]["score"].clone())
}

fn measures(s: &Value) -> [f64; 4] {
    ["ratio", "coverage", "largest_offset", "gradient_ratio"]
        .map(|k| s[k].as_f64().unwrap_or_else(|| panic!("{k} in {s}")))
}

#[test]
fn an_undistorted_sheet_is_synthesized_near_the_issue_bar() {
    let (grid, surface) = sheet_scores(1.0, 1.0);
    let [ratio, coverage, offset, gradient] = measures(&grid);
    // The issue's bar for coverage, largest offset and gradient; the ratio within 0.1 of its
    // 0.6 (0.627 measured), so that a regression of the synthesizer's core shows here.
    assert!(ratio <= 0.7, "ratio {ratio}: {grid}");
    assert!(coverage >= 0.4, "coverage {coverage}: {grid}");
    assert!(offset <= 0.15, "largest offset {offset}: {grid}");
    assert!(gradient >= 0.8, "gradient ratio {gradient}: {grid}");
    assert_eq!(grid["queries"].as_u64(), Some(20_000), "{grid}");
    // Without distortion the surface row reads the grid as it is.
    let s = measures(&surface);
    for (a, b) in s.iter().zip([ratio, coverage, offset, gradient]) {
        assert!(
            (a - b).abs() < 0.05,
            "surface {surface} against grid {grid}"
        );
    }
}

#[test]
#[ignore = "issue 12: the default does not reach the bar on a stretched sheet yet (0.753 / 0.229 / 0.001 / 0.346)"]
fn a_stretched_sheet_comes_near_the_floor_along_the_surface() {
    let (_, surface) = sheet_scores(3.0, 1.0);
    let [ratio, coverage, offset, gradient] = measures(&surface);
    assert!(
        ratio <= 0.65 && coverage >= 0.4 && offset <= 0.15 && gradient >= 0.8,
        "{surface}"
    );
}
