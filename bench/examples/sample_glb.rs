//! Writes `sample.glb`, a tetrahedron with everything the glb writer can put in a file
//! (normals, tangents, two texcoord sets, vertex colours, a custom `_DISPLACEMENT` attribute,
//! base colour, normal and metallic-roughness textures), for checking the writer with the
//! Khronos glTF validator (https://github.khronos.org/glTF-Validator/):
//!
//! ```text
//! cargo run --release -p texsyn-bench --example sample_glb -- [OUT_DIR]
//! ```
//!
//! `OUT_DIR` defaults to the system temp directory. The mesh is the one the glb writer's unit
//! tests check (core/src/export/glb/sample.rs).

mod common;
// The sample module names the glb types as `super::…`: they are imported here.
#[path = "../../core/src/export/glb/sample.rs"]
mod sample;

use texsyn::export::glb::{GlbAttribute, GlbMaterial, GlbMesh, write_glb};

fn main() {
    let path = common::out_dir().join("sample.glb");
    let bytes = write_glb(&sample::sample_mesh());
    std::fs::write(&path, &bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    println!("wrote {} ({} bytes)", path.display(), bytes.len());
}
