//! Meshes for geometry images (Lai et al. 2005 §3, Gu et al. 2002). Shared by
//! tests/it/geometry_image.rs and bench/'s `geometry_image_previews` example.
#![allow(dead_code)] // each user takes a different part

use texsyn::geom::Mesh;

/// A mesh of the repository, `rel` from its root (e.g. `tests/data/meshes/knot.off`).
pub fn load_mesh(rel: &str) -> Mesh {
    // The root crate's folder for the tests, `bench/`'s parent for the examples.
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let root = here
        .ancestors()
        .find(|d| d.join(rel).exists())
        .unwrap_or(here);
    texsyn::geom::io::read_mesh(&root.join(rel)).unwrap()
}

/// The knot with the triangles near two of its vertices removed: genus 1 with two boundary
/// loops, so the cut must both open the handle and reach both loops.
pub fn holed_knot() -> Mesh {
    let k = load_mesh("tests/data/meshes/knot.off");
    let centres = [k.positions[0], k.positions[k.vertex_count() / 2]];
    let r = 3.0 * k.mean_edge_length();
    let tris = k
        .triangles
        .iter()
        .copied()
        .filter(|t| {
            !centres.iter().any(|c| {
                t.iter()
                    .all(|&v| (k.positions[v as usize] - *c).length() < r)
            })
        })
        .collect();
    Mesh::new(k.positions.clone(), tris)
}
