//! The geometry-image method end to end: mated texels stay identical through synthesis, the
//! output of a closed input is closed and manifold with no flipped face, results do not depend
//! on the thread count, a density change reruns only what depends on it, and bad inputs are
//! named.

use crate::common;
use common::{
    artifact, assert_runs_fail_naming, assert_same_hashes_on_any_thread_count, err, materialized,
    plan_config, ran, repo, run_config,
};
use std::collections::HashMap;
use texsyn::artifact::Format;
use texsyn::geom::geometry_image::{GeometryImage, TexelImage};
use texsyn::pipeline::RunResult;
use texsyn_core::math::PureMath;

/// Small and quick: a 65² geometry image, 4 orientations, tiny previews.
const SMALL: &[&str] = &[
    "parameterize.size=65",
    "analyse_exemplar.orientations=4",
    "analyse_exemplar.scales=3",
    "field.density_offset=0.0",
    "reconstruct.preview_size=32",
];

fn run(config: &str, sets: &[&str], cache: &std::path::Path) -> Result<RunResult, String> {
    run_config(&repo().join("configs").join(config), SMALL, sets, cache)
}

/// Reads a binary little-endian PLY written by texsyn: positions and triangles.
fn read_ply(bytes: &[u8]) -> texsyn::geom::Mesh {
    texsyn::geom::io::read_mesh_bytes(std::path::Path::new("relief.ply"), bytes).unwrap()
}

#[test]
fn a_genus_one_input_gives_a_closed_manifold_relief_with_mates_identical_and_no_flips() {
    let cache = tempfile::tempdir().unwrap();
    // The knot has genus 1: its cut opens a handle, so the square's sides are mated in pairs.
    let r = run(
        "relief_cow.toml",
        &["inputs.mesh=assets/knot.off", "analyse_exemplar.scales=3"],
        cache.path(),
    )
    .unwrap();
    let gi = GeometryImage::view(artifact(&r, "parameterize")).unwrap();
    let texels = TexelImage::view(artifact(&r, "synthesize")).unwrap();
    let groups = gi.mate_groups();
    assert!(!groups.is_empty());
    let n = gi.n;
    for g in &groups {
        let first = texels.texel(g[0] % n, g[0] / n).to_vec();
        for &k in g {
            assert_eq!(texels.texel(k % n, k / n), &first[..], "mate group {g:?}");
            assert_eq!(gi.positions[k as usize], gi.positions[g[0] as usize]);
        }
    }
    // The exported mesh: every edge has exactly two faces (closed, manifold), consistently
    // oriented (each directed edge once).
    let out = materialized(&r, "reconstruct");
    let mesh = read_ply(&std::fs::read(out.path().join("relief.ply")).unwrap());
    let mut undirected: HashMap<(u32, u32), u32> = HashMap::new();
    let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *undirected.entry((a.min(b), a.max(b))).or_default() += 1;
            *directed.entry((a, b)).or_default() += 1;
        }
    }
    let open = undirected.values().filter(|&&c| c != 2).count();
    assert_eq!(open, 0, "{open} edges without exactly two faces");
    assert!(
        directed.values().all(|&c| c == 1),
        "inconsistent orientation"
    );
    let he = texsyn::geom::half_edge::HalfEdgeMesh::new(&mesh).expect("manifold");
    assert_eq!(he.components().len(), 1);
    assert_eq!(
        he.components()[0].genus,
        1,
        "the relief keeps the knot's genus"
    );

    // No face turned by more than the flip threshold against the same triangle on the
    // undisplaced surface (vertices are numbered by mate group either way).
    let undisplaced = texsyn::stages::reconstruct::displacement::grid_mesh(&gi, &gi.positions).0;
    assert_eq!(undisplaced.positions.len(), mesh.positions.len());
    let cos_limit = 150f32.to_radians().cos_pure();
    let normal = |p: &[glam::Vec3], t: &[u32; 3]| {
        (p[t[1] as usize] - p[t[0] as usize])
            .cross(p[t[2] as usize] - p[t[0] as usize])
            .normalize_or_zero()
    };
    for (f, t) in mesh.triangles.iter().enumerate() {
        let n0 = normal(&undisplaced.positions, t);
        let n1 = normal(&mesh.positions, t);
        if n0 != glam::Vec3::ZERO {
            assert!(
                n0.dot(n1) >= cos_limit - 1e-4,
                "face {f} {t:?} flipped: {n0} {n1} {:?} {:?}",
                t.map(|v| undisplaced.positions[v as usize]),
                t.map(|v| mesh.positions[v as usize])
            );
        }
    }
}

