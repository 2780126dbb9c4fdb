//! The pipeline end to end on the demo config: incrementality, early cutoff, recovery from
//! damaged cache objects, determinism across thread counts, and the properties of the
//! jump-map artifacts that a wrong implementation would break.
#![allow(clippy::needless_range_loop, clippy::type_complexity)]

use crate::common;
use common::{artifact, assert_same_hashes_on_any_thread_count, ran, repo, run_config};
use std::path::{Path, PathBuf};
use texsyn::artifact::Format;
use texsyn::artifact::jump_maps::{JumpParameterization, TexelAddresses};
use texsyn::pipeline::{self, RunResult};

/// Small exports keep the tests fast; the algorithm nodes are the demo's own.
const FAST: &[&str] = &["reconstruct.atlas_size=1024", "reconstruct.preview_size=64"];

fn run(config: &Path, sets: &[&str], cache: &Path) -> RunResult {
    run_config(config, FAST, sets, cache).expect("run succeeds")
}

fn demo() -> PathBuf {
    repo().join("configs/demo.toml")
}

/// The demo run in a new, empty cache, and that cache (for further runs; the result's
/// artifacts are read from it).
fn fresh_demo() -> (tempfile::TempDir, RunResult) {
    let cache = tempfile::tempdir().unwrap();
    let r = run(&demo(), &[], cache.path());
    (cache, r)
}

#[test]
fn a_second_run_runs_nothing_and_a_new_seed_reruns_only_synthesis_and_reconstruction() {
    let (cache, first) = fresh_demo();
    assert_eq!(
        ran(&first).len(),
        first.reports.len(),
        "empty cache: everything runs"
    );
    let second = run(&demo(), &[], cache.path());
    assert!(ran(&second).is_empty(), "ran: {:?}", ran(&second));
    let seeded = run(&demo(), &["synthesize.seed=2"], cache.path());
    assert_eq!(ran(&seeded), vec!["synthesize", "reconstruct"]);
    // A different seed gives different coordinates.
    assert_ne!(
        artifact(&first, "synthesize").content_hash(),
        artifact(&seeded, "synthesize").content_hash()
    );
}

#[test]
fn a_new_field_anchor_reruns_the_surface_nodes_but_never_the_exemplar_analysis() {
    let (cache, _) = fresh_demo();
    let anchored = run(
        &demo(),
        &["field.anchors=[{ at = [0.0, 0.3, 0.0], direction = [0.0, 1.0, 0.0] }]"],
        cache.path(),
    );
    assert_eq!(
        ran(&anchored),
        vec!["field", "parameterize", "synthesize", "reconstruct"]
    );
}

#[test]
fn touching_the_exemplar_reruns_nothing_and_the_same_mesh_in_another_format_is_cut_off_early() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let assets = dir.path().join("assets");
    std::fs::create_dir_all(&assets).unwrap();
    for f in ["cow.obj", "wood1.png"] {
        std::fs::copy(repo().join("configs/assets").join(f), assets.join(f)).unwrap();
    }
    std::fs::copy(
        repo().join("tests/data/meshes/cow.off"),
        assets.join("cow.off"),
    )
    .unwrap();
    let config = dir.path().join("demo.toml");
    std::fs::copy(demo(), &config).unwrap();
    run(&config, &[], &cache);

    // Rewrite the exemplar with the same bytes: a new modification time, the same content.
    let bytes = std::fs::read(assets.join("wood1.png")).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    std::fs::write(assets.join("wood1.png"), &bytes).unwrap();
    let touched = run(&config, &[], &cache);
    assert!(ran(&touched).is_empty(), "ran: {:?}", ran(&touched));

    // cow.off holds the same mesh as cow.obj: only the import reruns; its artifact is
    // identical, so nothing downstream does (early cutoff).
    let off = run(&config, &["inputs.mesh=assets/cow.off"], &cache);
    assert_eq!(ran(&off), vec!["import.mesh"]);
}

fn object_path(cache: &Path, r: &RunResult, node: &str) -> PathBuf {
    let key = &r.reports.iter().find(|n| n.node == node).unwrap().key;
    cache.join("objects-v1").join(&key[..2]).join(&key[2..])
}

