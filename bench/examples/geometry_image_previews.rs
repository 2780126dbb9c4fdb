//! Geometry images (Lai et al. 2005 §3, Gu et al. 2002) of real meshes, timed and drawn: for
//! each mesh it builds the geometry image, prints its vertex count, genus, build time, cut
//! (length and edges), stretch before and after stretch reduction (and the iterations used)
//! and the flipped triangles, and writes
//!
//! - `gi_<mesh>.png`: the grid of samples triangulated (the pipeline's `grid_mesh`, mates
//!   merged) and rendered from three sides;
//! - `gi_<mesh>_uv.png`: the cut mesh in the square, edges grey and the border red.
//!
//! The meshes: configs/assets/cow.obj, then `knot.off`, `elephant.off`, `mushroom.off` and
//! `refined_elephant.off` from the mesh directory where they exist, and the knot with two holes
//! of tests/it/geometry_image.rs (third).
//!
//! ```text
//! cargo run --release -p texsyn-bench --example geometry_image_previews -- [OUT_DIR]
//! ```
//!
//! `OUT_DIR` defaults to the system temp directory. Environment:
//! - `TEXSYN_GI_MESHES`: the mesh directory (default tests/data/meshes);
//! - `TEXSYN_GI_SIZE`: the image's side (default 257, the paper's);
//! - `TEXSYN_GI_EXTREMITY`: extra cuts to extremities (default 0);
//! - `TEXSYN_GI_STRETCH`: stretch-reduction iterations (default 8).

mod common;
#[path = "../../tests/it/common/geometry_image.rs"]
mod geometry_image;

use common::env_or;
use geometry_image::holed_knot;
use glam::{Vec2, Vec3};
use std::path::{Path, PathBuf};
use texsyn::geom::Mesh;
use texsyn::geom::half_edge::HalfEdgeMesh;
use texsyn::stages::parameterize::geometry_image::{
    GeometryImageBuild, GeometryImageParams, build_geometry_image,
};
use texsyn::stages::reconstruct::displacement::grid_mesh;

fn main() {
    let root = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let dir = std::env::var("TEXSYN_GI_MESHES")
        .map(PathBuf::from)
        .unwrap_or(root.join("tests/data/meshes"));
    let out = common::out_dir();
    let size: u32 = env_or("TEXSYN_GI_SIZE", 257);
    let extremity_cuts: u32 = env_or("TEXSYN_GI_EXTREMITY", 0);
    let stretch_iterations: u32 = env_or("TEXSYN_GI_STRETCH", 8);
    let mut files: Vec<PathBuf> = vec![root.join("configs/assets/cow.obj")];
    for name in [
        "knot.off",
        "elephant.off",
        "mushroom.off",
        "refined_elephant.off",
    ] {
        if dir.join(name).exists() {
            files.push(dir.join(name));
        }
    }
    let mut inputs: Vec<(String, Mesh)> = files
        .iter()
        .map(|f| {
            let stem = f.file_stem().unwrap().to_string_lossy().to_string();
            (stem, texsyn::geom::io::read_mesh(f).unwrap())
        })
        .collect();
    inputs.insert(
        2.min(inputs.len()),
        ("holed_knot".to_string(), holed_knot()),
    );
    for (stem, m) in inputs {
        let p = GeometryImageParams {
            size,
            extremity_cuts,
            stretch_iterations,
            ..Default::default()
        };
        let t0 = std::time::Instant::now();
        let b = build_geometry_image(&m, &p, &|_| {}).unwrap();
        let dt = t0.elapsed();
        println!(
            "{stem}: {} vertices, genus {}, {:.3} s, cut length {:.4} ({} edges), stretch {:.3} -> {:.3} ({} iterations), flipped {}",
            m.vertex_count(),
            b.genus,
            dt.as_secs_f64(),
            b.cut_length,
            b.cut_edges.len(),
            b.initial_stretch,
            b.stretch,
            b.stretch_iterations_used,
            b.flipped_triangles
        );
        let (grid, _) = grid_mesh(&b.image, &b.image.positions);
        let img = texsyn::render::render_views(
            &grid,
            &texsyn::render::ConstantShader(Vec3::splat(0.8)),
            &texsyn::render::ViewOptions::default(),
        );
        img.save(out.join(format!("gi_{stem}.png"))).unwrap();
        save_uv_plot(&b, &out.join(format!("gi_{stem}_uv.png")));
    }
    println!("wrote gi_*.png to {}", out.display());
}

/// Draws the disk's parameter-domain edges (grey) and its boundary (red) into a PNG.
fn save_uv_plot(b: &GeometryImageBuild, path: &Path) {
    let px = 1024u32;
    let n1 = (b.image.n - 1) as f32;
    let mut img = image::RgbImage::from_pixel(px, px, image::Rgb([255, 255, 255]));
    let to_px = |q: Vec2| {
        Vec2::new(
            q.x / n1 * (px - 1) as f32,
            (1.0 - q.y / n1) * (px - 1) as f32,
        )
    };
    let dhe = HalfEdgeMesh::new(&b.disk).unwrap();
    let mut line = |a: Vec2, c: Vec2, col: [u8; 3]| {
        let (pa, pc) = (to_px(a), to_px(c));
        let steps = ((pc - pa).length().ceil() as usize).max(1);
        for s in 0..=steps {
            let q = pa.lerp(pc, s as f32 / steps as f32);
            let (x, y) = (q.x.round() as i64, q.y.round() as i64);
            if x >= 0 && y >= 0 && x < px as i64 && y < px as i64 {
                img.put_pixel(x as u32, y as u32, image::Rgb(col));
            }
        }
    };
    for t in &b.disk.triangles {
        for k in 0..3 {
            line(
                b.disk_uv[t[k] as usize],
                b.disk_uv[t[(k + 1) % 3] as usize],
                [90, 90, 90],
            );
        }
    }
    for &h in &dhe.boundary_loops()[0] {
        line(
            b.disk_uv[dhe.origin(h) as usize],
            b.disk_uv[dhe.dest(h) as usize],
            [220, 0, 0],
        );
    }
    img.save(path).unwrap();
}
