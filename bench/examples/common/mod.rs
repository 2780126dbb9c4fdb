//! What the examples share: where they write and how they read their settings. Each example
//! says `mod common;`; helpers shared with the tests come from `tests/it/common/` by `#[path]`.
#![allow(dead_code)] // each example uses a different part

use std::path::PathBuf;

/// The output directory: the first command-line argument, or the system temp directory.
/// Created if missing.
pub fn out_dir() -> PathBuf {
    let dir = std::env::args_os()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(std::env::temp_dir);
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    dir
}

/// The environment variable `name` parsed as a `T`, or `default` if it is unset or does not
/// parse.
pub fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The texsyn binary beside the running example's folder (target/release/examples/..).
pub fn texsyn_binary() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let bin = exe.parent().unwrap().parent().unwrap().join("texsyn");
    assert!(
        bin.exists(),
        "{}: build it first (cargo build --release)",
        bin.display()
    );
    bin
}

/// Runs `config` with `sets` (each a `--set`) into `out`, in a fresh cache beside it that is
/// removed afterwards; the path of the run's `preview.png`.
pub fn run_preview(config: &std::path::Path, sets: &[String], out: &std::path::Path) -> PathBuf {
    let cache = out.join("cache");
    let mut cmd = std::process::Command::new(texsyn_binary());
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
    assert!(status.success(), "{} {sets:?}: {status}", config.display());
    std::fs::remove_dir_all(&cache).ok();
    out.join("preview.png")
}

/// View `view` (0-based; a preview's views are squares side by side) of each preview, side by
/// side, 8 pixels apart, into `out`.
pub fn preview_strip(previews: &[PathBuf], view: u32, out: &std::path::Path) {
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
