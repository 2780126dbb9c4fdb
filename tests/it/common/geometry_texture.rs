//! Synthetic geometry images, parameter fields and texel samples for geometric texture
//! synthesis (Lai et al. 2005, §4.2–4.3). Shared by tests/geometry_texture.rs and the
//! `geometry_texture_*` examples.
#![allow(dead_code)] // each user takes a different part

use glam::{Vec2, Vec3};
use texsyn::geom::geometry_image::{GeometryImage, TexelImage};
use texsyn::random::counter_unit;
use texsyn::stages::analyse_exemplar::texel_variants::{
    TexelVariantParams, TexelVariants, build_texel_variants,
};
use texsyn::stages::synthesize::geometry_texture::{
    GeometrySynthParams, ParamField, synthesize_geometry_texture,
};
use texsyn_core::math::PureMath;

/// A flat square: no mates.
pub fn flat(n: u32) -> GeometryImage {
    let nn = (n * n) as usize;
    GeometryImage {
        n,
        positions: (0..nn)
            .map(|k| Vec3::new((k as u32 % n) as f32, (k as u32 / n) as f32, 0.0))
            .collect(),
        normals: vec![Vec3::Z; nn],
        mate_rep: (0..nn as u32).collect(),
    }
}

/// A cylinder: column 0 mated with column n−1 row by row (the left and right sides of the
/// square are the two sides of one cut).
pub fn cylinder(n: u32) -> GeometryImage {
    let mut gi = flat(n);
    for i in 0..n {
        gi.mate_rep[(i * n + n - 1) as usize] = i * n;
    }
    gi
}

/// A cut folded at the corner: the top side `(0, j)` glued to the left side `(j, 0)`.
pub fn folded(n: u32) -> GeometryImage {
    let mut gi = flat(n);
    for j in 1..n {
        gi.mate_rep[(j * n) as usize] = j;
    }
    gi
}

/// The same direction and relative scale everywhere.
pub fn field(n: u32, dir: Vec2, r: f32) -> ParamField {
    let nn = (n * n) as usize;
    ParamField {
        dir: vec![dir; nn],
        rel_scale: vec![r; nn],
    }
}

/// The paper's timing case on an n² image: the direction turns along the columns (0.02 rad
/// a column), the relative scale R goes from 0.5 to 2 down the rows.
pub fn turning_field(n: u32) -> ParamField {
    let nn = (n * n) as usize;
    ParamField {
        dir: (0..nn)
            .map(|k| Vec2::from_angle((k as u32 % n) as f32 * 0.02).rotate(Vec2::Y))
            .collect(),
        rel_scale: (0..nn)
            .map(|k| 0.5 + 1.5 * (k as u32 / n) as f32 / n as f32)
            .collect(),
    }
}

/// Stripes across x: dn = sin(2π x / period), dx = 0.3 cos(2π x / period), dy = 0.
pub fn stripes(size: u32, period: f32) -> TexelImage {
    let mut t = TexelImage::new(size, size, 3);
    for y in 0..size {
        for x in 0..size {
            let a = std::f32::consts::TAU * x as f32 / period;
            let p = t.texel_mut(x, y);
            p[0] = 0.3 * a.cos_pure();
            p[1] = 0.0;
            p[2] = a.sin_pure();
        }
    }
    t
}

/// Random Gaussian bumps; (dx, dy) point down the slopes. With `color`, r g b follow the height.
pub fn bumps(size: u32, seed: u64, color: bool) -> TexelImage {
    let c = if color { 6 } else { 3 };
    let mut t = TexelImage::new(size, size, c);
    let count = (size * size / 40) as u64;
    let sigma = 2.2f32;
    let centres: Vec<(f32, f32, f32)> = (0..count)
        .map(|k| {
            (
                counter_unit(seed, 1, k) * size as f32,
                counter_unit(seed, 2, k) * size as f32,
                0.5 + 0.5 * counter_unit(seed, 3, k),
            )
        })
        .collect();
    for y in 0..size {
        for x in 0..size {
            let (mut h, mut gx, mut gy) = (0.0f32, 0.0f32, 0.0f32);
            for &(cx, cy, a) in &centres {
                let (dx, dy) = (x as f32 - cx, y as f32 - cy);
                let e = a * (-(dx * dx + dy * dy) / (2.0 * sigma * sigma)).exp_pure();
                h += e;
                gx -= e * dx / (sigma * sigma);
                gy -= e * dy / (sigma * sigma);
            }
            let p = t.texel_mut(x, y);
            p[0] = -0.5 * gx;
            p[1] = -0.5 * gy;
            p[2] = h;
            if color {
                p[3] = 0.2 + 0.5 * h;
                p[4] = 0.5;
                p[5] = 1.0 - 0.3 * h;
            }
        }
    }
    t
}

/// The sample's variants with the default parameters (8 orientations × 3 scales).
pub fn variants(sample: &TexelImage) -> TexelVariants {
    build_texel_variants(sample, &TexelVariantParams::default(), &|_| {}).unwrap()
}

/// Synthesis with the default parameters and `seed`.
pub fn synth(gi: &GeometryImage, f: &ParamField, v: &TexelVariants, seed: u64) -> TexelImage {
    let p = GeometrySynthParams {
        seed,
        ..Default::default()
    };
    synthesize_geometry_texture(gi, f, &v.as_ref(), &p, &|_| {}).unwrap()
}

/// One channel of every texel, in order.
pub fn channel(t: &TexelImage, ch: usize) -> Vec<f32> {
    t.data
        .iter()
        .skip(ch)
        .step_by(t.channels as usize)
        .copied()
        .collect()
}
