//! The graph-matching method end to end: its outputs, determinism, what a rerun recomputes, and
//! the errors a user meets before any work starts.

use crate::common;
use common::{
    artifact, assert_runs_fail_naming, assert_same_hashes_on_any_thread_count, materialized, ran,
    repo, run_config,
};
use texsyn::artifact::Format;
use texsyn::pipeline::RunResult;
use texsyn::stages::parameterize::sqrt2_subdivision::Sqrt2Hierarchy;
use texsyn::stages::synthesize::graph_matching::GraphMatching;

/// Small: a coarse scale (about 12,000 vertices at the finest level, in three levels), no
/// pre-subdivision, the paper's region and tiny previews.
const SMALL: &[&str] = &[
    "parameterize.scale=90",
    "parameterize.area_factor=0",
    "synthesize.region=3",
    "reconstruct.preview_size=48",
    "reconstruct.atlas_size=1024",
];

fn run(config: &str, sets: &[&str], cache: &std::path::Path) -> Result<RunResult, String> {
    run_config(&repo().join("configs").join(config), SMALL, sets, cache)
}

fn hierarchy(r: &RunResult) -> Sqrt2Hierarchy {
    Sqrt2Hierarchy::view(artifact(r, "parameterize")).unwrap()
}

#[test]
fn outputs_are_the_finest_level_coloured_and_the_same_for_any_thread_count() {
    assert_same_hashes_on_any_thread_count(|cache| run("graph_matching.toml", &[], cache).unwrap());
    // Exact search is the part that runs in parallel (the texel scan).
    assert_same_hashes_on_any_thread_count(|cache| {
        run(
            "graph_matching_open.toml",
            &["synthesize.search=\"exact\"", "parameterize.scale=40"],
            cache,
        )
        .unwrap()
    });
    let cache = tempfile::tempdir().unwrap();
    let r = run(
        "graph_matching.toml",
        &["reconstruct.level_previews=true"],
        cache.path(),
    )
    .unwrap();
    let h = hierarchy(&r);
    assert!(h.levels() >= 2, "scale 90 subdivides the cow");
    let finest = *h.level_vertices.last().unwrap() as usize;
    let out = materialized(&r, "reconstruct");
    let ply = std::fs::read(out.path().join("textured.ply")).unwrap();
    let header = String::from_utf8_lossy(&ply[..200]).to_string();
    assert!(
        header.contains(&format!("element vertex {finest}\n")),
        "{header}"
    );
    for f in [
        "textured.glb",
        "preview.png",
        "textured_atlas.png",
        "textured.mtl",
    ] {
        assert!(out.path().join(f).is_file(), "{f}");
    }
    // The user's own mesh gets the baked atlas: the OBJ has the input's vertices, in order.
    let input = texsyn::geom::io::read_mesh(&repo().join("configs/assets/cow.obj")).unwrap();
    let obj = texsyn::geom::io::read_mesh(&out.path().join("textured.obj")).unwrap();
    assert_eq!(obj.positions, input.positions);
    assert_eq!(obj.triangles.len(), input.triangles.len());
    let mtl = std::fs::read_to_string(out.path().join("textured.mtl")).unwrap();
    assert!(mtl.contains("map_Kd textured_atlas.png"), "{mtl}");
    // Without an atlas, textured.glb is the vertex-coloured finest level and no OBJ is written.
    let r0 = run(
        "graph_matching.toml",
        &["reconstruct.atlas_size=0"],
        cache.path(),
    )
    .unwrap();
    let out0 = materialized(&r0, "reconstruct");
    assert!(!out0.path().join("textured.obj").exists());
    assert!(out0.path().join("textured.glb").is_file());
    for l in 0..h.levels() {
        assert!(out.path().join(format!("level_{l:02}.png")).is_file());
    }
    // Every vertex got its colour from a texel, and the graph cut copied more than the matched
    // vertex (with transfer = "vertex" there would be exactly one per match).
    let g = GraphMatching::view(artifact(&r, "synthesize")).unwrap();
    assert_eq!(g.colours.len(), finest);
    assert!(
        g.stats.transferred as f64 > 1.5 * g.stats.matches as f64,
        "{:?}",
        g.stats
    );
    // wood1.png is 96×96: every source texel is inside it.
    assert!(
        g.sources
            .iter()
            .all(|s| (0.0..96.0).contains(&s[0]) && (0.0..96.0).contains(&s[1])),
        "a source outside the exemplar"
    );
}

