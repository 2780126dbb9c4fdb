//! Fig. 6 of Bangay & Morkel (§3.2.2) as a table: the area spread (standard deviation of face
//! area over its mean) of adaptive pre-subdivision against the threshold factor f, round by
//! round, on the shipped meshes, with the paper's fixed rounds (`parameterize.adaptive_min_gain
//! = 0`) and where the default early stop (a round must lower the spread by 10 %) ends.
//!
//! ```text
//! cargo run --release -p texsyn-bench --example gm_area_spread
//! ```
//!
//! `ROUNDS` [16]: rounds per factor.

mod common;

use common::env_or;
use std::path::Path;
use texsyn::geom::poly_mesh::PolyMesh;
use texsyn::stages::parameterize::sqrt2_subdivision::adaptive_presubdivision;

fn main() {
    let rounds: u32 = env_or("ROUNDS", 16);
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    println!(
        "| mesh | f | spread before | after rounds 1 / 2 / 4 / 8 / {rounds} | lowest | vertices after {rounds} | default stop: rounds, spread |"
    );
    println!("|---|---:|---:|---|---:|---:|---|");
    for name in ["cow.obj", "elephant.off", "mushroom.off"] {
        let path = repo.join("configs/assets").join(name);
        let mesh = texsyn::geom::io::read_mesh(&path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let poly = PolyMesh::from_mesh(&mesh);
        for f in [1.0f32, 1.25, 1.5, 2.0, 3.0, 4.0] {
            let (out, _, spread) = adaptive_presubdivision(&poly, f, rounds);
            let pct = |i: usize| {
                // A run that stopped (no face over the threshold) keeps its last spread.
                format!("{:.1}", 100.0 * spread[i.min(spread.len() - 1)])
            };
            let marks: Vec<String> = [1, 2, 4, 8, rounds as usize]
                .iter()
                .map(|&i| pct(i))
                .collect();
            let lowest = spread.iter().copied().fold(f32::INFINITY, f32::min);
            let kept = (1..spread.len())
                .take_while(|&i| spread[i] <= 0.9 * spread[i - 1])
                .count();
            let stopped = if spread.len() - 1 < rounds as usize {
                format!(" (no face over f after {})", spread.len() - 1)
            } else {
                String::new()
            };
            println!(
                "| {name} | {f} | {} | {}{stopped} | {:.1} | {} | {kept}, {} |",
                pct(0),
                marks.join(" / "),
                100.0 * lowest,
                out.vertex_count(),
                pct(kept),
            );
        }
    }
}
