//! Times geometric texture synthesis in the paper's setting (Lai et al. 2005, §4.3): a 257²
//! geometry image (a cylinder, so the seam is resynthesized), a 64² sample of random bumps,
//! 3 levels, 8 orientations × 3 scales of variants; the direction turns along the columns and
//! the relative scale goes from 0.5 to 2 down the rows.
//!
//! Prints the time to build the variants, then the median of three syntheses (seeds 0, 1, 2),
//! all three times and the number of threads:
//!
//! ```text
//! cargo run --release -p texsyn-bench --example geometry_texture_timing
//! ```
//!
//! Threads: `RAYON_NUM_THREADS` (default: one per core). Writes no files.

#[path = "../../tests/it/common/geometry_texture.rs"]
mod geometry_texture;
use geometry_texture::{bumps, cylinder, synth, turning_field, variants};

fn main() {
    let sample = bumps(64, 11, false);
    let t = std::time::Instant::now();
    let v = variants(&sample);
    let build = t.elapsed().as_secs_f64();
    let n = 257;
    let gi = cylinder(n);
    let f = turning_field(n);
    let mut times = Vec::new();
    for seed in 0..3 {
        let t = std::time::Instant::now();
        let out = synth(&gi, &f, &v, seed);
        times.push(t.elapsed().as_secs_f64());
        assert_eq!(out.width, n);
    }
    times.sort_by(f64::total_cmp);
    println!(
        "variants: {build:.3} s; synthesis 257²: median {:.3} s (runs {times:?}); threads {}",
        times[1],
        rayon::current_num_threads()
    );
}
