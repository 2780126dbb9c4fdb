//! The solid method end to end: bricks cached across requests, determinism of the outputs,
//! and the errors a user meets.

use crate::common;
use common::{
    artifact, assert_runs_fail_naming, assert_same_hashes_on_any_thread_count, err, materialized,
    repo, run_config,
};
use std::path::PathBuf;
use texsyn::config::Config;
use texsyn::pipeline::{self, RunResult};

/// Small: a 40-voxel volume, 3 levels, small neighbourhoods, an 8-cell field grid (the
/// shipped 20 cells take half a minute a run).
const SMALL: &[&str] = &[
    "parameterize.resolution=40",
    "field.cells=8",
    "analyse_exemplar.levels=3",
    "analyse_exemplar.neighbourhood_coarsest=5",
    "analyse_exemplar.neighbourhood=5",
    "synthesize.levels=[{ passes = 2, scheme = \"plain\" }, { passes = 2 }, { passes = 2 }]",
    "reconstruct.preview_size=32",
    "reconstruct.atlas_size=1024",
];

fn run(config: &str, sets: &[&str], cache: &std::path::Path) -> Result<RunResult, String> {
    run_config(&repo().join("configs").join(config), SMALL, sets, cache)
}

/// The brick objects in a cache (kind code 16 in the artifact header).
fn bricks(cache: &std::path::Path) -> std::collections::BTreeSet<PathBuf> {
    let mut out = std::collections::BTreeSet::new();
    for shard in std::fs::read_dir(cache.join("objects-v1"))
        .unwrap()
        .flatten()
    {
        for f in std::fs::read_dir(shard.path()).unwrap().flatten() {
            let bytes = std::fs::read(f.path()).unwrap();
            if bytes.len() >= 16 && u32::from_le_bytes(bytes[12..16].try_into().unwrap()) == 16 {
                out.insert(f.path());
            }
        }
    }
    out
}

#[test]
fn a_section_after_the_surface_computes_fewer_bricks_than_from_an_empty_cache() {
    let shared = tempfile::tempdir().unwrap();
    run("solid_elephant.toml", &[], shared.path()).unwrap();
    let before = bricks(shared.path());
    let after_surface = run("solid_elephant_section.toml", &[], shared.path()).unwrap();
    let made_after_surface = bricks(shared.path()).len() - before.len();
    let empty = tempfile::tempdir().unwrap();
    let alone = run("solid_elephant_section.toml", &[], empty.path()).unwrap();
    let made_alone = bricks(empty.path()).len();
    assert!(
        made_after_surface < made_alone,
        "{made_after_surface} vs {made_alone}"
    );
    // The section is the same whatever the cache held (spatial determinism), and every brick
    // the two caches share is byte-identical.
    let h = |r: &RunResult| {
        r.reports
            .iter()
            .find(|n| n.node == "synthesize")
            .unwrap()
            .content_hash
            .clone()
    };
    assert_eq!(h(&after_surface), h(&alone));
    let names = |c: &std::path::Path| -> std::collections::BTreeSet<PathBuf> {
        bricks(c)
            .into_iter()
            .map(|p| p.strip_prefix(c).unwrap().to_owned())
            .collect()
    };
    let common: Vec<PathBuf> = names(shared.path())
        .intersection(&names(empty.path()))
        .cloned()
        .collect();
    assert!(!common.is_empty());
    for p in common {
        assert_eq!(
            std::fs::read(shared.path().join(&p)).unwrap(),
            std::fs::read(empty.path().join(&p)).unwrap(),
            "{p:?}"
        );
    }
}

/// The synthesis node's piece counts in a run's report.
fn pieces(r: &RunResult) -> Option<pipeline::PieceReport> {
    r.reports
        .iter()
        .find(|n| n.node == "synthesize")
        .expect("a synthesize node")
        .pieces
}

#[test]
fn the_run_report_counts_the_bricks_a_section_reuses_from_the_surface() {
    let shared = tempfile::tempdir().unwrap();
    let surface = run("solid_elephant.toml", &[], shared.path()).unwrap();
    let first = pieces(&surface).expect("the surface's synthesis ran");
    assert!(first.computed > 0 && first.reused == 0, "{first:?}");
    // Every brick computed is one object in the cache.
    assert_eq!(first.computed as usize, bricks(shared.path()).len());

    let before = bricks(shared.path()).len();
    let cut = run("solid_elephant_section.toml", &[], shared.path()).unwrap();
    let after_surface = pieces(&cut).expect("the section's synthesis ran");
    assert!(after_surface.reused > 0, "{after_surface:?}");
    let made = bricks(shared.path()).len() - before;
    assert_eq!(after_surface.computed as usize, made);

    let empty = tempfile::tempdir().unwrap();
    let alone = pieces(&run("solid_elephant_section.toml", &[], empty.path()).unwrap())
        .expect("the section's synthesis ran");
    assert_eq!(alone.reused, 0, "{alone:?}");
    assert!(
        after_surface.computed < alone.computed,
        "after the surface {after_surface:?}, alone {alone:?}"
    );
    // What the section did not compute, it reused; and it needs no more bricks than alone (the
    // bricks it has at one level need nothing below).
    assert!(after_surface.computed + after_surface.reused <= alone.computed);

    // Nothing changed: the synthesis is cached, so no brick is even looked at.
    let again = run("solid_elephant_section.toml", &[], shared.path()).unwrap();
    assert_eq!(pieces(&again), None);
}

