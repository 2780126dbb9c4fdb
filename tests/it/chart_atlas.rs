//! The jump-map export's chart atlas over pages: a texture spread over
//! several pages opens correctly (the .glb passes the Khronos glTF validator, installed by
//! `scripts/gltf-validator`; the OBJ loads in tobj with one material per page), chart borders
//! add no seams, and an atlas that cannot be built names a value the validator accepts.

use crate::common;

use common::{err, materialized, run_config};
use glam::Vec2;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn demo() -> PathBuf {
    repo().join("configs/demo.toml")
}

/// Small pages, so the demo's texture needs several.
const SMALL_PAGES: &[&str] = &["reconstruct.atlas_size=128", "reconstruct.preview_size=64"];

/// Installs the validator with the project's script (idempotent) and validates `glb`; returns
/// the report's summary, or None (said on stderr) outside the full tier or with
/// TEXSYN_NO_GLTF_VALIDATOR set.
fn validate(glb: &Path) -> Option<serde_json::Value> {
    let script = repo().join("scripts/gltf-validator");
    if !common::full_tier() {
        common::say_skipped("the Khronos glTF validator's check of the .glb");
        return None;
    }
    if std::env::var_os("TEXSYN_NO_GLTF_VALIDATOR").is_some() {
        use std::io::Write;
        let _ = writeln!(
            std::io::stderr().lock(),
            "SKIPPED the glTF validator's check: TEXSYN_NO_GLTF_VALIDATOR is set, the .glb is NOT validated"
        );
        return None;
    }
    let install = std::process::Command::new(&script)
        .arg("install")
        .output()
        .unwrap();
    assert!(
        install.status.success(),
        "scripts/gltf-validator install failed (set TEXSYN_NO_GLTF_VALIDATOR=1 to skip): {}",
        String::from_utf8_lossy(&install.stderr)
    );
    let o = std::process::Command::new(&script)
        .arg("check")
        .arg(glb)
        .output()
        .unwrap();
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| {
        panic!(
            "validator output is not JSON ({e}): {} {}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        )
    });
    Some(report)
}

/// The JSON chunk of a .glb.
fn glb_json(bytes: &[u8]) -> serde_json::Value {
    let len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    serde_json::from_slice(&bytes[20..20 + len]).unwrap()
}

fn page_files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("baked_basecolor"))
        .collect();
    v.sort_by_key(|n| {
        n.trim_start_matches("baked_basecolor_")
            .trim_end_matches(".png")
            .parse::<usize>()
            .unwrap_or(0)
    });
    v
}

#[test]
fn a_texture_over_several_pages_opens_with_one_material_per_page() {
    let cache = tempfile::tempdir().unwrap();
    let r = run_config(&demo(), &[], SMALL_PAGES, cache.path()).unwrap();
    let out = materialized(&r, "reconstruct");
    let pages = page_files(out.path());
    assert!(pages.len() >= 3, "expected several pages: {pages:?}");
    for (k, p) in pages.iter().enumerate() {
        assert_eq!(p, &format!("baked_basecolor_{k}.png"));
        let img = image::open(out.path().join(p)).unwrap();
        assert!(
            img.width() <= 128 && img.height() <= 128,
            "{p} is larger than a page"
        );
    }

    // The .glb: valid, one primitive and one material per page, each material's base colour
    // being that page's PNG.
    let glb_path = out.path().join("textured.glb");
    if let Some(report) = validate(&glb_path) {
        assert_eq!(report["numErrors"], 0, "{report}");
    }
    let glb = std::fs::read(&glb_path).unwrap();
    let json = glb_json(&glb);
    let prims = json["meshes"][0]["primitives"].as_array().unwrap();
    assert_eq!(prims.len(), pages.len());
    assert_eq!(json["materials"].as_array().unwrap().len(), pages.len());
    let bin_start = 20 + u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize + 8;
    for (k, prim) in prims.iter().enumerate() {
        assert_eq!(prim["material"], k);
        let tex = json["materials"][k]["pbrMetallicRoughness"]["baseColorTexture"]["index"]
            .as_u64()
            .unwrap() as usize;
        let image = json["textures"][tex]["source"].as_u64().unwrap() as usize;
        let view =
            &json["bufferViews"][json["images"][image]["bufferView"].as_u64().unwrap() as usize];
        let (off, len) = (
            view["byteOffset"].as_u64().unwrap() as usize,
            view["byteLength"].as_u64().unwrap() as usize,
        );
        let png = &glb[bin_start + off..bin_start + off + len];
        assert_eq!(
            png,
            std::fs::read(out.path().join(&pages[k]))
                .unwrap()
                .as_slice()
        );
    }

    // The OBJ: tobj splits it by `usemtl`, one model per page, every face once.
    let (models, materials) = tobj::load_obj(
        out.path().join("baked.obj"),
        &tobj::LoadOptions {
            triangulate: true,
            ..Default::default()
        },
    )
    .unwrap();
    let materials = materials.unwrap();
    assert_eq!(materials.len(), pages.len());
    assert_eq!(models.len(), pages.len());
    let mut faces = 0;
    for m in &models {
        let id = m.mesh.material_id.unwrap();
        assert_eq!(
            materials[id].diffuse_texture.as_deref(),
            Some(pages[id].as_str())
        );
        faces += m.mesh.indices.len() / 3;
    }
    let mesh = texsyn::geom::io::read_mesh(&repo().join("configs/assets/cow.obj")).unwrap();
    assert_eq!(faces, mesh.triangles.len());
}

