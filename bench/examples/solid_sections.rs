//! Sections through a synthesized solid texture (on-demand brick synthesis from the candidate
//! triples of Dong et al. 2008, stages/synthesize/solid/solid_synthesis/), for looking at. Analyses an exemplar, synthesizes the middle z, x and y
//! sections of an n³ cube, prints the analysis time and per section its time and per-level
//! report, and writes (tag = `<exemplar>_<config>_<angle>`):
//!
//! - `solid_<tag>_z.png`, `_x.png`, `_y.png`: the three sections, each pixel doubled;
//! - `solid_<tag>_z_plane0.png` … `_plane2.png`: the z section as each plane's texel alone
//!   (and it prints the mean |xy − zx| texel difference: how much the planes disagree);
//! - with `LEVELS_DUMP`: `solid_<tag>_z_level<l>.png`, the coarser levels of the z section.
//!
//! ```text
//! cargo run --release -p texsyn-bench --example solid_sections -- [OUT_DIR]
//! ```
//!
//! `OUT_DIR` defaults to the system temp directory. Environment (defaults in brackets):
//! - `EXEMPLAR`: a file in tests/data/exemplars or an absolute path [wood2.png];
//! - `SIZE`: the cube's side n [64]; `LEVELS`: pyramid levels [4]; `K`: candidates [4];
//! - `CONFIG`: `same` (the exemplar on all three planes), `layers` (a solid layered across x:
//!   xy the exemplar, zx it transposed, yz not matched) or `layers3` (the same with the mean
//!   colour for yz) [same];
//! - `WEIGHTS`: the three planes' weights, e.g. `1,0,1`; `ANGLE`: the field's rotation about z
//!   in degrees [0];
//! - `SCHEME`: `dual` or `plain` [dual]; `PASSES`, `PASSES0`: correction passes of the finer
//!   levels and of the coarsest; `JITTER` [0]; `SEED` [0]; `TRILINEAR` and `NO_COHERENT`
//!   (set to turn on trilinear upsampling / turn off coherent candidates).

mod common;
#[path = "../../tests/it/common/exemplars.rs"]
mod exemplars;
#[path = "../../tests/it/common/solid.rs"]
mod solid;

use common::env_or;
use exemplars::load_exemplar as load;
use glam::Quat;
use solid::{cube, rotated_field, transpose};
use std::path::Path;
use texsyn::stages::analyse_exemplar::candidate_triples::{CandidateParams, analyse};
use texsyn::stages::synthesize::solid::solid_synthesis::{
    MemoryBrickStore, Scheme, SolidParams, SolidSynthesis, VoxelRequest,
};

/// Writes w×h colours as an RGB PNG, each pixel `zoom`×`zoom`.
fn write_png(path: &Path, px: &[[f32; 3]], w: u32, h: u32, zoom: u32) {
    let mut img = image::RgbImage::new(w * zoom, h * zoom);
    for y in 0..h * zoom {
        for x in 0..w * zoom {
            let c = px[((y / zoom) * w + x / zoom) as usize];
            img.put_pixel(
                x,
                y,
                image::Rgb(c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8)),
            );
        }
    }
    img.save(path).unwrap();
}