#[test]
fn outputs_do_not_depend_on_the_thread_count() {
    assert_same_hashes_on_any_thread_count(|cache| {
        run("solid_elephant_section.toml", &[], cache).unwrap()
    });
}

#[test]
fn user_mistakes_are_named() {
    assert_runs_fail_naming(
        run,
        &[
            (
                "solid_trivial.toml",
                &["field.curves=[{ points = [[0.0, 0.0, 0.0]] }]"],
                &["field.curves[0]", "at least two points"],
            ),
            (
                "solid_trivial.toml",
                &["field.curves=[{ points = [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]], axis = \"w\" }]"],
                &["field.curves", "axis"],
            ),
            (
                "solid_trivial.toml",
                &[
                    "parameterize.request={ kind = \"section\", point = [0.0, 0.0, 50.0], normal = [0.0, 0.0, 1.0] }",
                ],
                &["misses the volume"],
            ),
            (
                "solid_trivial.toml",
                &["inputs.yz=\"assets/wood1.png\""],
                &["same size"],
            ),
            (
                "solid_trivial.toml",
                &["analyse_exemplar.levels=2"],
                &["synthesize.levels"],
            ),
        ],
    );
}

#[test]
fn the_pyramid_depth_follows_synthesize_levels_when_only_they_are_given() {
    // solid_trivial.toml without its `analyse_exemplar.levels`, planned (not run).
    let path = repo().join("configs/solid_trivial.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let text = text.replace("levels = 4", "");
    let sets = ["synthesize.levels=[{ passes = 2 }, { passes = 2 }]".to_string()];
    let plan = texsyn::methods::plan(&Config::from_str(&path, &text, &sets).unwrap()).unwrap();
    let params = |node: &str| {
        let i = plan.dag.node_index(node).unwrap();
        plan.dag.nodes[i].params_json.clone()
    };
    // The analysis' parameters, beside which planes are transposed.
    assert_eq!(params("analyse_exemplar")["analysis"]["levels"], 2);
    assert_eq!(params("synthesize")["levels"].as_array().unwrap().len(), 2);
    // Given both, they must agree, and the error names both.
    let e = run(
        "solid_trivial.toml",
        &["synthesize.levels=[{ passes = 2 }, { passes = 2 }]"],
        tempfile::tempdir().unwrap().path(),
    );
    let e = err(e);
    assert!(
        e.contains("synthesize.levels") && e.contains("analyse_exemplar.levels is 3"),
        "{e}"
    );
}

#[test]
fn a_surface_the_atlas_cannot_hold_gets_vertex_colours_in_its_glb() {
    // 64² texels cannot hold the elephant's 5,558 triangles with their gutters: the run still
    // writes the surface, its .glb with the refined surface's vertex colours, and no bake.
    let cache = tempfile::tempdir().unwrap();
    let r = run(
        "solid_trivial.toml",
        &["reconstruct.atlas_size=64"],
        cache.path(),
    )
    .unwrap();
    let out = materialized(&r, "reconstruct");
    assert!(!out.path().join("baked_surface.png").exists());
    let glb = std::fs::read(out.path().join("solid_surface.glb")).unwrap();
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let json: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let attributes = &json["meshes"][0]["primitives"][0]["attributes"];
    assert!(attributes.get("COLOR_0").is_some(), "{attributes}");
    assert!(attributes.get("TEXCOORD_0").is_none(), "{attributes}");
    assert!(
        json.get("images")
            .is_none_or(|i| i.as_array().is_some_and(|a| a.is_empty()))
    );
    // The same vertices as the coloured PLY.
    let ply = std::fs::read(out.path().join("solid_surface.ply")).unwrap();
    let head = String::from_utf8_lossy(&ply[..ply.len().min(512)]).into_owned();
    let vertices: usize = head
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let accessor = attributes["COLOR_0"].as_u64().unwrap() as usize;
    assert_eq!(
        json["accessors"][accessor]["count"].as_u64(),
        Some(vertices as u64)
    );
    // With room, the bake is back.
    let r = run("solid_trivial.toml", &[], cache.path()).unwrap();
    assert!(
        materialized(&r, "reconstruct")
            .path()
            .join("baked_surface.png")
            .exists()
    );
}

#[test]
fn a_box_request_writes_a_raw_volume_with_its_header() {
    let cache = tempfile::tempdir().unwrap();
    let r = run(
        "solid_trivial.toml",
        &["parameterize.request={ kind = \"box\", min = [0.0, -0.1, -0.05], max = [0.06, -0.04, 0.01] }"],
        cache.path(),
    )
    .unwrap();
    let out = materialized(&r, "reconstruct");
    let header: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.path().join("volume.json")).unwrap()).unwrap();
    let d: Vec<u64> = header["dims"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    let raw = std::fs::read(out.path().join("volume.raw")).unwrap();
    assert_eq!(raw.len() as u64, d[0] * d[1] * d[2] * 3);
    // Wood: the voxels are not all one colour.
    let first = &raw[0..3];
    assert!(raw.chunks(3).any(|c| c != first));
    // volume.exr holds the same voxels, one part per z-slice, read with the exr crate.
    use exr::prelude::{ReadChannels, ReadLayers};
    let bytes = std::fs::read(out.path().join("volume.exr")).unwrap();
    let img = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(&bytes))
        .unwrap();
    assert_eq!(img.layer_data.len() as u64, d[2]);
    let (w, h) = (d[0] as usize, d[1] as usize);
    for (z, layer) in img.layer_data.iter().enumerate() {
        assert_eq!(
            layer.attributes.layer_name.as_ref().unwrap().to_string(),
            format!("z{z:04}")
        );
        assert_eq!((layer.size.x(), layer.size.y()), (w, h));
        let names: Vec<String> = layer
            .channel_data
            .list
            .iter()
            .map(|c| c.name.to_string())
            .collect();
        assert_eq!(names, ["B", "G", "R"]);
        for (ch, c) in layer.channel_data.list.iter().zip([2usize, 1, 0]) {
            for i in 0..w * h {
                let x = ch.sample_data.value_by_flat_index(i).to_f32();
                let byte = (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
                assert_eq!(byte, raw[(z * w * h + i) * 3 + c], "slice {z}, voxel {i}");
            }
        }
    }
}

