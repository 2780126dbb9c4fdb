//! Table 1/2-style numbers for solid synthesis (stages/synthesize/solid/solid_synthesis/,
//! candidate triples of Dong et al. 2008): the analysis time of an
//! exemplar (128² marble1: 4 levels, N = 7 then 9, k = 4 candidates), then the middle z
//! section of a 128³ volume synthesized from scratch with the dual-grid scheme and with the
//! standard one, each with its total time and a per-level table of bricks, voxels,
//! corrections, comparisons and seconds.
//!
//! ```text
//! cargo run --release -p texsyn-bench --example solid_bench_table
//! ```
//!
//! Environment: `EXEMPLAR`, a file in tests/data/exemplars or an absolute path (default
//! marble1.png); `SIZE`, the volume's side (default 128); `RAYON_NUM_THREADS`. Writes no
//! files.

mod common;
#[path = "../../tests/it/common/exemplars.rs"]
mod exemplars;
#[path = "../../tests/it/common/solid.rs"]
mod solid;

use common::env_or;
use exemplars::load_exemplar as load;
use solid::trivial_cube;
use texsyn::stages::analyse_exemplar::candidate_triples::{CandidateParams, analyse};
use texsyn::stages::synthesize::solid::solid_synthesis::{
    MemoryBrickStore, Scheme, SolidParams, SolidSynthesis, VoxelRequest,
};

fn main() {
    let name: String = env_or("EXEMPLAR", "marble1.png".to_string());
    let img = load(&name);
    let t = std::time::Instant::now();
    let a = analyse([img.view(); 3], &CandidateParams::default()).unwrap();
    println!(
        "analysis {name} {}×{} (L=4, N=7/9, k=4): {:.2} s on {} threads",
        img.width,
        img.height,
        t.elapsed().as_secs_f64(),
        rayon::current_num_threads()
    );
    let n: u32 = env_or("SIZE", 128);
    let (vol, field) = trivial_cube(n);
    let req = VoxelRequest::from_box([0, 0, n as i32 / 2], [n as i32, n as i32, n as i32 / 2 + 1]);
    for (label, params) in [
        ("dual-grid", SolidParams::paper(4)),
        ("standard", SolidParams::paper(4).with_scheme(Scheme::Plain)),
    ] {
        let s = SolidSynthesis::new(a.as_ref(), &field, vol, params).unwrap();
        let t = std::time::Instant::now();
        let rep = s.synthesize(&req, &MemoryBrickStore::new()).unwrap();
        println!("{label}: {:.2} s in all", t.elapsed().as_secs_f64());
        println!("level | bricks | voxels | corrections | comparisons | seconds");
        for l in &rep.levels {
            println!(
                "{} | {} | {} | {} | {} | {:.2}",
                l.level, l.bricks_computed, l.voxels, l.corrections, l.comparisons, l.seconds
            );
        }
    }
}
