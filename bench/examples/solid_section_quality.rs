//! The solid's section quality (README, "Solid: what a voxel shows"): a sketch-free solid
//! (the trivial field) in a cube of side n + 2·margin, the n² middle of its middle z section
//! (away from the cube's faces, where neighbourhoods are clamped, as a config's
//! `parameterize.margin` keeps the object away from them) synthesized and shown as the
//! reconstruct node shows a cut, once with the paper's mean colours
//! (`synthesize.neighbourhood_colour = "mean"`, `reconstruct.colour = "mean"`) and once with
//! the defaults (`"plane"`, `"facing"`), scored by `texsyn score`'s nearest-patch measures
//! (7×7 patches) against the exemplar. The section is n² pixels, so at n = 128 it has more
//! patch positions than a 128² exemplar and coverage can reach 1.
//!
//! Exemplars: wood2 layered across x (xy the image, zx transposed, yz not matched: the
//! setup of configs/solid_trivial.toml) and marble1 on all three planes (the untuned one,
//! written down before any tuning). Prints a Markdown table (BENCHMARKS.md, "Solid
//! sections") and writes `solid-section.png`: per exemplar, exemplar | mean | plane + facing.
//!
//! ```text
//! cargo run --release -p texsyn-bench --example solid_section_quality -- [OUT_DIR]
//! ```
//!
//! `SIZE` [128]: the section's side n; `MARGIN` [32]: voxels between it and the cube's faces.

mod common;
#[path = "../../tests/it/common/exemplars.rs"]
mod exemplars;
#[path = "../../tests/it/common/solid.rs"]
mod solid;

use common::env_or;
use exemplars::load_exemplar as load;
use glam::Vec3;
use solid::{transpose, trivial_cube};
use texsyn::image::Image;
use texsyn::image::patch_score::{ScoreParams, patch_score};
use texsyn::stages::analyse_exemplar::candidate_triples::{CandidateParams, analyse};
use texsyn::stages::reconstruct::solid_colour::{SolidColourRule, VoxelTriples};
use texsyn::stages::synthesize::solid::solid_synthesis::{
    MemoryBrickStore, NeighbourhoodColour, SolidParams, SolidSynthesis,
};

/// `tiles` (each `w × h` colours) side by side, every pixel `zoom`×`zoom`, 4 px gaps, rows of
/// tiles one under another.
fn save_rows(path: &std::path::Path, rows: &[Vec<Image>], zoom: u32) {
    let gap = 4;
    let width = |r: &Vec<Image>| r.iter().map(|t| t.width * zoom + gap).sum::<u32>() - gap;
    let w = rows.iter().map(width).max().unwrap();
    let row_h = |r: &Vec<Image>| r.iter().map(|t| t.height).max().unwrap() * zoom;
    let h = rows.iter().map(|r| row_h(r) + gap).sum::<u32>() - gap;
    let mut img = image::RgbImage::from_pixel(w, h, image::Rgb([255, 255, 255]));
    let mut y0 = 0;
    for r in rows {
        let mut x0 = 0;
        for t in r {
            for y in 0..t.height * zoom {
                for x in 0..t.width * zoom {
                    let c = t.pixels[((y / zoom) * t.width + x / zoom) as usize];
                    let c = [c[0], c[1], c[2]].map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
                    img.put_pixel(x0 + x, y0 + y, image::Rgb(c));
                }
            }
            x0 += t.width * zoom + gap;
        }
        y0 += row_h(r) + gap;
    }
    img.save(path).unwrap();
}

fn main() {
    let dir = common::out_dir();
    let n: u32 = env_or("SIZE", 128);
    let margin: u32 = env_or("MARGIN", 32);
    println!(
        "| exemplar | neighbourhoods, colour | ratio | coverage | largest offset | gradient ratio | patches | seconds |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|");
    let mut picture = Vec::new();
    for (name, layers) in [("wood2.png", true), ("marble1.png", false)] {
        let img = load(name);
        let a = if layers {
            let p = CandidateParams {
                plane_weights: [1.0, 0.0, 1.0],
                ..Default::default()
            };
            let tr = transpose(&img);
            analyse([img.view(), img.view(), tr.view()], &p).unwrap()
        } else {
            analyse([img.view(); 3], &CandidateParams::default()).unwrap()
        };
        let mut row = vec![img.clone()];
        for (neighbourhoods, rule, what) in [
            (
                NeighbourhoodColour::Mean,
                SolidColourRule::Mean,
                "mean, mean (the paper's)",
            ),
            (
                NeighbourhoodColour::Plane,
                SolidColourRule::Facing,
                "plane, facing (default)",
            ),
        ] {
            let (vol, field) = trivial_cube(n + 2 * margin);
            let params = SolidParams {
                neighbourhood_colour: neighbourhoods,
                ..SolidParams::paper(4)
            };
            let s = SolidSynthesis::new(a.as_ref(), &field, vol, params).unwrap();
            let (lo, c) = (margin as i32, (n + 2 * margin) as i32 / 2);
            // Row r at y = lo + r: the exemplar's frame (image y along the local y axis).
            let voxels: Vec<[i32; 3]> = (lo..lo + n as i32)
                .flat_map(|y| (lo..lo + n as i32).map(move |x| [x, y, c]))
                .collect();
            let t = std::time::Instant::now();
            let (triples, _) = s
                .synthesize_voxels(&voxels, &MemoryBrickStore::new())
                .unwrap();
            let seconds = t.elapsed().as_secs_f64();
            let mut shown = VoxelTriples::new(&field, &vol, rule);
            shown.add(&voxels, &triples, a.as_ref());
            let mut section = Image::new(n, n);
            for (i, v) in voxels.iter().enumerate() {
                let c = shown.colour((*v).into(), Some(Vec3::Z)).unwrap();
                section.pixels[i] = [c[0], c[1], c[2], 1.0];
            }
            let sc = patch_score(section.view(), img.view(), &ScoreParams::default()).unwrap();
            println!(
                "| {name} | {what} | {:.3} | {:.3} | {:.3} | {:.3} | {} | {seconds:.1} |",
                sc.ratio, sc.coverage, sc.largest_offset, sc.gradient_ratio, sc.queries
            );
            row.push(section);
        }
        picture.push(row);
    }
    let path = dir.join("solid-section.png");
    save_rows(&path, &picture, 2);
    println!("\nwrote {}", path.display());
}