#[test]
fn a_corrupted_artifact_is_detected_and_recomputed_to_the_same_result() {
    let (cache, clean) = fresh_demo();
    let hashes = |r: &RunResult| -> Vec<String> {
        r.reports.iter().map(|n| n.content_hash.clone()).collect()
    };

    // Flip one byte in the jump map's payload: its header still looks fine, so the damage
    // is found when synthesis reads it (after a new seed makes synthesis run).
    let jm = object_path(cache.path(), &clean, "analyse_exemplar");
    let mut bytes = std::fs::read(&jm).unwrap();
    let last = bytes.len() - 100;
    bytes[last] ^= 0x55;
    std::fs::write(&jm, &bytes).unwrap();
    let repaired = run(&demo(), &["synthesize.seed=3"], cache.path());
    assert!(
        ran(&repaired).contains(&"analyse_exemplar"),
        "ran: {:?}",
        ran(&repaired)
    );
    assert!(!repaired.warnings.is_empty());
    assert_eq!(
        artifact(&repaired, "analyse_exemplar").content_hash(),
        artifact(&clean, "analyse_exemplar").content_hash()
    );

    // Truncate the walk: a cache miss, recomputed; identical bytes, so reconstruction stays
    // cached.
    let walk = object_path(cache.path(), &clean, "synthesize");
    let bytes = std::fs::read(&walk).unwrap();
    std::fs::write(&walk, &bytes[..bytes.len() / 2]).unwrap();
    let again = run(&demo(), &[], cache.path());
    assert_eq!(ran(&again), vec!["synthesize"]);
    assert_eq!(hashes(&again), hashes(&clean));
}

#[test]
fn artifact_hashes_do_not_depend_on_the_thread_count() {
    assert_same_hashes_on_any_thread_count(|cache| run(&demo(), &[], cache));
}

#[test]
fn synth2d_hashes_do_not_depend_on_the_thread_count() {
    let config = repo().join("configs/synth2d.toml");
    assert_same_hashes_on_any_thread_count(|cache| run_config(&config, &[], &[], cache).unwrap());
}

#[test]
fn the_walk_honours_order_validity_boxes_and_edge_offsets() {
    let (_cache, r) = fresh_demo();
    let param = JumpParameterization::view(artifact(&r, "parameterize")).unwrap();
    let walk = TexelAddresses::view(artifact(&r, "synthesize")).unwrap();
    let n = param.meta.vertices as usize;
    let (w, h) = param.meta.exemplar;

    // The order is a permutation of the vertices that have edges, and every vertex after a
    // component's seed has a neighbour synthesized before it.
    let mut seen = vec![false; n];
    for (pos, &v) in param.order.iter().enumerate() {
        assert!(!seen[v as usize], "vertex {v} twice in the order");
        let nbrs = &param.neighbors
            [param.adj_offsets[v as usize] as usize..param.adj_offsets[v as usize + 1] as usize];
        let has_prior = nbrs.iter().any(|&u| seen[u as usize]);
        assert_eq!(
            !has_prior,
            param.seeds.contains(&(pos as u32)),
            "position {pos}: vertex {v}"
        );
        seen[v as usize] = true;
    }
    for v in 0..n {
        let has_edges = param.adj_offsets[v] != param.adj_offsets[v + 1];
        assert_eq!(seen[v], has_edges, "vertex {v}");
    }
    assert_eq!(param.seeds.len(), 1, "the cow is one connected piece");

    // Every address is valid for its vertex: its whole box stays inside the exemplar.
    for &v in param.order {
        let a = walk.addresses[v as usize];
        let b = param.boxes[v as usize];
        assert!(b.admits(a, w, h), "vertex {v}: {a} with box {b:?}");
    }

    // Opposite half-edges carry opposite offsets.
    for v in 0..n {
        for k in param.adj_offsets[v] as usize..param.adj_offsets[v + 1] as usize {
            let u = param.neighbors[k];
            assert_eq!(param.offset(u, v as u32), Some(-param.edge_offsets[k]));
        }
    }
}

/// Reads `v`, `vt` and `f v/vt` lines of an OBJ written by texsyn.
fn obj_faces(text: &str) -> (Vec<[f32; 2]>, Vec<[(usize, usize); 3]>) {
    let mut vt = Vec::new();
    let mut faces = Vec::new();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("vt") => {
                let u: f32 = it.next().unwrap().parse().unwrap();
                let v: f32 = it.next().unwrap().parse().unwrap();
                vt.push([u, v]);
            }
            Some("f") => {
                let c: Vec<(usize, usize)> = it
                    .map(|t| {
                        let (a, b) = t.split_once('/').unwrap();
                        (
                            a.parse::<usize>().unwrap() - 1,
                            b.parse::<usize>().unwrap() - 1,
                        )
                    })
                    .collect();
                faces.push([c[0], c[1], c[2]]);
            }
            _ => {}
        }
    }
    (vt, faces)
}