fn samples(r: &RunResult, node: &str) -> std::collections::BTreeMap<[i32; 3], [u8; 12]> {
    let a = artifact(r, node);
    let voxels: &[[i32; 3]] = a.array("voxels").unwrap();
    let triples = a.raw_array("triples").unwrap();
    let per = triples.len() / voxels.len().max(1);
    assert_eq!(per, 12, "a triple is three 2D coordinates of u16 pairs");
    voxels
        .iter()
        .enumerate()
        .map(|(k, v)| (*v, triples[k * per..(k + 1) * per].try_into().unwrap()))
        .collect()
}

#[test]
fn regions_split_a_section_by_depth_and_the_core_is_the_same_solid() {
    use texsyn::geom::surface_distance::closest_point_on_triangle;
    let cache = tempfile::tempdir().unwrap();
    let plain = run("solid_elephant_section.toml", &[], cache.path()).unwrap();
    let layered = run("solid_elephant_bark.toml", &[], cache.path()).unwrap();
    let all = samples(&plain, "synthesize");
    let core = samples(&layered, "synthesize");
    let shell = samples(&layered, "synthesize.region1");
    assert!(!core.is_empty() && !shell.is_empty());
    // The two regions partition the section's voxels …
    assert_eq!(core.len() + shell.len(), all.len());
    assert!(core.keys().chain(shell.keys()).all(|v| all.contains_key(v)));
    // … and the core is the same solid as without regions, voxel for voxel.
    for (v, t) in &core {
        assert_eq!(all[v], *t, "{v:?}");
    }
    // Depth by brute force over every triangle: the shell is the shallow part.
    let cfg = Config::load(&repo().join("configs/solid_elephant_bark.toml"), &[]).unwrap();
    let mesh =
        texsyn::geom::io::read_mesh(&cfg.resolve(std::path::Path::new("assets/elephant.off")))
            .unwrap();
    let vol = texsyn::stages::parameterize::volume_embedding::embed(&mesh, 40, 0.25).unwrap();
    let depth = |v: &[i32; 3]| {
        let p = vol.centre(glam::IVec3::from(*v));
        mesh.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
                closest_point_on_triangle(p, a, b, c).distance(p)
            })
            .fold(f32::INFINITY, f32::min)
    };
    for v in shell.keys() {
        assert!(depth(v) < 0.03 + 1e-4, "{v:?} at {}", depth(v));
    }
    for v in core.keys() {
        assert!(depth(v) >= 0.03 - 1e-4, "{v:?} at {}", depth(v));
    }
}

