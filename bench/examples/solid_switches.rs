//! Before/after pictures of the solid method's three §4.3/§6 switches (README, "Solid:
//! feature masks and the coarse-level field"):
//!
//! - `solid-feature-mask.png`: brick.png on all three planes, the trivial field; the middle z
//!   section of a 64³ cube: exemplar | detected feature channel | without | with
//!   `analyse_exemplar.feature_mask` (detected curves) | a drawn mask (the joints traced as
//!   straight lines, as a user would draw them) | with the drawn mask;
//! - `solid-coarse-field.png`: wood2 layered across x (yz not matched) in a "tree rings"
//!   field (x pointing away from the cube's z axis, a singularity on it) with every node
//!   tilted by up to 0.35 rad at random; the middle z section (top row) and level 2 of 4 under
//!   it (bottom row, grey, contrast stretched): neither | `field_smoothing = 2` | `field_integration` | both.
//!
//! Sections are shown as the reconstruct node shows a z-cut (`reconstruct.colour = "facing"`).
//! It prints the measurements the README quotes. `cargo run --release -p texsyn-bench --example
//! solid_switches -- [OUT_DIR]`; `SIZE` [64].

mod common;
#[path = "../../tests/it/common/exemplars.rs"]
mod exemplars;
#[path = "../../tests/it/common/solid.rs"]
mod solid;

use common::env_or;
use exemplars::load_exemplar as load;
use glam::Vec3;
use solid::{cube, jittered, rings_field, transpose, trivial_field};
use texsyn::image::Image;
use texsyn::stages::analyse_exemplar::candidate_triples::{
    CandidateParams, Triple, analyse, analyse_masked,
};
use texsyn::stages::analyse_exemplar::feature_mask::{FeatureMaskParams, feature_channel};
use texsyn::stages::analyse_exemplar::texture_feature_lines::{
    TextureFeatureParams, detect_texture_features, line_length,
};
use texsyn::stages::field::quaternion_field::RotationField;
use texsyn::stages::reconstruct::solid_colour::{SolidColourRule, VoxelTriples};
use texsyn::stages::synthesize::solid::solid_synthesis::{
    MemoryBrickStore, SolidParams, SolidSynthesis, VoxelRequest,
};

/// Tiles of `n × n` colours side by side, each pixel `zoom`×`zoom`, 4 px gaps.
fn save_row(path: &std::path::Path, tiles: &[Vec<[f32; 3]>], n: u32, zoom: u32) {
    let gap = 4;
    let w = tiles.len() as u32 * (n * zoom + gap) - gap;
    let mut img = image::RgbImage::from_pixel(w, n * zoom, image::Rgb([255, 255, 255]));
    for (t, px) in tiles.iter().enumerate() {
        let x0 = t as u32 * (n * zoom + gap);
        for y in 0..n * zoom {
            for x in 0..n * zoom {
                let c = px[((y / zoom) * n + x / zoom) as usize];
                let c = c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
                img.put_pixel(x0 + x, y, image::Rgb(c));
            }
        }
    }
    img.save(path).unwrap();
}

/// Luminance stretched to the full range, grey (a coarse level's blurred colours are
/// otherwise too flat to see).
fn stretch(px: &[[f32; 3]]) -> Vec<[f32; 3]> {
    let lum: Vec<f32> = px.iter().map(|c| (c[0] + c[1] + c[2]) / 3.0).collect();
    let lo = lum.iter().copied().fold(f32::MAX, f32::min);
    let hi = lum.iter().copied().fold(f32::MIN, f32::max);
    lum.iter()
        .map(|l| [(l - lo) / (hi - lo).max(1e-6); 3])
        .collect()
}

/// Tiles in rows of `cols`, each pixel `zoom`×`zoom`, 4 px gaps.
fn save_grid(path: &std::path::Path, tiles: &[Vec<[f32; 3]>], cols: usize, n: u32, zoom: u32) {
    let gap = 4;
    let rows = tiles.len().div_ceil(cols) as u32;
    let side = n * zoom + gap;
    let mut img = image::RgbImage::from_pixel(
        cols as u32 * side - gap,
        rows * side - gap,
        image::Rgb([255, 255, 255]),
    );
    for (t, px) in tiles.iter().enumerate() {
        let (x0, y0) = ((t % cols) as u32 * side, (t / cols) as u32 * side);
        for y in 0..n * zoom {
            for x in 0..n * zoom {
                let c = px[((y / zoom) * n + x / zoom) as usize];
                let c = c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
                img.put_pixel(x0 + x, y0 + y, image::Rgb(c));
            }
        }
    }
    img.save(path).unwrap();
}

