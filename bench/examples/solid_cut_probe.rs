use std::time::Instant;
use texsyn::stages::analyse_exemplar::candidate_triples::{CandidateParams, analyse_transposed};
use texsyn::stages::field::quaternion_field::{FieldGrid, RotationField};
use texsyn::stages::parameterize::volume_embedding::{
    embed, outside_voxels, section, section_voxels_inside, surface_voxels,
};
use texsyn::stages::synthesize::solid::solid_synthesis::{
    BrickStore, MemoryBrickStore, SolidParams, SolidSynthesis, VoxelRequest,
};

/// User + system CPU seconds of this process (all threads).
fn cpu_seconds() -> f64 {
    texsyn::memory::process_cpu_seconds().unwrap_or(0.0)
}

fn main() {
    let p = std::path::Path::new("configs/assets/cow.obj");
    let mesh = texsyn::geom::io::read_mesh_bytes(p, &std::fs::read(p).unwrap()).unwrap();
    let ip = std::path::Path::new("configs/assets/wood2.png");
    let img = texsyn::image::decode_image(ip, &std::fs::read(ip).unwrap()).unwrap();
    let cp = CandidateParams {
        plane_weights: [1.0, 0.0, 1.0],
        ..Default::default()
    };
    let analysis =
        analyse_transposed([img.view(); 3], [None; 3], [false, false, true], &cp).unwrap();
    let emb = embed(&mesh, 512, 0.25).unwrap();
    let (lo, hi) = (emb.min(), emb.max());
    let field = RotationField::trivial(FieldGrid::covering(lo, hi, 24));
    let surface: Vec<[i32; 3]> = surface_voxels(&mesh, &emb)
        .iter()
        .map(|v| v.to_array())
        .collect();
    let synth = SolidSynthesis::new(analysis.as_ref(), &field, emb, SolidParams::paper(4)).unwrap();
    let store = MemoryBrickStore::new();
    let t = Instant::now();
    let skip = std::env::var_os("SKIP_SURFACE").is_some();
    let rep = if skip {
        Default::default()
    } else {
        synth
            .synthesize(&VoxelRequest::from_voxels(&surface), &store)
            .unwrap()
    };
    println!(
        "surface {:.2} s {:?}",
        t.elapsed().as_secs_f64(),
        rep.levels
            .iter()
            .map(|l| (l.voxels, l.seconds))
            .collect::<Vec<_>>()
    );
    let s = section(&emb, (lo + hi) * 0.5, glam::Vec3::new(0.0, 0.0, 1.0)).unwrap();
    let cut: Vec<[i32; 3]> = section_voxels_inside(&emb, &s, &outside_voxels(&mesh, &emb))
        .iter()
        .map(|v| v.to_array())
        .collect();
    let req = VoxelRequest::from_voxels(&cut);
    let runs: usize = std::env::var("RUNS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let mut checksum = 0u64;
    for _ in 0..runs {
        let fresh = MemoryBrickStore::new();
        for l in 1..=4 {
            for b in store.bricks(l) {
                fresh.put(l, b, store.get(l, b).unwrap());
            }
        }
        let t = Instant::now();
        let _ = synth.dependent_set(&req);
        let tp = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let c0 = cpu_seconds();
        let rep = synth.synthesize(&req, &fresh).unwrap();
        println!("cpu {:.2} s", cpu_seconds() - c0);
        println!(
            "cut {:.2} s (plan alone {:.2} s) {:?}",
            t.elapsed().as_secs_f64(),
            tp,
            rep.levels
                .iter()
                .map(|l| (l.bricks_computed, l.voxels, l.seconds))
                .collect::<Vec<_>>()
        );
        checksum = 0;
        for v in &cut {
            let c = synth.triple_at(&fresh, 4, *v).unwrap();
            for x in c.c.iter().flatten() {
                checksum = checksum.wrapping_mul(31).wrapping_add(*x as u64);
            }
        }
    }
    println!("checksum {checksum:x}");
}
