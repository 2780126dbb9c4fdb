//! Pictures of geometric texture synthesis (Lai et al. 2005, §4.2–4.3) on synthetic geometry
//! images, for looking at: for two 64² samples (stripes of period 10, random bumps) it writes
//! the normal displacement dn as greyscale PNGs, each stretched to black–white:
//!
//! - `gt_<sample>_sample.png`: the sample;
//! - `gt_<sample>_cyl.png`: synthesized on a 129² cylinder (left and right sides are one cut);
//! - `gt_<sample>_cyl_twice.png`: that cylinder unrolled twice side by side, so the seam is in
//!   the middle and shows if it is not hidden;
//! - `gt_<sample>_swirl_scale.png`: a flat 129² square with the direction swirling around the
//!   centre and the relative scale growing from 0.5 to 2 across the columns;
//! - `gt_<sample>_257.png`: the timing case of the `geometry_texture_timing` example (257²
//!   cylinder, direction turning along the columns, scale 0.5 to 2 down the rows).
//!
//! ```text
//! cargo run --release -p texsyn-bench --example geometry_texture_previews -- [OUT_DIR]
//! ```
//!
//! `OUT_DIR` defaults to the system temp directory.

mod common;
#[path = "../../tests/it/common/geometry_texture.rs"]
mod geometry_texture;

use geometry_texture::{
    bumps, channel, cylinder, field, flat, stripes, synth, turning_field, variants,
};
use glam::Vec2;
use std::path::Path;
use texsyn::geom::geometry_image::TexelImage;
use texsyn::stages::synthesize::geometry_texture::ParamField;

/// Writes dn (channel 2) as a greyscale PNG, stretched from its minimum to its maximum.
fn save(t: &TexelImage, path: &Path) {
    let d = channel(t, 2);
    let lo = d.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = d.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let img = image::GrayImage::from_fn(t.width, t.height, |x, y| {
        let v = (t.texel(x, y)[2] - lo) / (hi - lo).max(1e-9);
        image::Luma([(v * 255.0 + 0.5) as u8])
    });
    img.save(path).unwrap();
}

fn main() {
    let dir = common::out_dir();
    let n = 129;
    let nn = (n * n) as usize;
    for (name, sample) in [
        ("stripes", stripes(64, 10.0)),
        ("bumps", bumps(64, 12, false)),
    ] {
        let path = |what: &str| dir.join(format!("gt_{name}_{what}.png"));
        save(&sample, &path("sample"));
        let v = variants(&sample);
        let out = synth(&cylinder(n), &field(n, Vec2::Y, 1.0), &v, 1);
        save(&out, &path("cyl"));
        // The cylinder unrolled twice side by side: the seam is in the middle.
        let mut twice = TexelImage::new(2 * n - 2, n, 3);
        for y in 0..n {
            for x in 0..2 * n - 2 {
                let src = out.texel(x % (n - 1), y).to_vec();
                twice.texel_mut(x, y).copy_from_slice(&src);
            }
        }
        save(&twice, &path("cyl_twice"));
        let swirl = ParamField {
            dir: (0..nn)
                .map(|k| {
                    let (i, j) = ((k as u32 / n) as f32, (k as u32 % n) as f32);
                    let c = (n as f32 - 1.0) / 2.0;
                    Vec2::new(i - c, -(j - c)).normalize_or(Vec2::Y)
                })
                .collect(),
            rel_scale: (0..nn)
                .map(|k| 0.5 + 1.5 * (k as u32 % n) as f32 / n as f32)
                .collect(),
        };
        let out = synth(&flat(n), &swirl, &v, 2);
        save(&out, &path("swirl_scale"));
        // The timing case: 257², direction turning along the columns, R from 0.5 to 2 down.
        let m = 257u32;
        let out = synth(&cylinder(m), &turning_field(m), &v, 3);
        save(&out, &path("257"));
    }
    println!("wrote gt_*.png to {}", dir.display());
}
