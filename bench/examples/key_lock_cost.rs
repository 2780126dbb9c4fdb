//! The cost of one key lock (README, "Several processes on one cache"): take and release the
//! lock of `N` distinct keys in a cache folder, first creating each lock file (a node's first
//! computation), then again with the files there (a recomputation), and an uncontended
//! `try_lock` for comparison. Prints the median per lock of five rounds of each.
//!
//! ```text
//! cargo run --release -p texsyn-bench --example key_lock_cost [CACHE_DIR]
//! ```
//!
//! `CACHE_DIR` (default: a temporary folder on the local disk) is where the locks go: give a
//! folder on another filesystem (NFS) to measure it there. Leaves no lock files behind.

use std::time::Instant;
use texsyn::artifact::ContentHash;
use texsyn::cache::{Cache, Locking};

const N: u32 = 2000;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let tmp = tempfile::tempdir().expect("a temporary folder");
    let root = std::env::args()
        .nth(1)
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| tmp.path().to_owned());
    let cache = Cache::open(&root).expect("a cache");
    let locks = cache.locks();
    let (mut fresh, mut again, mut try_again) = (Vec::new(), Vec::new(), Vec::new());
    for round in 0..5u32 {
        let keys: Vec<ContentHash> = (0..N)
            .map(|i| ContentHash::of(&[round.to_le_bytes(), i.to_le_bytes()].concat()))
            .collect();
        for (times, blocking) in [
            (&mut fresh, true),
            (&mut again, true),
            (&mut try_again, false),
        ] {
            let t = Instant::now();
            for k in &keys {
                let held = if blocking {
                    locks.lock(k, || panic!("nobody else holds it"))
                } else {
                    locks.try_lock(k)
                };
                assert!(matches!(held, Locking::Held(_)), "{held:?}");
            }
            times.push(t.elapsed().as_secs_f64() / N as f64 * 1e6);
        }
        locks.remove_unused();
    }
    println!("key lock + unlock in {}:", root.display());
    println!("  lock file created:     {:.1} µs", median(fresh));
    println!("  lock file there:       {:.1} µs", median(again));
    println!("  try_lock, file there:  {:.1} µs", median(try_again));
}