/// The middle z section of an n³ cube: colours and triples.
fn section(
    a: &texsyn::stages::analyse_exemplar::candidate_triples::SolidAnalysis,
    field: &RotationField,
    n: u32,
    params: SolidParams,
) -> (Vec<[f32; 3]>, Vec<Triple>, Vec<[f32; 3]>) {
    let vol = cube(n);
    let s = SolidSynthesis::new(a.as_ref(), field, vol, params).unwrap();
    let store = MemoryBrickStore::new();
    let c = n as i32 / 2;
    let finest = s.levels();
    let t = std::time::Instant::now();
    s.synthesize(
        &VoxelRequest::from_box([0, 0, c], [n as i32, n as i32, c + 1]),
        &store,
    )
    .unwrap();
    eprintln!("  section: {:.1} s", t.elapsed().as_secs_f64());
    let mut voxels = vec![];
    let mut ts = vec![];
    for y in 0..n as i32 {
        for x in 0..n as i32 {
            voxels.push([x, y, c]);
            ts.push(s.triple_at(&store, finest, [x, y, c]).unwrap());
        }
    }
    let mut shown = VoxelTriples::new(field, &vol, SolidColourRule::Facing);
    shown.add(&voxels, &ts, a.as_ref());
    let px = voxels
        .iter()
        .map(|v| shown.colour((*v).into(), Some(Vec3::Z)).unwrap())
        .collect();
    // Level L − 2 (a coarse level) under the same pixels, each of its voxels 4 × 4.
    let l = s.levels() - 2;
    let mut coarse = vec![];
    for y in 0..n as i32 {
        for x in 0..n as i32 {
            let t = s.triple_at(&store, l, [x / 4, y / 4, c / 4]).unwrap();
            coarse.push(s.colour(l, &t));
        }
    }
    (px, ts, coarse)
}

/// Lines the feature detector finds in an `n × n` image of colours: (count, total length in
/// texels, longest).
fn lines_in(px: &[[f32; 3]], n: u32) -> (usize, f32, f32) {
    let img = Image::from_fn(n, n, |x, y| {
        let c = px[(y * n + x) as usize];
        [c[0], c[1], c[2], 1.0]
    });
    match detect_texture_features(&img, &TextureFeatureParams::default()) {
        Err(_) => (0, 0.0, 0.0),
        Ok(f) => {
            let len: Vec<f32> = f.lines.iter().map(|l| line_length(l)).collect();
            (
                len.len(),
                len.iter().sum(),
                len.iter().copied().fold(0.0, f32::max),
            )
        }
    }
}

/// How far a section is from rings about its centre: the variance of colour within 1-voxel
/// radius bins over the total variance (0 = perfect rings).
fn ring_residual(px: &[[f32; 3]], n: u32) -> f64 {
    let c = (n as f64 - 1.0) / 2.0;
    let bins = n as usize;
    let (mut sum, mut sq, mut cnt) = (vec![0.0f64; bins], vec![0.0f64; bins], vec![0usize; bins]);
    let (mut ts, mut tq) = (0.0f64, 0.0f64);
    for y in 0..n {
        for x in 0..n {
            let p = px[(y * n + x) as usize];
            let l = (p[0] + p[1] + p[2]) as f64 / 3.0;
            let r = ((x as f64 - c).powi(2) + (y as f64 - c).powi(2)).sqrt() as usize;
            sum[r] += l;
            sq[r] += l * l;
            cnt[r] += 1;
            ts += l;
            tq += l * l;
        }
    }
    let total = tq - ts * ts / (n * n) as f64;
    let within: f64 = (0..bins)
        .filter(|&b| cnt[b] > 0)
        .map(|b| sq[b] - sum[b] * sum[b] / cnt[b] as f64)
        .sum();
    within / total
}

/// The top-left `n × n` of an image, tiled if smaller.
fn tile_of(img: &Image, n: u32) -> Vec<[f32; 3]> {
    let mut out = vec![];
    for y in 0..n {
        for x in 0..n {
            let p = img.pixels[((y % img.height) * img.width + x % img.width) as usize];
            out.push([p[0], p[1], p[2]]);
        }
    }
    out
}

fn main() {
    let dir = common::out_dir();
    let n: u32 = env_or("SIZE", 64);
    let levels = 4;

    let part: String = env_or("PART", "all".to_string());
    if part != "wood" {
        feature_mask_picture(&dir, n, levels);
    }
    if part != "brick" {
        coarse_field_picture(&dir, n, levels);
    }
}