#[test]
fn region_mistakes_are_named() {
    assert_runs_fail_naming(
        run,
        &[
            (
                "solid_elephant_bark.toml",
                &["regions=[{ depth = -1.0, exemplar = \"assets/bark.png\" }]"],
                &["regions[0].depth"],
            ),
            (
                "solid_elephant_bark.toml",
                &[
                    "regions=[{ depth = 0.05, exemplar = \"assets/bark.png\" }, { depth = 0.02, exemplar = \"assets/wood1.png\" }]",
                ],
                &["regions[1].depth", "increasing"],
            ),
            (
                "solid_elephant_bark.toml",
                &["regions=[{ depth = 0.05, xy = \"assets/bark.png\" }]"],
                &["regions[0].yz", "missing"],
            ),
            (
                "solid_elephant_bark.toml",
                &["regions=[{ depth = 0.05, exemplar = \"assets/no_such_bark.png\" }]"],
                &["no_such_bark.png", "regions[0].exemplar"],
            ),
        ],
    );
}

#[test]
fn a_region_with_the_core_s_own_exemplars_changes_nothing() {
    // Same exemplar set in the shell and the core: the same solid, so the two regions' samples
    // together are exactly the section without regions (each region's synthesis must own its
    // voxels even though its inputs equal the other's).
    let cache = tempfile::tempdir().unwrap();
    let plain = run("solid_elephant_section.toml", &[], cache.path()).unwrap();
    let same = run(
        "solid_elephant_bark.toml",
        &["regions=[{ depth = 0.03, xy = \"assets/wood2.png\", yz = \"assets/wood2.png\", zx = { path = \"assets/wood2.png\", transpose = true } }]"],
        cache.path(),
    )
    .unwrap();
    let mut both = samples(&same, "synthesize");
    let shell = samples(&same, "synthesize.region1");
    assert!(!shell.is_empty() && !both.is_empty());
    both.extend(shell);
    assert_eq!(both, samples(&plain, "synthesize"));
}

/// A drawn mask given beside a plane's exemplar reaches the analysis (its result changes, and
/// is not the detector's), and one of another size or without a drawn texel is refused naming
/// the mask's file and key. (That a mask is read transposed with its image is checked on the
/// analysis itself, in solid_switches.rs.)
#[test]
fn a_drawn_mask_beside_an_exemplar_feeds_the_analysis_and_a_wrong_one_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let wood = repo().join("configs/assets/wood2.png");
    let (w, h) = image::image_dimensions(&wood).unwrap();
    // The grain's columns every 7 texels, as a user might draw them.
    let mask =
        image::GrayImage::from_fn(w, h, |x, _| image::Luma([if x % 7 == 0 { 255 } else { 0 }]));
    let good = dir.path().join("grain.png");
    mask.save(&good).unwrap();
    let small = dir.path().join("small.png");
    image::GrayImage::from_pixel(9, 9, image::Luma([255]))
        .save(&small)
        .unwrap();
    let spec = |mask: &std::path::Path| {
        format!(
            "inputs.zx={{ path = {:?}, transpose = true, mask = {:?} }}",
            wood.display().to_string(),
            mask.display().to_string()
        )
    };
    let cache = tempfile::tempdir().unwrap();
    let analysis = |r: &RunResult| {
        let n = r
            .reports
            .iter()
            .find(|n| n.node == "analyse_exemplar")
            .unwrap();
        (n.key.clone(), n.content_hash.clone())
    };
    let plain = run("solid_trivial.toml", &[], cache.path()).unwrap();
    let drawn = run("solid_trivial.toml", &[&spec(&good)], cache.path()).unwrap();
    let (k0, h0) = analysis(&plain);
    let (k1, h1) = analysis(&drawn);
    assert_ne!(k0, k1);
    assert_ne!(h0, h1);
    // Not the detector's curves: the drawn ones.
    let detected = run(
        "solid_trivial.toml",
        &["analyse_exemplar.feature_mask={}"],
        cache.path(),
    )
    .unwrap();
    assert_ne!(analysis(&detected).1, h1);
    let e = err(run("solid_trivial.toml", &[&spec(&small)], cache.path()));
    assert!(
        e.contains("small.png") && e.contains("inputs.zx.mask") && e.contains("9×9"),
        "{e}"
    );
    let blank = dir.path().join("blank.png");
    image::GrayImage::new(w, h).save(&blank).unwrap();
    let e = err(run("solid_trivial.toml", &[&spec(&blank)], cache.path()));
    assert!(
        e.contains("blank.png") && e.contains("no feature texel"),
        "{e}"
    );
}
