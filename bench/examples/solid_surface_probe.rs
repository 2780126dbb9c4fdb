//! The bench's cow surface row (wood2 in xy and zx, trivial field, 4 levels, dual-grid) at
//! `RESOLUTION` voxels (default 256): CPU seconds of the synthesis alone, per level, and a
//! checksum of every brick it made (to compare builds and thread counts byte for byte).
//!
//! `cargo run --release -p texsyn-bench --example solid_surface_probe` (from the repository root);
//! `BATCH_SCALE=k` runs with both `BatchLimits` k times the default.
use std::time::Instant;
use texsyn::stages::analyse_exemplar::candidate_triples::{CandidateParams, analyse_transposed};
use texsyn::stages::field::quaternion_field::{FieldGrid, RotationField};
use texsyn::stages::parameterize::volume_embedding::{embed, surface_voxels};
use texsyn::stages::synthesize::solid::solid_synthesis::{
    BatchLimits, BrickStore, MemoryBrickStore, SolidParams, SolidSynthesis, VoxelRequest,
};

/// User + system CPU seconds of this process (all threads).
fn cpu_seconds() -> f64 {
    texsyn::memory::process_cpu_seconds().unwrap_or(0.0)
}

fn main() {
    let resolution: u32 = std::env::var("RESOLUTION")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(256);
    let p = std::path::Path::new("configs/assets/cow.obj");
    let mesh = texsyn::geom::io::read_mesh_bytes(p, &std::fs::read(p).expect("cow.obj"))
        .expect("cow.obj parses");
    let ip = std::path::Path::new("configs/assets/wood2.png");
    let img = texsyn::image::decode_image(ip, &std::fs::read(ip).expect("wood2.png"))
        .expect("wood2.png decodes");
    let cp = CandidateParams {
        plane_weights: [1.0, 0.0, 1.0],
        ..Default::default()
    };
    let analysis = analyse_transposed([img.view(); 3], [None; 3], [false, false, true], &cp)
        .expect("analysis");
    let emb = embed(&mesh, resolution, 0.25).expect("embedding");
    let (lo, hi) = (emb.min(), emb.max());
    let field = RotationField::trivial(FieldGrid::covering(lo, hi, 24));
    let surface: Vec<[i32; 3]> = surface_voxels(&mesh, &emb)
        .iter()
        .map(|v| v.to_array())
        .collect();
    let mut synth = SolidSynthesis::new(analysis.as_ref(), &field, emb, SolidParams::paper(4))
        .expect("synthesis");
    // BATCH_SCALE=k: both batch limits k times the default (the voxels do not change).
    if let Some(k) = std::env::var("BATCH_SCALE")
        .ok()
        .and_then(|s| s.parse::<u64>().ok())
    {
        let d = BatchLimits::default();
        synth = synth.with_batch_limits(BatchLimits {
            box_voxels: d.box_voxels * k,
            chunk_voxels: d.chunk_voxels * k,
        });
    }
    let store = MemoryBrickStore::new();
    let (t, c0) = (Instant::now(), cpu_seconds());
    let rep = synth
        .synthesize(&VoxelRequest::from_voxels(&surface), &store)
        .expect("synthesize");
    let (wall, used) = (t.elapsed().as_secs_f64(), cpu_seconds() - c0);
    // FNV-1a over every brick of every level, in sorted order.
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for level in 1..=4 {
        for b in store.bricks(level) {
            let brick = store.get(level, b).expect("listed");
            for (_, bytes) in brick.arrays() {
                for &x in bytes {
                    h = (h ^ x as u64).wrapping_mul(0x100_0000_01b3);
                }
            }
        }
    }
    for l in &rep.levels {
        println!(
            "level {}: {} voxels, {} corrections, {} comparisons, {:.2} s wall, {} batches (largest {} working voxels)",
            l.level,
            l.voxels,
            l.corrections,
            l.comparisons,
            l.seconds,
            l.batches,
            l.largest_batch_voxels
        );
    }
    let hwm = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .map(|l| l.split_whitespace().nth(1).unwrap_or("0").to_string())
        })
        .unwrap_or_default();
    println!("peak (VmHWM) {hwm} kB, with every level's bricks kept (MemoryBrickStore)");
    println!(
        "resolution {resolution}: {} surface voxels, synthesize {wall:.2} s wall, {used:.2} s CPU, checksum {h:016x}",
        surface.len()
    );
}