#[test]
fn a_new_seed_reruns_synthesis_and_export_only() {
    let cache = tempfile::tempdir().unwrap();
    run("graph_matching.toml", &[], cache.path()).unwrap();
    let r = run("graph_matching.toml", &["synthesize.seed=9"], cache.path()).unwrap();
    assert_eq!(ran(&r), vec!["synthesize", "reconstruct"]);
    // A new key reruns the field (and what follows), not the subdivision or the stack.
    let r = run(
        "graph_matching.toml",
        &["field.keys=[{ vertex = 5, direction = [1, 0, 0] }]"],
        cache.path(),
    )
    .unwrap();
    assert_eq!(
        ran(&r),
        vec!["field.keys", "field", "synthesize", "reconstruct"]
    );
    // A rotation is the field's alone; a sink is checked on the input mesh too.
    let r = run("graph_matching.toml", &["field.rotation=45"], cache.path()).unwrap();
    assert_eq!(ran(&r), vec!["field", "synthesize", "reconstruct"]);
    let r = run(
        "graph_matching.toml",
        &["field.sinks=[{ at = [0, 0, 1] }]"],
        cache.path(),
    )
    .unwrap();
    assert_eq!(
        ran(&r),
        vec!["field.keys", "field", "synthesize", "reconstruct"]
    );
}

/// The keys of existing configs' nodes stay as they were: sinks, sources and rotation at their
/// defaults add nothing to the field nodes' canonical parameter bytes (so no lock changes),
/// and a rotation does.
#[test]
fn sinks_sources_and_rotation_at_their_defaults_leave_the_field_keys_as_they_were() {
    use texsyn::artifact::canonical_bytes;
    use texsyn::stages::field::sweep_field::SweepFieldParams;
    let p = SweepFieldParams::default();
    let without = (p.keys.clone(), p.axis, p.tolerance, p.max_passes);
    assert_eq!(canonical_bytes(&p), canonical_bytes(&without));
    assert_eq!(canonical_bytes(&p.key_points()), canonical_bytes(&p.keys));
    let turned = SweepFieldParams {
        rotation: 10.0,
        ..p.clone()
    };
    assert_ne!(canonical_bytes(&turned), canonical_bytes(&without));
}

#[test]
fn a_mesh_finer_than_the_texture_is_used_as_it_is() {
    // Table 1's donkey: scale 30 against 1/ē = 110. Here the cow (ē ≈ 0.021) at scale 20.
    let cache = tempfile::tempdir().unwrap();
    let r = run(
        "graph_matching.toml",
        &["parameterize.scale=20", "parameterize.area_factor=0"],
        cache.path(),
    )
    .unwrap();
    let h = hierarchy(&r);
    assert_eq!(h.levels(), 1);
    assert_eq!(h.level_vertices, vec![2904]);
}

#[test]
fn open_meshes_and_displacement_run() {
    let cache = tempfile::tempdir().unwrap();
    let r = run("graph_matching_open.toml", &[], cache.path()).unwrap();
    assert!(hierarchy(&r).levels() >= 2);
    let r = run("graph_matching_displacement.toml", &[], cache.path()).unwrap();
    let out = materialized(&r, "reconstruct");
    for f in ["displaced.obj", "displaced.ply", "displaced_preview.png"] {
        assert!(out.path().join(f).is_file(), "{f}");
    }
}

#[test]
fn bad_inputs_are_named_before_synthesis() {
    assert_runs_fail_naming(
        run,
        &[
            (
                "graph_matching.toml",
                &["parameterize.scale=100000"],
                &["parameterize.scale", "vertices", "fits"],
            ),
            (
                "graph_matching.toml",
                &["synthesize.region=60"],
                &["synthesize.region", "96×96", "at most 48"],
            ),
            (
                "graph_matching.toml",
                &["field.keys=[{ vertex = 99999, direction = [0, 1, 0] }]"],
                &["field.keys[0]", "99999", "2904"],
            ),
            (
                "graph_matching.toml",
                &["synthesize.sigma=0"],
                &["synthesize.sigma"],
            ),
            (
                "graph_matching.toml",
                &["field.sinks=[{ vertex = 5000 }]"],
                &["field.sinks[0]", "5000", "2904"],
            ),
            (
                "graph_matching.toml",
                &[
                    "field.sinks=[{ vertex = 7 }]",
                    "field.sources=[{ vertex = 3 }, { vertex = 7 }]",
                ],
                &["field.sources[1]", "vertex 7", "also a sink"],
            ),
            (
                "graph_matching.toml",
                &["field.rotation=270"],
                &["field.rotation"],
            ),
        ],
    );
    // A wrong key is found before any other work: nothing but the imports is in the cache.
    // (A scale that is too fine is found by the subdivision, which builds levels until the
    // next would pass the budget, so that the scale it names is one that fits.)
    let cache = tempfile::tempdir().unwrap();
    for bad in [
        "field.keys=[{ vertex = 99999, direction = [0, 1, 0] }]",
        "field.sources=[{ vertex = 99999 }]",
    ] {
        let e = run("graph_matching.toml", &[bad], cache.path());
        assert!(e.is_err());
        // The cache's objects (its lock files, left by the imports, are not objects).
        let objects = common::cli::object_count(cache.path());
        assert!(
            objects <= 2,
            "{bad}: {objects} objects stored before the error"
        );
    }
}

