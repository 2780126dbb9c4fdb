//! Measures of jump maps and of what is synthesized with them. Shared by tests/jump_map.rs
//! and the `jump_map_preview` example.
#![allow(dead_code)] // each user takes a different part

use texsyn::image::{Image, ImageView};

/// The exemplars (in tests/data/exemplars) the jump-map tests and the preview use.
pub const EXEMPLARS: [&str; 3] = ["wood1.png", "leopard.png", "marble1.png"];

/// Gaussian-free plain 5×5 RGB sum of squared differences, clamped borders: an independent
/// measure of how alike two pixels' surroundings are.
pub fn patch_ssd(img: ImageView, a: (u32, u32), b: (u32, u32)) -> f32 {
    let mut s = 0.0;
    for dy in -2i64..=2 {
        for dx in -2i64..=2 {
            let p = img.get_clamped(a.0 as i64 + dx, a.1 as i64 + dy);
            let q = img.get_clamped(b.0 as i64 + dx, b.1 as i64 + dy);
            for c in 0..3 {
                s += (p[c] - q[c]) * (p[c] - q[c]);
            }
        }
    }
    s
}

/// Fraction of horizontally and vertically adjacent output pixels whose addresses differ by
/// exactly their offset (the same patch continues).
pub fn coherence(addr: &[[u16; 2]], w: u32, h: u32) -> f64 {
    let (mut same, mut total) = (0usize, 0usize);
    for y in 0..h {
        for x in 0..w {
            let a = addr[(y * w + x) as usize];
            if x + 1 < w {
                let b = addr[(y * w + x + 1) as usize];
                same += (b[0] as i32 - a[0] as i32 == 1 && b[1] == a[1]) as usize;
                total += 1;
            }
            if y + 1 < h {
                let b = addr[((y + 1) * w + x) as usize];
                same += (b[1] as i32 - a[1] as i32 == 1 && b[0] == a[0]) as usize;
                total += 1;
            }
        }
    }
    same as f64 / total as f64
}

/// Mean and standard deviation of each of the R, G, B channels.
pub fn stats(img: &Image) -> [(f64, f64); 3] {
    let n = img.pixels.len() as f64;
    let mut out = [(0.0, 0.0); 3];
    for (c, o) in out.iter_mut().enumerate() {
        let mean = img.pixels.iter().map(|p| p[c] as f64).sum::<f64>() / n;
        let var = img
            .pixels
            .iter()
            .map(|p| (p[c] as f64 - mean).powi(2))
            .sum::<f64>()
            / n;
        *o = (mean, var.sqrt());
    }
    out
}
