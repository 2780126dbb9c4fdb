//! The floor of the geometry-image surface row: what a *perfect* synthesis
//! would score when its layout is stretched.
//!
//! The surface row of `texsyn score` reads the relief image through each texel's map `M`
//! (grid offsets to sample texels) and compares the patches with the sample's. Here the "relief
//! image" is the sample itself laid out verbatim under one constant `M`: texel `c` holds the
//! sample at `M (c − centre)`, taken at the nearest sample texel (as synthesis copies texels)
//! or bilinearly. With `M` the identity the score is that of a verbatim crop (ratio 0,
//! largest offset 1); any stretch resamples twice, and the ratio and gradient ratio that
//! costs are the best the row can report for a map with that stretch. Coverage and largest
//! offset are not floors: they depend on how many patches fit in the square, which shrinks
//! with the stretch (the pipeline scores 20,000 patches of a 257² grid), and on rounding.
//!
//! ```text
//! cargo run --release -p texsyn-bench --example frame_score_floor [SAMPLE.png]
//! ```
//! (default `configs/assets/nops.png`, read as grey.)

use texsyn::image::Image;
use texsyn::image::patch_score::ScoreParams;
use texsyn::score::relief_frame::score_along_maps;
use texsyn_core::math::PureMath;

/// `R(θ) diag(a, b) R(θ)ᵀ`, row-major.
fn stretch(a: f32, b: f32, theta: f32) -> [f32; 4] {
    let (s, c) = (theta.sin_pure(), theta.cos_pure());
    [
        a * c * c + b * s * s,
        (a - b) * c * s,
        (a - b) * c * s,
        a * s * s + b * c * c,
    ]
}

fn main() -> anyhow::Result<()> {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "configs/assets/nops.png".to_owned());
    let path = std::path::Path::new(&path);
    let sample = texsyn::image::decode_image(path, &std::fs::read(path)?)?;
    let (w, h) = (sample.width as usize, sample.height as usize);
    let lum: Vec<f32> = sample
        .pixels
        .iter()
        .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
        .collect();
    let grey = Image::from_fn(w as u32, h as u32, |x, y| {
        let g = lum[y as usize * w + x as usize];
        [g, g, g, 1.0]
    });
    let at = |x: usize, y: usize| lum[y * w + x];
    println!("| M | copy | grid | queries | ratio | gradient ratio | coverage | largest offset |");
    println!("|---|---|---|---:|---:|---:|---:|---:|");
    // λ as in `max_stretch`: `A`'s eigenvalues λ and 1/λ, surface lengths λ² : 1. A rhombus
    // sheet of angle α maps to the square affinely, with λ⁴ = (1 + cos α) / (1 − cos α) along
    // the square's diagonal.
    let cases = [
        ("identity", stretch(1.0, 1.0, 0.0)),
        ("λ 1.1 along a side", stretch(1.1, 1.0 / 1.1, 0.0)),
        ("λ 1.3 along a side", stretch(1.3, 1.0 / 1.3, 0.0)),
        (
            "λ 1.316 at 45° (a 60° rhombus)",
            stretch(1.316, 1.0 / 1.316, 0.785),
        ),
        (
            "λ 1.732 along a side",
            stretch(3f32.sqrt(), 1.0 / 3f32.sqrt(), 0.0),
        ),
        (
            "λ 1.732 at 45° (a 36.87° rhombus)",
            stretch(3f32.sqrt(), 1.0 / 3f32.sqrt(), 0.785),
        ),
        ("uniform 1.5 (minified)", stretch(1.5, 1.5, 0.0)),
        ("uniform 0.58 (magnified)", stretch(0.577, 0.577, 0.0)),
    ];
    for (name, m) in cases {
        for bilinear in [false, true] {
            // The largest square of grid texels whose sample positions all lie inside.
            let reach = |side: f32| {
                let r = side / 2.0;
                (m[0].abs() + m[1].abs()) * r <= (w as f32 - 1.0) / 2.0
                    && (m[2].abs() + m[3].abs()) * r <= (h as f32 - 1.0) / 2.0
            };
            let mut side = 8u32;
            while reach(side as f32 + 1.0) && side < 512 {
                side += 1;
            }
            let r = side as f32 / 2.0;
            let img = Image::from_fn(side, side, |x, y| {
                let (gx, gy) = (x as f32 - r, y as f32 - r);
                let u = (m[0] * gx + m[1] * gy + (w as f32 - 1.0) / 2.0).clamp(0.0, w as f32 - 1.0);
                let v = (m[2] * gx + m[3] * gy + (h as f32 - 1.0) / 2.0).clamp(0.0, h as f32 - 1.0);
                let g = if bilinear {
                    let (x0, y0) = (u.floor() as usize, v.floor() as usize);
                    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
                    let (fx, fy) = (u - x0 as f32, v - y0 as f32);
                    (1.0 - fx) * (1.0 - fy) * at(x0, y0)
                        + fx * (1.0 - fy) * at(x1, y0)
                        + (1.0 - fx) * fy * at(x0, y1)
                        + fx * fy * at(x1, y1)
                } else {
                    at((u + 0.5) as usize, (v + 0.5) as usize)
                };
                [g, g, g, 1.0]
            });
            let maps = vec![m; (side * side) as usize];
            let s = score_along_maps(img.view(), &maps, grey.view(), &ScoreParams::default())?;
            println!(
                "| {name} | {} | {side}² | {} | {:.3} | {:.3} | {:.3} | {:.3} |",
                if bilinear { "bilinear" } else { "nearest" },
                s.score.queries,
                s.score.ratio,
                s.score.gradient_ratio,
                s.score.coverage,
                s.score.largest_offset
            );
        }
    }
    Ok(())
}