/// Bilinear sample (RGB in [0, 1]) of `img` at glTF/OBJ-free texel coordinates `uv` in [0, 1]
/// (v down).
fn sample(img: &image::RgbImage, uv: Vec2) -> [f32; 3] {
    let (w, h) = (img.width() as f32, img.height() as f32);
    let (x, y) = (uv.x * w - 0.5, uv.y * h - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let px = |i: f32, j: f32| {
        let i = i.clamp(0.0, w - 1.0) as u32;
        let j = j.clamp(0.0, h - 1.0) as u32;
        img.get_pixel(i, j).0.map(|c| c as f32 / 255.0)
    };
    let (a, b, c, d) = (
        px(x0, y0),
        px(x0 + 1.0, y0),
        px(x0, y0 + 1.0),
        px(x0 + 1.0, y0 + 1.0),
    );
    std::array::from_fn(|k| {
        (a[k] * (1.0 - fx) + b[k] * fx) * (1.0 - fy) + (c[k] * (1.0 - fx) + d[k] * fx) * fy
    })
}

fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// One face's view of an edge: its page and the edge's two ends there.
type Side = (usize, Vec2, Vec2);

/// Colour differences across the edges where one chart meets another (the two faces address
/// different texels for the same point), against the same measure for pairs of unrelated
/// points ("relative to randomly placed triangles"): the baked pages are sampled
/// at the edge's quarter points from either side.
#[test]
fn chart_borders_add_no_seams() {
    let cache = tempfile::tempdir().unwrap();
    let r = run_config(&demo(), &[], SMALL_PAGES, cache.path()).unwrap();
    let out = materialized(&r, "reconstruct");
    let (models, _) =
        tobj::load_obj(out.path().join("baked.obj"), &tobj::LoadOptions::default()).unwrap();
    let pages: Vec<image::RgbImage> = page_files(out.path())
        .iter()
        .map(|p| image::open(out.path().join(p)).unwrap().to_rgb8())
        .collect();
    // Edge (a, b), a < b → the sides that use it: (page, uv at a, uv at b). tobj numbers
    // each model's vertices on its own: vertices are named by their coordinates' bits.
    let mut names: HashMap<[u32; 3], u32> = HashMap::new();
    let mut sides: HashMap<(u32, u32), Vec<Side>> = HashMap::new();
    for m in &models {
        let global: Vec<u32> = m
            .mesh
            .positions
            .chunks(3)
            .map(|p| {
                let next = names.len() as u32;
                *names
                    .entry([p[0].to_bits(), p[1].to_bits(), p[2].to_bits()])
                    .or_insert(next)
            })
            .collect();
        let page = m.mesh.material_id.unwrap();
        let uv = |i: u32| {
            let i = i as usize;
            // OBJ has v up; the pages are images with v down.
            Vec2::new(m.mesh.texcoords[2 * i], 1.0 - m.mesh.texcoords[2 * i + 1])
        };
        for (f, t) in m.mesh.indices.chunks(3).enumerate() {
            let tc = &m.mesh.texcoord_indices[3 * f..3 * f + 3];
            for k in 0..3 {
                let (a, b) = (global[t[k] as usize], global[t[(k + 1) % 3] as usize]);
                let (ua, ub) = (uv(tc[k]), uv(tc[(k + 1) % 3]));
                let key = (a.min(b), a.max(b));
                let (ua, ub) = if a < b { (ua, ub) } else { (ub, ua) };
                sides.entry(key).or_default().push((page, ua, ub));
            }
        }
    }
    let mut across = Vec::new();
    let mut points = Vec::new();
    for s in sides.values() {
        if s.len() != 2 || (s[0] == s[1]) {
            continue; // a boundary, or inside a chart (the same texels on both sides)
        }
        for t in [0.25f32, 0.5, 0.75] {
            let at = |(p, a, b): Side| sample(&pages[p], a + (b - a) * t);
            let (c0, c1) = (at(s[0]), at(s[1]));
            across.push(dist(c0, c1));
            points.push(c0);
        }
    }
    assert!(
        across.len() > 100,
        "too few chart borders: {}",
        across.len()
    );
    // Unrelated pairs: each border point against one a fixed stride away.
    let n = points.len();
    let random: Vec<f32> = (0..n)
        .map(|i| dist(points[i], points[(i * 7919 + n / 2) % n]))
        .collect();
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
    let (seam, unrelated) = (mean(&across), mean(&random));
    eprintln!("chart borders: mean colour difference {seam:.4}; unrelated points {unrelated:.4}");
    assert!(
        seam < 0.25 * unrelated,
        "chart borders differ by {seam:.4} on average, unrelated points by {unrelated:.4}"
    );
}

#[test]
fn an_atlas_that_cannot_be_built_names_a_value_that_works() {
    let cache = tempfile::tempdir().unwrap();
    // At 16 atlas texels per exemplar texel the cow's largest triangles span more than a
    // 64-texel page.
    let sets = [
        "reconstruct.atlas_size=64",
        "reconstruct.texel_density=16",
        "reconstruct.preview_size=32",
    ];
    let e = err(run_config(&demo(), &[], &sets, cache.path()));
    assert!(e.contains("reconstruct.texel_density"), "{e}");
    let named: f32 = e
        .split("reconstruct.texel_density ≤ ")
        .nth(1)
        .and_then(|s| s.split(|c: char| !(c.is_ascii_digit() || c == '.')).next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no value named in: {e}"));
    assert!(
        (0.25..=16.0).contains(&named),
        "{named} is outside the validator's range"
    );
    let fixed = format!("reconstruct.texel_density={named}");
    run_config(
        &demo(),
        &[],
        &[
            "reconstruct.atlas_size=64",
            &fixed,
            "reconstruct.preview_size=32",
        ],
        cache.path(),
    )
    .unwrap_or_else(|e| panic!("the value the message named fails: {e}"));
}

/// Graph matching's texture baked onto the user's mesh opens in glTF tools: the validator
/// (full tier) finds no error, and the file holds the input's triangles, each corner with
/// texture coordinates, and one base-colour texture.
#[test]
fn graph_matchings_baked_atlas_is_valid_gltf() {
    let cache = tempfile::tempdir().unwrap();
    let sets = [
        "parameterize.scale=30",
        "reconstruct.preview_size=48",
        "reconstruct.atlas_size=1024",
    ];
    let config = repo().join("configs/graph_matching.toml");
    let r = run_config(&config, &[], &sets, cache.path()).unwrap();
    let out = materialized(&r, "reconstruct");
    let glb_path = out.path().join("textured.glb");
    if let Some(report) = validate(&glb_path) {
        assert_eq!(report["numErrors"], 0, "{report}");
    }
    let json = glb_json(&std::fs::read(&glb_path).unwrap());
    let prim = &json["meshes"][0]["primitives"][0];
    let input = texsyn::geom::io::read_mesh(&repo().join("configs/assets/cow.obj")).unwrap();
    let positions = prim["attributes"]["POSITION"].as_u64().unwrap() as usize;
    assert_eq!(
        json["accessors"][positions]["count"],
        3 * input.triangles.len()
    );
    let uv = prim["attributes"]["TEXCOORD_0"].as_u64().unwrap() as usize;
    assert_eq!(json["accessors"][uv]["count"], 3 * input.triangles.len());
    assert_eq!(json["images"].as_array().unwrap().len(), 1);
}