#[test]
fn genus_zero_inputs_and_the_tetrahedron_give_closed_manifold_reliefs() {
    // A sphere's cut is a path: the square's border folds back on itself at both of its tips,
    // where a relief mesh can get a folded pair of triangles (a non-manifold edge, two
    // boundary edges) and unused tip samples. A tetrahedron's cut must be more than one edge,
    // which would open nothing.
    let dir = tempfile::tempdir().unwrap();
    let tet = dir.path().join("tetrahedron.off");
    std::fs::write(
        &tet,
        "OFF\n4 4 0\n1 1 1\n1 -1 -1\n-1 1 -1\n-1 -1 1\n3 0 1 2\n3 0 3 1\n3 0 2 3\n3 1 3 2\n",
    )
    .unwrap();
    for mesh in ["assets/cow.obj".to_string(), tet.display().to_string()] {
        let cache = tempfile::tempdir().unwrap();
        let r = run(
            "relief_cow.toml",
            &[
                &format!("inputs.mesh={mesh:?}"),
                "analyse_exemplar.scales=3",
            ],
            cache.path(),
        )
        .unwrap_or_else(|e| panic!("{mesh}: {e}"));
        let out = materialized(&r, "reconstruct");
        let m = read_ply(&std::fs::read(out.path().join("relief.ply")).unwrap());
        let h = texsyn::geom::mesh_check::mesh_health(&m);
        assert!(h.is_closed_manifold(), "{mesh}: {}", h.summary());
        let he = texsyn::geom::half_edge::HalfEdgeMesh::new(&m).expect("manifold");
        assert_eq!(he.components().len(), 1, "{mesh}");
        assert_eq!(he.components()[0].genus, 0, "{mesh}");
    }
    // A mesh whose corners all coincide has nothing to map: a clear error, not a cut bug.
    let flat = dir.path().join("point.off");
    std::fs::write(
        &flat,
        "OFF\n4 4 0\n1 1 1\n1 1 1\n1 1 1\n1 1 1\n3 0 1 2\n3 0 3 1\n3 0 2 3\n3 1 3 2\n",
    )
    .unwrap();
    let cache = tempfile::tempdir().unwrap();
    let e = err(run(
        "relief_cow.toml",
        &[&format!("inputs.mesh={:?}", flat.display().to_string())],
        cache.path(),
    ));
    assert!(e.contains("no area") && !e.contains("internal"), "{e}");
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    assert_same_hashes_on_any_thread_count(|cache| run("relief_cow.toml", &[], cache).unwrap());
}

#[test]
fn a_new_density_reruns_neither_parameterization_nor_extraction_nor_analysis() {
    let cache = tempfile::tempdir().unwrap();
    run("relief_cow.toml", &[], cache.path()).unwrap();
    let r = run(
        "relief_cow.toml",
        &["field.density_offset=0.5"],
        cache.path(),
    )
    .unwrap();
    assert_eq!(ran(&r), vec!["field", "synthesize", "reconstruct"]);
}

