//! Jump maps (Zelinka & Garland 2002) on exemplars, timed and shown: for each exemplar it
//! builds the jump map three times and prints the median and all analysis times, the mean
//! 5×5 SSD between each pixel and its best jump, then synthesizes a size² image (seed 1) and
//! prints its coherence (the share of neighbours that continue one patch), the synthesis time,
//! and the gradient energy and per-channel standard deviation relative to the exemplar. It
//! writes
//!
//! - `<exemplar>_exemplar.png` and `<exemplar>_synth.png`: the exemplar and the synthesized
//!   image, blended across seams (both zoomed);
//! - `<exemplar>_synth_r0.png`: the synthesized image without blending;
//! - `<exemplar>_addr.png`: the patches, coloured by source address (red x, green y).
//!
//! ```text
//! cargo run --release -p texsyn-bench --example jump_map_preview -- [OUT_DIR]
//! ```
//!
//! `OUT_DIR` defaults to the system temp directory. Environment:
//! - `TEXSYN_PREVIEW_EXEMPLARS`: image paths, comma-separated (default: wood1, leopard and
//!   marble1 of tests/data/exemplars);
//! - `TEXSYN_PREVIEW_SIZE`: the synthesized image's side (default 256);
//! - `TEXSYN_PREVIEW_PARAMS`, `TEXSYN_PREVIEW_SYNTH`: `JumpMapParams` and `Synth2dParams` as
//!   JSON (default: their defaults);
//! - `TEXSYN_PREVIEW_BLEND`: the seam blending radius (default 1);
//! - `TEXSYN_PREVIEW_ZOOM`: pixel zoom of the `_exemplar` and `_synth` images (default 1).

mod common;
#[path = "../../tests/it/common/exemplars.rs"]
mod exemplars;
#[path = "../../tests/it/common/jump_map.rs"]
mod jump_map;

use common::env_or;
use jump_map::{EXEMPLARS, coherence, patch_ssd, stats};
use std::path::PathBuf;
use texsyn::image::{Image, decode_image};
use texsyn::stages::analyse_exemplar::jump_map::{JumpMapParams, build_jump_map};
use texsyn::stages::reconstruct::blend2d::render_2d;
use texsyn::stages::synthesize::synth2d::{Synth2dParams, synthesize_2d};

/// Mean squared difference of horizontally and vertically neighbouring pixels (R, G, B).
fn gradient_energy(im: &Image) -> f64 {
    let v = im.view();
    let (mut s, mut n) = (0.0f64, 0usize);
    for y in 0..im.height - 1 {
        for x in 0..im.width - 1 {
            let p = v.get(x, y);
            for q in [v.get(x + 1, y), v.get(x, y + 1)] {
                for c in 0..3 {
                    s += ((p[c] - q[c]) as f64).powi(2);
                }
                n += 1;
            }
        }
    }
    s / n as f64
}

fn main() {
    let dir = common::out_dir();
    let list: Vec<PathBuf> = match std::env::var("TEXSYN_PREVIEW_EXEMPLARS") {
        Ok(s) => s.split(',').map(PathBuf::from).collect(),
        Err(_) => EXEMPLARS
            .iter()
            .map(|n| exemplars::exemplar_path(n))
            .collect(),
    };
    let size: u32 = env_or("TEXSYN_PREVIEW_SIZE", 256);
    let params: JumpMapParams = match std::env::var("TEXSYN_PREVIEW_PARAMS") {
        Ok(s) => serde_json::from_str(&s).unwrap(),
        Err(_) => JumpMapParams::default(),
    };
    let synth: Synth2dParams = match std::env::var("TEXSYN_PREVIEW_SYNTH") {
        Ok(s) => serde_json::from_str(&s).unwrap(),
        Err(_) => Synth2dParams::default(),
    };
    let blend: u32 = env_or("TEXSYN_PREVIEW_BLEND", 1);
    let zoom: u32 = env_or("TEXSYN_PREVIEW_ZOOM", 1);
    for path in list {
        let bytes = std::fs::read(&path).unwrap();
        let img = decode_image(&path, &bytes).unwrap();
        let stem = path.file_stem().unwrap().to_string_lossy().to_string();
        let mut times = Vec::new();
        let mut jm = None;
        for _ in 0..3 {
            let t = std::time::Instant::now();
            jm = Some(build_jump_map(img.view(), &params, &|_| {}));
            times.push(t.elapsed().as_secs_f64());
        }
        times.sort_by(|a, b| a.total_cmp(b));
        println!(
            "{stem}: {}x{} analysis median {:.3} s (runs {:?})",
            img.width, img.height, times[1], times
        );
        let jm = jm.unwrap();
        let mut ssd = 0.0f64;
        for y in 0..img.height {
            for x in 0..img.width {
                let j = jm.jumps_at(x, y)[0];
                ssd += patch_ssd(img.view(), (x, y), (j.x as u32, j.y as u32)) as f64;
            }
        }
        println!(
            "{stem}: mean best-jump 5x5 SSD {:.5}",
            ssd / (img.width * img.height) as f64
        );
        let t = std::time::Instant::now();
        let addr = synthesize_2d(jm.as_ref(), size, size, &synth, 1);
        let ts = t.elapsed().as_secs_f64();
        println!("{stem}: coherence {:.3}", coherence(&addr, size, size));
        let out = render_2d(img.view(), &addr, size, size, blend);
        println!("{stem}: synthesis {size}x{size} {:.4} s", ts);
        let zoomed = |img: &Image| {
            let mut z = Image::new(img.width * zoom, img.height * zoom);
            for (i, p) in z.pixels.iter_mut().enumerate() {
                let (x, y) = (i as u32 % z.width / zoom, i as u32 / z.width / zoom);
                *p = img.view().get(x, y);
            }
            z
        };
        let png = |what: &str| dir.join(format!("{stem}_{what}.png"));
        zoomed(&out).to_rgba8().save(png("synth")).unwrap();
        zoomed(&img).to_rgba8().save(png("exemplar")).unwrap();
        let r0 = render_2d(img.view(), &addr, size, size, 0);
        println!(
            "{stem}: gradient energy ratio r0 {:.3} blended {:.3}",
            gradient_energy(&r0) / gradient_energy(&img),
            gradient_energy(&out) / gradient_energy(&img)
        );
        let (se, so) = (stats(&img), stats(&r0));
        println!(
            "{stem}: std ratio r0 {:.3} {:.3} {:.3}",
            so[0].1 / se[0].1,
            so[1].1 / se[1].1,
            so[2].1 / se[2].1
        );
        r0.to_rgba8().save(png("synth_r0")).unwrap();
        // Patches coloured by source address.
        let mut vis = Image::new(size, size);
        for (p, a) in vis.pixels.iter_mut().zip(&addr) {
            *p = [
                a[0] as f32 / jm.width as f32,
                a[1] as f32 / jm.height as f32,
                0.5,
                1.0,
            ];
        }
        vis.to_rgba8().save(png("addr")).unwrap();
    }
    println!("wrote the previews to {}", dir.display());
}