#[test]
fn the_exported_obj_gives_each_triangle_corners_that_differ_by_its_edge_offsets() {
    let (_cache, r) = fresh_demo();
    let out = tempfile::tempdir().unwrap();
    pipeline::outputs::materialize(artifact(&r, "reconstruct"), out.path()).unwrap();
    let text = std::fs::read_to_string(out.path().join("textured.obj")).unwrap();
    let (vt, faces) = obj_faces(&text);
    let param = JumpParameterization::view(artifact(&r, "parameterize")).unwrap();
    let (w, h) = param.meta.exemplar;
    assert_eq!(faces.len(), 5804);
    let to_texel = |t: [f32; 2]| glam::Vec2::new(t[0] * w as f32, (1.0 - t[1]) * h as f32);
    // §4.3: some corner is the base, and the other two sit at the base's coordinates plus
    // the offsets of the edges from the base (up to the rounding of writing uv as text).
    for (f, face) in faces.iter().enumerate() {
        let fits = |b: usize| {
            (0..3).filter(|&c| c != b).all(|c| {
                let got = to_texel(vt[face[c].1]) - to_texel(vt[face[b].1]);
                let want = param
                    .offset(face[b].0 as u32, face[c].0 as u32)
                    .expect("edge exists");
                (got - want).length() < 1e-3
            })
        };
        assert!((0..3).any(fits), "face {f}: no corner is a consistent base");
    }
}

#[test]
fn the_base_corner_offsets_are_exact_in_every_coordinate_set() {
    use texsyn::stages::reconstruct::jump_blend::corner_sets;
    let (_cache, r) = fresh_demo();
    let param = JumpParameterization::view(artifact(&r, "parameterize")).unwrap();
    let walk = TexelAddresses::view(artifact(&r, "synthesize")).unwrap();
    let mesh = <texsyn::geom::Mesh as Format>::view(artifact(&r, "import.mesh")).unwrap();
    let sets = corner_sets(&mesh.triangles, &param, walk.addresses).unwrap();
    for (f, t) in mesh.triangles.iter().enumerate() {
        for b in 0..3 {
            assert_eq!(sets[f][b][b], walk.addresses[t[b] as usize]);
            for c in 0..3 {
                if c != b {
                    let d = param.offset(t[b], t[c]).unwrap();
                    // base + d, rounded once to f32.
                    let err = (sets[f][b][c] - (sets[f][b][b] + d)).length();
                    assert_eq!(err, 0.0, "face {f}, base {b}, corner {c}");
                }
            }
        }
    }
}

/// `field.symmetry = 4` on the genus-3 elephant: the field is smoother up to a quarter turn
/// than the default one (both measured at symmetry 4), its vectors are unit tangents, and the
/// key is the default's when the symmetry is 1; a symmetry that is not 1, 2 or 4, or one with
/// sinks, is refused naming it.
#[test]
fn a_four_fold_field_turns_less_than_the_default_on_a_genus_3_mesh() {
    use texsyn::artifact::jump_maps::OrientationField;
    use texsyn::stages::field::symmetric_field::measure;
    let cache = tempfile::tempdir().unwrap();
    let base = [
        "inputs.mesh=\"assets/elephant.off\"",
        "inputs.exemplar=\"assets/parque1.png\"",
        "parameterize.scale=\"auto\"",
        "reconstruct.preview_size=32",
        "reconstruct.atlas_size=256",
    ];
    let field = |symmetry: &str| {
        let set = format!("field.symmetry={symmetry}");
        let r = run_config(&demo(), &base, &[&set], cache.path()).unwrap();
        OrientationField::view(artifact(&r, "field"))
            .unwrap()
            .to_vec()
    };
    let mesh = texsyn::geom::io::read_mesh(&repo().join("configs/assets/elephant.off")).unwrap();
    let (one, four) = (field("1"), field("4"));
    for (d, n) in four.iter().zip(mesh.vertex_normals()) {
        assert!((d.length() - 1.0).abs() < 1e-3 && d.dot(*n).abs() < 1e-3);
    }
    let (m1, m4) = (measure(&mesh, &one, 4), measure(&mesh, &four, 4));
    assert!(
        m4.mean_turn_deg < 0.8 * m1.mean_turn_deg && m4.energy < m1.energy,
        "{m4:?} vs {m1:?}"
    );
    // Combed, neighbours mostly hold the same one of their four directions: measured as a
    // 1-field it turns far less than representatives picked per vertex would (as good as
    // random: 90° on average). Across the cut lines between its singularities they differ
    // by a quarter turn (15.6° mean measured, against 5.1° up to the symmetry).
    let as_one = measure(&mesh, &four, 1);
    assert!(as_one.mean_turn_deg < 25.0, "{as_one:?}");
    for (sets, words) in [
        (
            &["field.symmetry=3"][..],
            &["symmetry = 3", "1, 2 or 4"][..],
        ),
        (
            &["field.symmetry=4", "field.sinks=[{ vertex = 3 }]"][..],
            &["symmetry = 4", "sinks"][..],
        ),
    ] {
        let e = common::err(run_config(&demo(), &base, sets, cache.path()));
        assert!(words.iter().all(|w| e.contains(w)), "{e}");
    }
}

