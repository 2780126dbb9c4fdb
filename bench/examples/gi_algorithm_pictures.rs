//! The geometry-image method's two synthesizers side by side, as a user sees them: for each
//! case, `texsyn run` with `synthesize.algorithm = "template"` and then `"appearance"` (fresh
//! cache), and one view of each `preview.png` (its views are squares side by side) next to
//! each other in `gi-<case>-algorithms.png` (template left, appearance right). Cases: relief_cow and dragon_elephant as shipped, and
//! the untuned photo relief of BENCHMARKS.md (mushroom.off with crinklepaper.png, a colour
//! photo read as a height field, relief_cow's settings otherwise), which needs
//! ../shared/data and is skipped, saying so, without it.
//!
//! ```text
//! cargo build --release && cargo run --release -p texsyn-bench --example gi_algorithm_pictures -- [OUT_DIR]
//! ```

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs `config` with the algorithm and extra `--set`s into `out`; the preview's path.
fn preview(config: &Path, algorithm: &str, sets: &[String], out: &Path) -> PathBuf {
    let cache = out.join("cache");
    let mut cmd = Command::new(common::texsyn_binary());
    cmd.arg("run")
        .arg(config)
        .arg("--cache")
        .arg(&cache)
        .arg("--out")
        .arg(out)
        .arg("-q")
        .arg("--set")
        .arg(format!("synthesize.algorithm=\"{algorithm}\""));
    for s in sets {
        cmd.arg("--set").arg(s);
    }
    let status = cmd.status().unwrap();
    assert!(
        status.success(),
        "{} {algorithm}: {status}",
        config.display()
    );
    std::fs::remove_dir_all(&cache).ok();
    out.join("preview.png")
}

/// View `view` (0-based) of the previews `a` and `b`, side by side into `out`.
fn side_by_side(a: &Path, b: &Path, view: u32, out: &Path) {
    let crop = |p: &Path| {
        let img = image::open(p).unwrap().to_rgb8();
        let side = img.height();
        image::imageops::crop_imm(&img, view * side, 0, side, side).to_image()
    };
    let (a, b) = (crop(a), crop(b));
    let gap = 8;
    let (w, h) = (a.width() + gap + b.width(), a.height().max(b.height()));
    let mut img = image::RgbImage::from_pixel(w, h, image::Rgb([255, 255, 255]));
    image::imageops::replace(&mut img, &a, 0, 0);
    image::imageops::replace(&mut img, &b, (a.width() + gap) as i64, 0);
    img.save(out).unwrap();
}

fn main() {
    let dir = common::out_dir();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let shared = repo.join("../shared/data");
    // (name, config, --sets, the preview's view to show)
    let mut cases: Vec<(&str, PathBuf, Vec<String>, u32)> = vec![
        (
            "relief-cow",
            repo.join("configs/relief_cow.toml"),
            vec![],
            0,
        ),
        (
            "dragon-elephant",
            repo.join("configs/dragon_elephant.toml"),
            vec![],
            2,
        ),
    ];
    let (mushroom, paper) = (
        shared.join("meshes/mushroom.off"),
        shared.join("exemplars/crinklepaper.png"),
    );
    if mushroom.exists() && paper.exists() {
        cases.push((
            "mushroom-crinklepaper-untuned",
            repo.join("configs/relief_cow.toml"),
            vec![
                format!("inputs.mesh={:?}", mushroom.display().to_string()),
                format!("inputs.sample={:?}", paper.display().to_string()),
            ],
            2,
        ));
    } else {
        println!(
            "{} not found: the untuned photo relief is skipped",
            shared.display()
        );
    }
    for (name, config, sets, view) in cases {
        let t = preview(
            &config,
            "template",
            &sets,
            &dir.join(format!("{name}-template")),
        );
        let a = preview(
            &config,
            "appearance",
            &sets,
            &dir.join(format!("{name}-appearance")),
        );
        let out = dir.join(format!("gi-{name}-algorithms.png"));
        side_by_side(&t, &a, view, &out);
        println!("wrote {}", out.display());
    }
}