/// brick.png's joints traced as straight two-texel lines, as a user would draw them over the
/// image: the bed joints (the dark rows between courses) at y = 24, 56 and 91, and the head
/// joints of each course at the dark columns of its rows (x = 22 and 60 in the course that
/// wraps from y = 92 to 23, 42 and 91 in y = 25–55, 54 in y = 57–90).
fn drawn_joints(brick: &Image) -> Image {
    assert_eq!((brick.width, brick.height), (96, 96), "traced on brick.png");
    let near = |a: u32, b: u32| a == b || a == b + 1;
    let on = |x: u32, y: u32| {
        let bed = [24, 56, 91].iter().any(|&r| near(y, r));
        let heads: &[u32] = if !(25..92).contains(&y) {
            &[22, 60]
        } else if y < 57 {
            &[42, 91]
        } else {
            &[54]
        };
        bed || heads.iter().any(|&c| near(x, c))
    };
    Image::from_fn(96, 96, |x, y| {
        let v = if on(x, y) { 1.0 } else { 0.0 };
        [v, v, v, 1.0]
    })
}

fn feature_mask_picture(dir: &std::path::Path, n: u32, levels: u32) {
    let brick = load("brick.png");
    let fm = FeatureMaskParams {
        weight: env_or("FM_WEIGHT", 1.0),
        radius: env_or("FM_RADIUS", 6.0),
        ..Default::default()
    };
    let chan = feature_channel(brick.view(), &fm).unwrap();
    let chan_img = Image::from_fn(brick.width, brick.height, |x, y| {
        let f = chan[(y * brick.width + x) as usize];
        [f, f, f, 1.0]
    });
    let drawn = drawn_joints(&brick);
    let mut tiles = vec![tile_of(&brick, n), tile_of(&chan_img, n)];
    let field = trivial_field(&cube(n));
    let ex = lines_in(&tiles[0], n);
    println!(
        "brick exemplar crop: lines {} total {:.0} longest {:.0}",
        ex.0, ex.1, ex.2
    );
    for (mask, what) in [
        (None, "none"),
        (Some(fm.clone()), "detected"),
        (Some(fm.clone()), "drawn"),
    ] {
        let cp = CandidateParams {
            levels,
            feature_mask: mask,
            ..Default::default()
        };
        let masks = [(what == "drawn").then(|| drawn.view()); 3];
        let a = analyse_masked([brick.view(); 3], masks, &cp).unwrap();
        eprintln!("brick, feature mask {what}:");
        if what == "drawn" {
            tiles.push(tile_of(&drawn, n));
        }
        let (px, ts, _) = section(&a, &field, n, SolidParams::paper(levels));
        // The feature channel carried by the synthesized voxels (mean over the planes).
        let f: Vec<f32> = ts
            .iter()
            .map(|t| {
                (0..3)
                    .map(|p| chan[(t.c[p][1] as u32 * brick.width + t.c[p][0] as u32) as usize])
                    .sum::<f32>()
                    / 3.0
            })
            .collect();
        let mean_f = f.iter().sum::<f32>() / f.len() as f32;
        let l = lines_in(&px, n);
        println!(
            "brick, feature mask {what}: lines {} total {:.0} longest {:.0}; mean F {:.3} (exemplar {:.3})",
            l.0,
            l.1,
            l.2,
            mean_f,
            chan.iter().sum::<f32>() / chan.len() as f32
        );
        tiles.push(px);
    }
    save_row(&dir.join("solid-feature-mask.png"), &tiles, n, 3);
}

fn coarse_field_picture(dir: &std::path::Path, n: u32, levels: u32) {
    // Coarse-level field: smoothing and integration.
    let wood = load("wood2.png");
    let tr = transpose(&wood);
    let cp = CandidateParams {
        levels,
        plane_weights: [1.0, 0.0, 1.0],
        ..Default::default()
    };
    let a = analyse([wood.view(), wood.view(), tr.view()], &cp).unwrap();
    let field = jittered(&rings_field(&cube(n), 16), 0.35, 7);
    let mut tiles = vec![];
    let mut coarse_tiles = vec![];
    for (smooth, integrate) in [(0.0, false), (2.0, false), (0.0, true), (2.0, true)] {
        let mut p = SolidParams::paper(levels);
        p.field_smoothing = smooth;
        p.field_integration = integrate;
        eprintln!("wood rings, smoothing {smooth}, integration {integrate}:");
        let (px, _, coarse) = section(&a, &field, n, p);
        println!(
            "wood rings, smoothing {smooth}, integration {integrate}: ring residual {:.3} (level {}: {:.3})",
            ring_residual(&px, n),
            levels - 2,
            ring_residual(&coarse, n)
        );
        tiles.push(px);
        coarse_tiles.push(stretch(&coarse));
    }
    tiles.extend(coarse_tiles);
    save_grid(&dir.join("solid-coarse-field.png"), &tiles, 4, n, 3);
}