/// `parameterize.scale_keys` on the demo cow: texels per unit near a key follow its factor
/// (the tail's 0.4 against the head's 2.5, a ratio of 6.25), every offset is still the
/// negation of its reverse, and a key the mesh does not have is refused naming it.
#[test]
fn scale_keys_vary_the_texture_scale_over_the_cow() {
    let cache = tempfile::tempdir().unwrap();
    let base = ["reconstruct.preview_size=32", "reconstruct.atlas_size=256"];
    let keys = "parameterize.scale_keys=[{ at = [-0.5, -0.15, 0.0], factor = 0.4 }, \
                { at = [0.5, 0.16, 0.0], factor = 2.5 }]";
    let r = run_config(&demo(), &base, &[keys], cache.path()).unwrap();
    let param = JumpParameterization::view(artifact(&r, "parameterize")).unwrap();
    let mesh = <texsyn::geom::Mesh as Format>::view(artifact(&r, "import.mesh")).unwrap();
    let flat = run_config(&demo(), &base, &[], cache.path()).unwrap();
    let plain = JumpParameterization::view(artifact(&flat, "parameterize")).unwrap();
    // Texels per unit length over the edges of the vertices within 0.05 of a point (inside
    // a key's default radius, 5 % of the cow's 1.25 diagonal).
    let texels_per_unit = |p: &texsyn::stages::parameterize::jump_parameterization::ParamParts,
                           at: [f32; 3]| {
        let at = glam::Vec3::from(at);
        let (mut texels, mut length) = (0.0f32, 0.0f32);
        for v in 0..mesh.vertex_count() {
            if mesh.positions[v].distance(at) > 0.05 {
                continue;
            }
            let (a, b) = (p.adj_offsets[v] as usize, p.adj_offsets[v + 1] as usize);
            for j in a..b {
                let w = p.neighbors[j] as usize;
                texels += p.edge_offsets[j].length();
                length += mesh.positions[v].distance(mesh.positions[w]);
                assert_eq!(p.offset(w as u32, v as u32), Some(-p.edge_offsets[j]));
            }
        }
        texels / length
    };
    let (tail, head) = ([-0.5, -0.15, 0.0], [0.5, 0.16, 0.0]);
    let (t, h) = (texels_per_unit(&param, tail), texels_per_unit(&param, head));
    let (t0, h0) = (texels_per_unit(&plain, tail), texels_per_unit(&plain, head));
    let ratio = (h / h0) / (t / t0);
    assert!(
        (4.5..8.0).contains(&ratio),
        "{ratio}: tail {t} / {t0}, head {h} / {h0}"
    );
    // In between, on the back, the scale lies between the two keys'.
    let back = [0.0, 0.2, 0.0];
    let middle = texels_per_unit(&param, back) / texels_per_unit(&plain, back);
    assert!(
        t / t0 < middle && middle < h / h0,
        "{}, {middle}, {}",
        t / t0,
        h / h0
    );
    for (set, words) in [
        (
            "parameterize.scale_keys=[{ vertex = 999999, factor = 2.0 }]",
            &["parameterize.scale_keys[0]", "vertex 999999"][..],
        ),
        (
            "parameterize.scale_keys=[{ vertex = 1, factor = 50.0 }]",
            &["parameterize.scale_keys[0]", "factor = 50"][..],
        ),
    ] {
        let e = common::err(run_config(&demo(), &base, &[set], cache.path()));
        assert!(words.iter().all(|w| e.contains(w)), "{e}");
    }
}
