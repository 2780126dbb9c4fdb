//! Meshes that no method can work with get a message that says what is wrong with the mesh,
//! not a doubled prefix or a scale printed as "0.0000".

use crate::common;
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

/// A mesh a method can work with despite its defects is textured, with a warning naming them
/// (one check for every method; geometry_images refuses such meshes precisely).
#[test]
fn defects_a_method_can_live_with_are_named_in_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = dir.path().join("dup.off");
    // A tetrahedron with one face repeated in the other orientation.
    std::fs::write(
        &mesh,
        format!("OFF\n4 5 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n{TETRA_FACES}3 2 1 0\n"),
    )
    .unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_texsyn"))
        .args(["run", "configs/demo.toml", "--set"])
        .arg(format!("inputs.mesh=\"{}\"", mesh.display()))
        .args([
            "--set",
            "parameterize.scale=20",
            "--set",
            "reconstruct.atlas_size=256",
        ])
        .args(["--set", "reconstruct.preview_size=32", "--cache"])
        .arg(dir.path().join("cache"))
        .arg("--out")
        .arg(dir.path().join("out"))
        .current_dir(repo())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("1 duplicate triangle") && err.contains("non-manifold edge"),
        "{err}"
    );
}
