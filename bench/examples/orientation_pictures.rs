//! The orientation controls as a user sees them, one picture each (one view of each run's
//! `preview.png`, side by side, each run in a fresh cache):
//! - `graph-matching-sink.png`: configs/graph_matching_open.toml (wood2's stripes on the
//!   mushroom) as shipped (the default flow along the longest axis), with a sink at the centre
//!   of the round cap (the stripes run into it), and with the same sink and
//!   `field.rotation = 90` (rings around it); the third view, from above.
//! - `jump-maps-symmetry.png`: jump maps (configs/demo.toml's settings) on the genus-3
//!   elephant with parque1's four-fold parquet, `field.symmetry = 1` then `4`; the first view.
//!
//! ```text
//! cargo build --release && cargo run --release -p texsyn-bench --example orientation_pictures -- [OUT_DIR]
//! ```

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs `config` with `sets` into `out` (a fresh cache beside it); the preview's path.
fn preview(config: &Path, sets: &[&str], out: &Path) -> PathBuf {
    let cache = out.join("cache");
    let mut cmd = Command::new(common::texsyn_binary());
    cmd.arg("run")
        .arg(config)
        .arg("--cache")
        .arg(&cache)
        .arg("--out")
        .arg(out)
        .arg("-q");
    for s in sets {
        cmd.arg("--set").arg(s);
    }
    let status = cmd.status().unwrap();
    assert!(status.success(), "{sets:?}: {status}");
    std::fs::remove_dir_all(&cache).ok();
    out.join("preview.png")
}

/// View `view` (0-based; a preview's views are squares side by side) of each preview, side by
/// side into `out`.
fn strip(previews: &[PathBuf], view: u32, out: &Path) {
    let gap = 8;
    let crops: Vec<image::RgbImage> = previews
        .iter()
        .map(|p| {
            let img = image::open(p).unwrap().to_rgb8();
            let side = img.height();
            image::imageops::crop_imm(&img, view * side, 0, side, side).to_image()
        })
        .collect();
    let w = crops.iter().map(|c| c.width()).sum::<u32>() + gap * (crops.len() as u32 - 1);
    let h = crops.iter().map(|c| c.height()).max().unwrap();
    let mut img = image::RgbImage::from_pixel(w, h, image::Rgb([255, 255, 255]));
    let mut x = 0;
    for c in &crops {
        image::imageops::replace(&mut img, c, x as i64, 0);
        x += c.width() + gap;
    }
    img.save(out).unwrap();
}

/// A picture's file, its config, its runs as (name, --sets), and the preview's view to show.
type Picture<'a> = (&'a str, &'a str, Vec<(&'a str, Vec<&'a str>)>, u32);

fn main() {
    let dir = common::out_dir();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let sink = "field.sinks=[{ at = [0.0, 0.0, 0.232] }]"; // the round cap's centre (z up)
    let elephant = [
        "inputs.mesh=\"assets/elephant.off\"",
        "inputs.exemplar=\"assets/parque1.png\"",
        "parameterize.scale=\"auto\"",
        "parameterize.rotation=0",
        "reconstruct.up=\"auto\"",
    ];
    let with = |extra: &[&'static str]| [&elephant[..], extra].concat();
    let pictures: [Picture; 2] = [
        (
            "graph-matching-sink.png",
            "configs/graph_matching_open.toml",
            vec![
                ("shipped", vec![]),
                ("sink", vec![sink]),
                ("sink-rotation", vec![sink, "field.rotation=90"]),
            ],
            2,
        ),
        (
            "jump-maps-symmetry.png",
            "configs/demo.toml",
            vec![
                ("symmetry1", with(&["field.symmetry=1"])),
                ("symmetry4", with(&["field.symmetry=4"])),
            ],
            0,
        ),
    ];
    for (picture, config, runs, view) in &pictures {
        let mut previews = Vec::new();
        for (name, sets) in runs {
            let out = dir.join(format!("orientation-{name}"));
            previews.push(preview(&repo.join(config), sets, &out));
            println!("{name}: {}", out.display());
        }
        let out = dir.join(picture);
        strip(&previews, *view, &out);
        println!("{}", out.display());
    }
}
