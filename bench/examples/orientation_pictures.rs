//! The orientation controls as a user sees them, one picture each (one view of each run's
//! `preview.png`, side by side, each run in a fresh cache):
//! - `graph-matching-sink.png`: configs/graph_matching_open.toml (wood2's stripes on the
//!   mushroom) as shipped (the default flow along the longest axis), with a sink at the centre
//!   of the round cap (the stripes run into it), and with the same sink and
//!   `field.rotation = 90` (rings around it); the third view, from above.
//! - `jump-maps-symmetry.png`: jump maps (configs/demo.toml's settings) on the genus-3
//!   elephant with parque1's four-fold parquet, `field.symmetry = 1` then `4`; the first view.
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
}