/// `parameterize.scale = "auto"` (and no scale at all) follows jump maps' rule for graph
/// matching and feature-aligned texturing: the exemplar's width spans a quarter of the mesh's
/// bounding-box diagonal, so a mesh 1000× larger gets a scale 1000× smaller.
#[test]
fn auto_scale_spans_a_quarter_of_the_bounding_box_diagonal_at_any_size() {
    let dir = tempfile::tempdir().unwrap();
    for (config, mesh, exemplar) in [
        ("graph_matching.toml", "cow.obj", "wood1.png"),
        ("feature_aligned.toml", "fandisk.off", "brick.png"),
    ] {
        let assets = repo().join("configs/assets");
        let mesh = texsyn::geom::io::read_mesh(&assets.join(mesh)).unwrap();
        let (width, _) = image::image_dimensions(assets.join(exemplar)).unwrap();
        let mut scales = Vec::new();
        for (factor, given) in [(1.0f32, "\"auto\""), (1000.0, "")] {
            let mut big = mesh.clone();
            big.positions.iter_mut().for_each(|p| *p *= factor);
            let path = dir.path().join(format!("m{factor}.ply"));
            std::fs::write(&path, texsyn::geom::io::write_ply(&big, None)).unwrap();
            let mesh_set = format!("inputs.mesh={:?}", path.display().to_string());
            let scale_set = format!("parameterize.scale={given}");
            let sets: Vec<&str> = if given.is_empty() {
                vec![&mesh_set]
            } else {
                vec![&mesh_set, &scale_set]
            };
            let cfg = repo().join("configs").join(config);
            let plan = if given.is_empty() {
                // Without the key at all: the config's own scale line removed.
                let text = std::fs::read_to_string(&cfg).unwrap();
                let text: String = (text.lines())
                    .filter(|l| !l.trim_start().starts_with("scale"))
                    .map(|l| format!("{l}\n"))
                    .collect();
                let copy = dir.path().join(config);
                std::fs::write(
                    &copy,
                    text.replace("assets/", &format!("{}/", assets.display())),
                )
                .unwrap();
                common::plan_config(&copy, &[], &sets)
            } else {
                common::plan_config(&cfg, &[], &sets)
            };
            let plan = plan.unwrap();
            let node = plan
                .dag
                .nodes
                .iter()
                .find(|n| n.name == "parameterize")
                .unwrap();
            let scale = node.params_json["scale"].as_f64().unwrap() as f32;
            let (lo, hi) = big.bounds();
            let want = width as f32 / (0.25 * (hi - lo).length());
            assert!(
                (scale - want).abs() <= 1e-4 * want,
                "{config} at {factor}×: scale {scale}, want {want}"
            );
            scales.push(scale);
        }
        let ratio = scales[0] / scales[1];
        assert!((ratio - 1000.0).abs() < 0.1, "{config}: scales {scales:?}");
    }
}

/// A region that `synthesize.max_k` cuts below `region` texels is said, per mesh level, with
/// the `max_k` that would keep it whole; a `max_k` that cuts nothing says nothing.
#[test]
fn regions_cut_short_by_max_k_are_named_in_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let run_with = |max_k: &str| {
        let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_texsyn"));
        cmd.args(["run", "configs/graph_matching.toml"]);
        for s in SMALL.iter().copied().chain([max_k]) {
            cmd.args(["--set", s]);
        }
        let out = cmd
            .arg("--cache")
            .arg(dir.path().join("cache"))
            .arg("--out")
            .arg(dir.path().join("out"))
            .current_dir(repo())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{err}");
        err
    };
    let err = run_with("synthesize.max_k=1");
    assert!(
        err.contains("synthesize.max_k = 1") && err.contains("vertices wanted a region radius"),
        "{err}"
    );
    let err = run_with("synthesize.max_k=32");
    assert!(!err.contains("wanted a region radius"), "{err}");
}