#[test]
fn bad_inputs_are_named() {
    assert_runs_fail_naming(
        run,
        &[
            // A colour image is read by its luma, unless only grey ones are allowed.
            (
                "relief_cow.toml",
                &["inputs.sample=assets/wood1.png", "extract.strict_grey=true"],
                &["wood1.png", "not grey"],
            ),
            // A sample region that misses the sample mesh.
            (
                "dragon_knot.toml",
                &["extract.region={ shape = \"sphere\", center = [0.0, 0.0, 0.0], radius = 1.0 }"],
                &["holds no triangles"],
            ),
            // A non-manifold input (pig.stl has a vertex where two fans meet).
            (
                "relief_cow.toml",
                &["inputs.mesh=../tests/data/meshes/pig.stl"],
                &["non-manifold", "vertex"],
            ),
            // An image sample must be read as a height field.
            (
                "relief_cow.toml",
                &["extract.method=\"planar\""],
                &["extract.method"],
            ),
        ],
    );
    // A sample too small for the appearance synthesizer (the default): the error names its size
    // and the least one.
    let cache = tempfile::tempdir().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let image_of = |side: u32, name: &str| {
        let path = dir.path().join(name);
        image::GrayImage::from_fn(side, side, |x, y| {
            image::Luma([((x * 40 + y * 7 + x * y) % 255) as u8])
        })
        .save(&path)
        .unwrap();
        format!("inputs.sample={}", path.display())
    };
    let tiny = image_of(6, "tiny.png");
    let e = err(run("relief_cow.toml", &[&tiny], cache.path()));
    assert!(
        e.contains("tiny.png") && e.contains("6×6") && e.contains("8 to"),
        "{e}"
    );
    // A sample too small for the template synthesizer's variants (each level of each variant
    // needs candidates for its templates) is refused by it, naming the size it needs, and
    // synthesized by the appearance synthesizer, which needs only its own stack.
    let small = image_of(24, "small.png");
    let template = "synthesize.algorithm=\"template\"";
    let e = err(run("relief_cow.toml", &[&small, template], cache.path()));
    assert!(e.contains("small.png") && e.contains("at least"), "{e}");
    run("relief_cow.toml", &[&small], cache.path()).expect("the appearance synthesizer runs");
}

/// The DAG of a config (nothing runs), or the error a user would see.
fn plan(config: &str, sets: &[&str]) -> Result<texsyn::methods::Plan, String> {
    plan_config(&repo().join("configs").join(config), SMALL, sets)
}

#[test]
fn the_cut_node_grid_follows_the_synthesis_levels_and_coupled_values_are_named() {
    // The parameterization's coarse levels are the synthesis's levels, not a key of their own.
    let p = plan("relief_cow.toml", &["analyse_exemplar.levels=2"]).unwrap();
    let i = p.dag.node_index("parameterize").unwrap();
    assert_eq!(p.dag.nodes[i].params_json["coarse_levels"], 2);
    let e = plan("relief_cow.toml", &["parameterize.coarse_levels=3"])
        .err()
        .unwrap();
    assert!(
        e.contains("parameterize.coarse_levels") && e.contains("analyse_exemplar.levels"),
        "{e}"
    );
    // Levels the geometry image is too small for: both keys are named.
    let e = plan(
        "relief_cow.toml",
        &["parameterize.size=9", "analyse_exemplar.levels=4"],
    )
    .err()
    .unwrap();
    assert!(
        e.contains("analyse_exemplar.levels") && e.contains("parameterize.size >= 17"),
        "{e}"
    );
    assert!(
        plan(
            "relief_cow.toml",
            &["parameterize.size=9", "analyse_exemplar.levels=3"]
        )
        .is_ok()
    );
    // A mesh sample's size is checked against the synthesizer before anything runs: the
    // template synthesizer's variants need far more texels than the appearance synthesizer.
    let template = "synthesize.algorithm=\"template\"";
    let e = plan("dragon_knot.toml", &["extract.size=32", template])
        .err()
        .unwrap();
    assert!(
        e.contains("extract.size") && e.contains("analyse_exemplar") && e.contains("at least"),
        "{e}"
    );
    assert!(plan("dragon_knot.toml", &["extract.size=32"]).is_ok());
}
