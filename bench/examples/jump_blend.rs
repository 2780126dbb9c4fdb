//! Jump maps' blend over several triangles (`reconstruct.blend_radius`) against §4.4's
//! one-triangle ramp, where the texture is large against the mesh (BENCHMARKS.md, "Jump maps:
//! blending over several triangles"):
//! - a table of `texsyn score` numbers per run: the blended seam ratio, the discs' patch
//!   ratio, coverage and gradient ratio, the OBJ's seam ratio, and the whole cold run's time;
//! - `jump-maps-wide-blend.png`: the demo cow with brick at 60 texels per unit, radius 0 then
//!   3, the side view's middle enlarged.
//!
//! The tuned rows use configs/assets; the untuned pairs read ../shared/data and are skipped
//! (said) when it is missing. Each run has a fresh cache.
//!
//! ```text
//! cargo build --release && cargo run --release -p texsyn-bench --example jump_blend -- [OUT_DIR]
//! ```

mod common;

use std::path::{Path, PathBuf};
use std::time::Instant;

/// One row: a name, the mesh and exemplar (paths as the config reads them) and the scale.
struct Case {
    name: &'static str,
    mesh: PathBuf,
    exemplar: PathBuf,
    scale: f32,
    radii: &'static [f32],
}

/// The scale (texels per unit) at which the mesh's median edge spans `texels` texels.
fn scale_for_median_edge(mesh: &Path, texels: f32) -> f32 {
    let m = texsyn::geom::io::read_mesh(mesh).unwrap();
    let mut lengths: Vec<f32> = m
        .triangles
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k] as usize, t[(k + 1) % 3] as usize)))
        .map(|(a, b)| m.positions[a].distance(m.positions[b]))
        .collect();
    lengths.sort_by(f32::total_cmp);
    texels / lengths[lengths.len() / 2]
}

fn main() {
    let dir = common::out_dir();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let demo = repo.join("configs/demo.toml");
    let assets = repo.join("configs/assets");
    let shared = repo.join("../shared/data");
    let mut cases = vec![
        Case {
            name: "cow + wood1 (tuned)",
            mesh: assets.join("cow.obj"),
            exemplar: assets.join("wood1.png"),
            scale: 60.0,
            radii: &[0.0, 1.0, 2.0, 3.0, 4.0, 8.0],
        },
        Case {
            name: "cow + brick (tuned)",
            mesh: assets.join("cow.obj"),
            exemplar: assets.join("brick.png"),
            scale: 60.0,
            radii: &[0.0, 1.0, 2.0, 3.0, 4.0, 8.0],
        },
    ];
    if shared.exists() {
        for (name, mesh, ex) in [
            ("pig + ground1 (untuned)", "pig.stl", "ground1.png"),
            (
                "refined elephant + burlap (untuned)",
                "refined_elephant.off",
                "burlap.png",
            ),
            (
                "dragon + marble1 (untuned)",
                "ChineseDragon-10kv.off",
                "marble1.png",
            ),
        ] {
            let mesh = shared.join("meshes").join(mesh);
            let scale = scale_for_median_edge(&mesh, 1.5);
            cases.push(Case {
                name,
                mesh,
                exemplar: shared.join("exemplars").join(ex),
                scale,
                radii: &[0.0, 3.0],
            });
        }
    } else {
        println!(
            "{} is missing: the untuned pairs are skipped",
            shared.display()
        );
    }
    println!(
        "| pair | scale | radius | blended seams | disc ratio | coverage | gradient ratio | OBJ seams | cold run (s) |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for case in &cases {
        for &r in case.radii {
            let sets = [
                format!("inputs.mesh={:?}", case.mesh.display().to_string()),
                format!("inputs.exemplar={:?}", case.exemplar.display().to_string()),
                format!("parameterize.scale={}", case.scale),
                "parameterize.rotation=0".to_string(),
                "reconstruct.up=\"auto\"".to_string(),
                format!("reconstruct.blend_radius={r}"),
            ];
            let out = dir.join(format!(
                "jump-blend-{}-{r}",
                case.name.replace([' ', '+', '(', ')'], "")
            ));
            let cache = out.join("cache");
            let mut cmd = std::process::Command::new(common::texsyn_binary());
            cmd.arg("score")
                .arg(&demo)
                .arg("--cache")
                .arg(&cache)
                .arg("--json");
            for s in &sets {
                cmd.arg("--set").arg(s);
            }
            let clock = Instant::now();
            let o = cmd.output().unwrap();
            let seconds = clock.elapsed().as_secs_f64();
            assert!(
                o.status.success(),
                "{}: {}",
                case.name,
                String::from_utf8_lossy(&o.stderr)
            );
            std::fs::remove_dir_all(&cache).ok();
            let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            let item = &v["items"][0];
            let (s, x) = (&item["score"], &item["extra"]);
            let f = |v: &serde_json::Value| v.as_f64().unwrap();
            println!(
                "| {} | {:.1} | {r} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {seconds:.2} |",
                case.name,
                case.scale,
                f(&x["blended_seams"]["ratio"]),
                f(&s["ratio"]),
                f(&s["coverage"]),
                f(&s["gradient_ratio"]),
                f(&x["seams"]["ratio"]),
            );
        }
    }
    // The picture: the side view's middle, enlarged.
    let mut crops = Vec::new();
    for r in [0, 3] {
        let out = dir.join(format!("jump-blend-picture-{r}"));
        let sets = [
            "inputs.exemplar=\"assets/brick.png\"".to_string(),
            "parameterize.scale=60".to_string(),
            "parameterize.rotation=0".to_string(),
            "reconstruct.preview_size=1536".to_string(),
            format!("reconstruct.blend_radius={r}"),
        ];
        let preview = common::run_preview(&demo, &sets, &out);
        let img = image::open(&preview).unwrap().to_rgb8();
        crops.push(image::imageops::crop_imm(&img, 250, 450, 900, 560).to_image());
    }
    let gap = 8;
    let (w, h) = (crops[0].width(), crops[0].height());
    let mut img = image::RgbImage::from_pixel(2 * w + gap, h, image::Rgb([255, 255, 255]));
    image::imageops::replace(&mut img, &crops[0], 0, 0);
    image::imageops::replace(&mut img, &crops[1], (w + gap) as i64, 0);
    // Two thirds of the size keeps the triangle-shaped seams visible in a smaller file.
    let (w, h) = (img.width() * 2 / 3, img.height() * 2 / 3);
    let img = image::imageops::resize(&img, w, h, image::imageops::FilterType::Triangle);
    let out = dir.join("jump-maps-wide-blend.png");
    img.save(&out).unwrap();
    println!("{}", out.display());
}
