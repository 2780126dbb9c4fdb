//! The geometry-image method's two synthesizers side by side, as a user sees them: for each
//! case, `texsyn run` with `synthesize.algorithm = "template"` and then `"appearance"` (fresh
//! cache), and one view of each `preview.png` (its views are squares side by side) next to
//! each other in `gi-<case>-algorithms.png` (template left, appearance right). Cases: relief_cow and dragon_elephant as shipped, and
//! the untuned photo relief of BENCHMARKS.md (mushroom.off with crinklepaper.png, a colour
//! photo read as a height field, relief_cow's settings otherwise), which needs
//! ../shared/data and is skipped, saying so, without it.
//!
//! ```text
//! cargo build --release && cargo run --release -p texsyn-bench --example gi_algorithm_pictures -- [OUT_DIR]
//! ```

mod common;

use std::path::{Path, PathBuf};

/// Runs `config` with the algorithm and extra `--set`s into `out`; the preview's path.
fn preview(config: &Path, algorithm: &str, sets: &[String], out: &Path) -> PathBuf {
    let mut all = vec![format!("synthesize.algorithm=\"{algorithm}\"")];
    all.extend_from_slice(sets);
    common::run_preview(config, &all, out)
}

fn main() {
    let dir = common::out_dir();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let shared = repo.join("../shared/data");
    // (name, config, --sets, the preview's view to show)
    let mut cases: Vec<(&str, PathBuf, Vec<String>, u32)> = vec![
        (
            "relief-cow",
            repo.join("configs/relief_cow.toml"),
            vec![],
            0,
        ),
        (
            "dragon-elephant",
            repo.join("configs/dragon_elephant.toml"),
            vec![],
            2,
        ),
    ];
    let (mushroom, paper) = (
        shared.join("meshes/mushroom.off"),
        shared.join("exemplars/crinklepaper.png"),
    );
    if mushroom.exists() && paper.exists() {
        cases.push((
            "mushroom-crinklepaper-untuned",
            repo.join("configs/relief_cow.toml"),
            vec![
                format!("inputs.mesh={:?}", mushroom.display().to_string()),
                format!("inputs.sample={:?}", paper.display().to_string()),
            ],
            2,
        ));
    } else {
        println!(
            "{} not found: the untuned photo relief is skipped",
            shared.display()
        );
    }
    for (name, config, sets, view) in cases {
        let t = preview(
            &config,
            "template",
            &sets,
            &dir.join(format!("{name}-template")),
        );
        let a = preview(
            &config,
            "appearance",
            &sets,
            &dir.join(format!("{name}-appearance")),
        );
        let out = dir.join(format!("gi-{name}-algorithms.png"));
        common::preview_strip(&[t, a], view, &out);
        println!("wrote {}", out.display());
    }
}
