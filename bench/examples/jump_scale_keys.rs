//! Jump maps' `parameterize.scale_keys` as a user sees them, and what they cost the seams:
//! `jump-maps-scale-keys.png` is the demo cow with brick at one scale (left) and with keys of
//! 0.4 at the tail and 2.5 at the nose (right), the first view of each `preview.png`; the
//! table is `texsyn score` of both (the OBJ's seam ratio, the blended seams and the discs'
//! numbers). Each run has a fresh cache.
//!
//! ```text
//! cargo build --release && cargo run --release -p texsyn-bench --example jump_scale_keys -- [OUT_DIR]
//! ```

mod common;

use std::path::Path;

fn main() {
    let dir = common::out_dir();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let demo = repo.join("configs/demo.toml");
    let base = [
        "inputs.exemplar=\"assets/brick.png\"",
        "parameterize.rotation=0",
    ];
    let keys = "parameterize.scale_keys=[{ at = [-0.5, -0.15, 0.0], factor = 0.4 }, \
                { at = [0.5, 0.16, 0.0], factor = 2.5 }]";
    println!("| run | OBJ seams | blended seams | disc ratio | coverage | gradient ratio |");
    println!("|---|---:|---:|---:|---:|---:|");
    let mut previews = Vec::new();
    for (name, extra) in [("one scale", None), ("keys 0.4 / 2.5", Some(keys))] {
        let sets: Vec<String> = base
            .iter()
            .copied()
            .chain(extra)
            .map(str::to_string)
            .collect();
        let out = dir.join(format!("scale-keys-{}", previews.len()));
        previews.push(common::run_preview(&demo, &sets, &out));
        let mut cmd = std::process::Command::new(common::texsyn_binary());
        cmd.arg("score")
            .arg(&demo)
            .arg("--cache")
            .arg(out.join("score-cache"))
            .arg("--json");
        for s in &sets {
            cmd.arg("--set").arg(s);
        }
        let o = cmd.output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::remove_dir_all(out.join("score-cache")).ok();
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let (s, x) = (&v["items"][0]["score"], &v["items"][0]["extra"]);
        let f = |v: &serde_json::Value| v.as_f64().unwrap();
        println!(
            "| {name} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
            f(&x["seams"]["ratio"]),
            f(&x["blended_seams"]["ratio"]),
            f(&s["ratio"]),
            f(&s["coverage"]),
            f(&s["gradient_ratio"]),
        );
    }
    let out = dir.join("jump-maps-scale-keys.png");
    common::preview_strip(&previews, 0, &out);
    println!("{}", out.display());
}