fn main() {
    let dir = common::out_dir();
    let name: String = env_or("EXEMPLAR", "wood2.png".to_string());
    let n: u32 = env_or("SIZE", 64);
    let levels: u32 = env_or("LEVELS", 4);
    let config: String = env_or("CONFIG", "same".to_string());
    let angle: f32 = env_or("ANGLE", 0.0);
    let img = load(&name);
    let mut cp = CandidateParams {
        levels,
        candidates: env_or("K", 4),
        ..Default::default()
    };
    if let Ok(w) = std::env::var("WEIGHTS") {
        let v: Vec<f32> = w.split(',').map(|x| x.parse().unwrap()).collect();
        cp.plane_weights = [v[0], v[1], v[2]];
    }
    let t = std::time::Instant::now();
    let a = if config == "layers" {
        // A solid layered across x: xy shows the stripes, zx the transposed stripes, yz is
        // not matched.
        let tr = transpose(&img);
        cp.plane_weights = [1.0, 0.0, 1.0];
        analyse([img.view(), img.view(), tr.view()], &cp).unwrap()
    } else if config == "layers3" {
        // The same, with a constant image (the mean colour) for yz: fully consistent.
        let tr = transpose(&img);
        let mut flat = img.clone();
        let n = img.pixels.len() as f32;
        let mean = img
            .pixels
            .iter()
            .fold([0.0f32; 4], |a, p| std::array::from_fn(|c| a[c] + p[c] / n));
        flat.pixels.iter_mut().for_each(|p| *p = mean);
        analyse([img.view(), flat.view(), tr.view()], &cp).unwrap()
    } else {
        analyse([img.view(); 3], &cp).unwrap()
    };
    println!(
        "analysis of {name} ({}×{}): {:.2} s",
        img.width,
        img.height,
        t.elapsed().as_secs_f64()
    );
    let vol = cube(n);
    let q = Quat::from_rotation_z(angle.to_radians());
    let field = rotated_field(&vol, q);
    let mut params = SolidParams::paper(levels);
    params.seed = env_or("SEED", 0);
    for l in params.levels.iter_mut().skip(1) {
        l.jitter = env_or("JITTER", 0.0);
        if std::env::var("TRILINEAR").is_ok() {
            l.trilinear = true;
        }
        l.passes = env_or("PASSES", l.passes);
    }
    params.levels[0].passes = env_or("PASSES0", params.levels[0].passes);
    params.coherent_candidates = std::env::var("NO_COHERENT").is_err();
    if env_or("SCHEME", "dual".to_string()) == "plain" {
        params = params.with_scheme(Scheme::Plain);
    }
    let s = SolidSynthesis::new(a.as_ref(), &field, vol, params).unwrap();
    let store = MemoryBrickStore::new();
    let stem = Path::new(&name)
        .file_stem()
        .unwrap()
        .to_string_lossy()
        .to_string();
    let tag = format!("{stem}_{config}_{angle}");
    let png = |what: &str| dir.join(format!("solid_{tag}_{what}.png"));
    let c = n as i32 / 2;
    for (axis, req) in [
        (
            "z",
            VoxelRequest::from_box([0, 0, c], [n as i32, n as i32, c + 1]),
        ),
        (
            "x",
            VoxelRequest::from_box([c, 0, 0], [c + 1, n as i32, n as i32]),
        ),
        (
            "y",
            VoxelRequest::from_box([0, c, 0], [n as i32, c + 1, n as i32]),
        ),
    ] {
        let t = std::time::Instant::now();
        let rep = s.synthesize(&req, &store).unwrap();
        println!("section {axis}: {:.2} s", t.elapsed().as_secs_f64());
        for l in &rep.levels {
            println!("  {l:?}");
        }
        let mut px = vec![];
        for i in 0..n as i32 {
            for j in 0..n as i32 {
                let v = match axis {
                    "z" => [j, i, c],
                    "x" => [c, j, i],
                    _ => [i, c, j],
                };
                px.push(s.colour_at(&store, v).unwrap());
            }
        }
        write_png(&png(axis), &px, n, n, 2);
        if axis == "z" {
            // Each plane's texel alone, and how much the three disagree.
            let r = a.as_ref();
            let mut spread = 0.0f64;
            for p in 0..3 {
                let mut px = vec![];
                for i in 0..n as i32 {
                    for j in 0..n as i32 {
                        let t = s.triple_at(&store, levels, [j, i, c]).unwrap();
                        let col = r.texel(levels as usize - 1, r.image_of(p), t.c[p]);
                        if p == 0 {
                            let o = r.texel(levels as usize - 1, r.image_of(2), t.c[2]);
                            spread += (0..3).map(|k| (col[k] - o[k]).abs() as f64).sum::<f64>();
                        }
                        px.push(col);
                    }
                }
                write_png(&png(&format!("z_plane{p}")), &px, n, n, 2);
            }
            println!(
                "mean |xy - zx| texel difference: {:.4}",
                spread / (n * n) as f64 / 3.0
            );
        }
        if axis == "z" && std::env::var("LEVELS_DUMP").is_ok() {
            for level in 1..levels {
                let shift = levels - level;
                let m = n as i32 >> shift;
                let mut px = vec![];
                for i in 0..m {
                    for j in 0..m {
                        let t = s.triple_at(&store, level, [j, i, c >> shift]).unwrap();
                        px.push(s.colour(level, &t));
                    }
                }
                write_png(
                    &png(&format!("z_level{level}")),
                    &px,
                    m as u32,
                    m as u32,
                    2 << shift,
                );
            }
        }
    }
    println!("wrote solid_{tag}_*.png to {}", dir.display());
}
