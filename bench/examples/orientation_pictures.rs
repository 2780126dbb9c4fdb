//! The orientation controls as a user sees them, one picture each (one view of each run's
//! `preview.png`, side by side, each run in a fresh cache):
//! - `graph-matching-sink.png`: configs/graph_matching_open.toml (wood2's stripes on the
//!   mushroom) as shipped (the default flow along the longest axis), with a sink at the centre
//!   of the round cap (the stripes run into it), and with the same sink and
//!   `field.rotation = 90` (rings around it); the third view, from above.
//! - `jump-maps-symmetry.png`: jump maps (configs/demo.toml's settings) on the genus-3
//!   elephant with parque1's four-fold parquet, `field.symmetry = 1` then `4`; the first view.
//! - `feature-aligned-fixed.png`: feature-aligned texturing of the cow with parque1 along four
//!   spokes drawn outward from one point of its flank (configs/feature_aligned_curves.toml's
//!   settings, these curves only): `field.png` and `preview.png` with the spokes free (§4.1
//!   joins the collinear pairs and orients them through the centre), then with every spoke
//!   `fixed = true` (the field leaves the centre along all four); the first view.
//!
//! ```text
//! cargo build --release && cargo run --release -p texsyn-bench --example orientation_pictures -- [OUT_DIR]
//! ```

mod common;

use std::path::Path;

/// A picture's file, its config, its runs as (name, --sets), and the preview's view to show.
type Picture<'a> = (&'a str, &'a str, Vec<(&'a str, Vec<&'a str>)>, u32);

fn main() {
    let dir = common::out_dir();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let sink = "field.sinks=[{ at = [0.0, 0.0, 0.232] }]"; // the round cap's centre (z up)
    let elephant = [
        "inputs.mesh=\"assets/elephant.off\"",
        "inputs.exemplar=\"assets/parque1.png\"",
        "parameterize.scale=\"auto\"",
        "parameterize.rotation=0",
        "reconstruct.up=\"auto\"",
    ];
    let with = |extra: &[&'static str]| [&elephant[..], extra].concat();
    let pictures: [Picture; 2] = [
        (
            "graph-matching-sink.png",
            "configs/graph_matching_open.toml",
            vec![
                ("shipped", vec![]),
                ("sink", vec![sink]),
                ("sink-rotation", vec![sink, "field.rotation=90"]),
            ],
            2,
        ),
        (
            "jump-maps-symmetry.png",
            "configs/demo.toml",
            vec![
                ("symmetry1", with(&["field.symmetry=1"])),
                ("symmetry4", with(&["field.symmetry=4"])),
            ],
            0,
        ),
    ];
    for (picture, config, runs, view) in &pictures {
        let mut previews = Vec::new();
        for (name, sets) in runs {
            let out = dir.join(format!("orientation-{name}"));
            let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
            previews.push(common::run_preview(&repo.join(config), &sets, &out));
            println!("{name}: {}", out.display());
        }
        let out = dir.join(picture);
        common::preview_strip(&previews, *view, &out);
        println!("{}", out.display());
    }
    fixed_spokes(&dir, &repo);
}

/// `feature-aligned-fixed.png` (see the module doc).
fn fixed_spokes(dir: &Path, repo: &Path) {
    let centre = "[-0.136, 0.059, 0.152]";
    let ends = [
        "[-0.074, 0.058, 0.141], [0.017, 0.046, 0.12]",
        "[-0.217, 0.04, 0.145], [-0.272, 0.044, 0.135]",
        "[-0.146, 0.084, 0.14], [-0.162, 0.157, 0.08]",
        "[-0.123, -0.045, 0.158]",
    ];
    let assets = repo.join("configs/assets").canonicalize().unwrap();
    let (mut fields, mut previews) = (Vec::new(), Vec::new());
    for fixed in [false, true] {
        let name = ["spokes-free", "spokes-fixed"][fixed as usize];
        let curves: Vec<String> = ends
            .iter()
            .map(|e| format!("  {{ points = [{centre}, {e}], fixed = {fixed} }},\n"))
            .collect();
        let config = format!(
            "method = \"feature_aligned\"\ncompare = false\n[inputs]\nmesh = {:?}\n\
             exemplar = {:?}\n[extract]\nfeatures = \"curves\"\ncurves = [\n{}]\n\
             [parameterize]\nscale = 160.0\n[synthesize]\npatch = 12\nseed = 1\n\
             [reconstruct]\nup = [0, 1, 0]\n",
            assets.join("cow.obj"),
            assets.join("parque1.png"),
            curves.concat()
        );
        let out = dir.join(format!("orientation-{name}"));
        std::fs::create_dir_all(&out).unwrap();
        let path = out.join(format!("{name}.toml"));
        std::fs::write(&path, config).unwrap();
        let preview = common::run_preview(&path, &[], &out);
        fields.push(out.join("field.png"));
        previews.push(preview);
        println!("{name}: {}", out.display());
    }
    let out = dir.join("feature-aligned-fixed.png");
    common::preview_strip(&[fields, previews].concat(), 0, &out);
    println!("{}", out.display());
}
