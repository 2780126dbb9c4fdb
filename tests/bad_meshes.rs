//! Meshes that no method can work with get a message that says what is wrong with the mesh
//! (issue 11, item 10), not a doubled prefix or a scale printed as "0.0000".

mod common;
use common::{err, repo, run_config};

fn run_demo_on(off: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let mesh = dir.path().join("m.off");
    std::fs::write(&mesh, off).unwrap();
    let set = format!("inputs.mesh=\"{}\"", mesh.display());
    err(run_config(
        &repo().join("configs/demo.toml"),
        &[],
        &[set.as_str()],
        &dir.path().join("cache"),
    ))
}

const TETRA_FACES: &str = "3 0 1 2\n3 0 2 3\n3 0 3 1\n3 1 3 2\n";

#[test]
fn a_mesh_whose_vertices_coincide_is_called_degenerate_once() {
    let e = run_demo_on(&format!(
        "OFF\n4 4 0\n0 0 0\n0 0 0\n0 0 0\n0 0 0\n{TETRA_FACES}"
    ));
    assert!(e.contains("degenerate"), "{e}");
    assert!(!e.contains("field: field:"), "{e}");
}

#[test]
fn coordinates_that_overflow_are_named_with_the_vertex() {
    let e = run_demo_on(&format!(
        "OFF\n4 4 0\n1e37 0 0\n0 1e37 0\n0 0 1e37\n0 0 0\n{TETRA_FACES}"
    ));
    assert!(
        e.contains("vertex 0") && e.contains("scale the mesh down"),
        "{e}"
    );
    assert!(!e.contains("0.0000"), "{e}");
}
