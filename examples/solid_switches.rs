//! Before/after pictures of the solid method's three §4.3/§6 switches (README, "Solid:
//! feature masks and the coarse-level field"):
//!
//! - `solid-feature-mask.png`: brick.png on all three planes, the trivial field; the middle z
//!   section of a 64³ cube: exemplar | feature channel | without | with
//!   `analyse_exemplar.feature_mask`;
//! - `solid-coarse-field.png`: wood2 layered across x (yz not matched) in a "tree rings"
//!   field (x pointing away from the cube's z axis, a singularity on it); the middle z section:
//!   neither | `field_smoothing = 2` | `field_integration` | both.
//!
//! It prints the measurements the README quotes. `cargo run --release --example
//! solid_switches -- [OUT_DIR]`; `SIZE` [64].

mod common;
#[path = "../tests/common/exemplars.rs"]
mod exemplars;
#[path = "../tests/common/solid.rs"]
mod solid;

use common::env_or;
use exemplars::load_exemplar as load;
use solid::{cube, rings_field, transpose, trivial_field};
use texsyn::image::Image;
use texsyn::stages::analyse_exemplar::candidate_triples::{CandidateParams, analyse};
use texsyn::stages::analyse_exemplar::feature_mask::{FeatureMaskParams, feature_channel};
use texsyn::stages::field::quaternion_field::RotationField;
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

/// The middle z section of an n³ cube.
fn section(
    a: &texsyn::stages::analyse_exemplar::candidate_triples::SolidAnalysis,
    field: &RotationField,
    n: u32,
    params: SolidParams,
) -> Vec<[f32; 3]> {
    let vol = cube(n);
    let s = SolidSynthesis::new(a.as_ref(), field, vol, params).unwrap();
    let store = MemoryBrickStore::new();
    let c = n as i32 / 2;
    let t = std::time::Instant::now();
    s.synthesize(
        &VoxelRequest::from_box([0, 0, c], [n as i32, n as i32, c + 1]),
        &store,
    )
    .unwrap();
    eprintln!("  section: {:.1} s", t.elapsed().as_secs_f64());
    let mut px = vec![];
    for y in 0..n as i32 {
        for x in 0..n as i32 {
            px.push(s.colour_at(&store, [x, y, c]).unwrap());
        }
    }
    px
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

    // Feature mask.
    let brick = load("brick.png");
    let fm = FeatureMaskParams::default();
    let chan = feature_channel(brick.view(), &fm).unwrap();
    let chan_img = Image::from_fn(brick.width, brick.height, |x, y| {
        let f = chan[(y * brick.width + x) as usize];
        [f, f, f, 1.0]
    });
    let mut tiles = vec![tile_of(&brick, n), tile_of(&chan_img, n)];
    let field = trivial_field(&cube(n));
    for mask in [None, Some(fm.clone())] {
        let cp = CandidateParams {
            levels,
            feature_mask: mask,
            ..Default::default()
        };
        let a = analyse([brick.view(); 3], &cp).unwrap();
        eprintln!("brick, feature mask {}:", cp.feature_mask.is_some());
        tiles.push(section(&a, &field, n, SolidParams::paper(levels)));
    }
    save_row(&dir.join("solid-feature-mask.png"), &tiles, n, 3);

    // Coarse-level field: smoothing and integration.
    let wood = load("wood2.png");
    let tr = transpose(&wood);
    let cp = CandidateParams {
        levels,
        plane_weights: [1.0, 0.0, 1.0],
        ..Default::default()
    };
    let a = analyse([wood.view(), wood.view(), tr.view()], &cp).unwrap();
    let field = rings_field(&cube(n), 16);
    let mut tiles = vec![];
    for (smooth, integrate) in [(0.0, false), (2.0, false), (0.0, true), (2.0, true)] {
        let mut p = SolidParams::paper(levels);
        p.field_smoothing = smooth;
        p.field_integration = integrate;
        eprintln!("wood rings, smoothing {smooth}, integration {integrate}:");
        tiles.push(section(&a, &field, n, p));
    }
    save_row(&dir.join("solid-coarse-field.png"), &tiles, n, 3);
}
