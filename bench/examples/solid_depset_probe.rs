//! Per-level dependent sets of the bench's cow (wood2, trivial field, 4 levels), planning
//! only: `cargo run --release -p texsyn-bench --example solid_depset_probe -- RESOLUTION SCHEME REQUEST`, with
//! SCHEME `dual` or `plain` and REQUEST `surface` (default) or `cut-x`, `cut-y`, `cut-z` (the
//! voxels inside the mesh on the plane through the volume's centre with that normal). Prints
//! what `SolidSynthesis::dependent_set` reports (distinct voxels per level) with the flat
//! stencil and with the cube, and the same from exact targets (no brick rounding).
//! `BATCH_SCALE=k` multiplies both `BatchLimits` by k; `QUICK=1` prints the flat stencil's
//! sets only; `PLAN_ONLY=1` times the planning a synthesis does.
use glam::IVec3;
use texsyn::stages::analyse_exemplar::candidate_triples::{CandidateParams, analyse_transposed};
use texsyn::stages::field::quaternion_field::{FieldGrid, RotationField};
use texsyn::stages::parameterize::volume_embedding::{
    embed, outside_voxels, section, section_voxels_inside, surface_voxels,
};
use texsyn::stages::synthesize::solid::dependent_set::dependent_set;
use texsyn::stages::synthesize::solid::solid_synthesis::{
    BatchLimits, Pyramid, Scheme, SolidParams, SolidSynthesis, VoxelRequest,
};

/// User + system CPU seconds of this process (all threads).
fn cpu_seconds() -> f64 {
    texsyn::memory::process_cpu_seconds().unwrap_or(0.0)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let resolution: u32 = args.get(1).map_or(512, |s| s.parse().unwrap());
    let scheme = match args.get(2).map(String::as_str) {
        Some("plain") => Scheme::Plain,
        _ => Scheme::DualGrid,
    };
    let what = args.get(3).map_or("surface", String::as_str);
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
    let emb = embed(&mesh, resolution, 0.25).unwrap();
    let pyr = Pyramid {
        volume: emb,
        levels: 4,
    };
    let field = RotationField::trivial(FieldGrid::covering(emb.min(), emb.max(), 24));
    let targets: Vec<[i32; 3]> = match what {
        "surface" => surface_voxels(&mesh, &emb)
            .iter()
            .map(|v| v.to_array())
            .collect(),
        cut => {
            let axis = match cut {
                "cut-x" => 0,
                "cut-y" => 1,
                _ => 2,
            };
            let mut normal = glam::Vec3::ZERO;
            normal[axis] = 1.0;
            let s = section(&emb, (emb.min() + emb.max()) * 0.5, normal).unwrap();
            section_voxels_inside(&emb, &s, &outside_voxels(&mesh, &emb))
                .iter()
                .map(|v| v.to_array())
                .collect()
        }
    };
    println!(
        "{what}: {} voxels in a {:?} volume, {scheme:?}",
        targets.len(),
        emb.dims
    );
    let request = VoxelRequest::from_voxels(&targets);
    let params = SolidParams::paper(4).with_scheme(scheme);
    // BATCH_SCALE=k multiplies both batch limits by k (how the overlap changes with them).
    let scale: u64 = std::env::var("BATCH_SCALE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let limits = BatchLimits::default();
    let limits = BatchLimits {
        box_voxels: limits.box_voxels * scale,
        chunk_voxels: limits.chunk_voxels * scale,
    };
    println!("batch limits {limits:?}");
    let synth = SolidSynthesis::new(analysis.as_ref(), &field, emb, params.clone())
        .unwrap()
        .with_batch_limits(limits);
    let cube = SolidSynthesis::new(analysis.as_ref(), &field, emb, params)
        .unwrap()
        .cube_stencil()
        .with_batch_limits(limits);
    println!("reach {:?}", synth.reach());
    // PLAN_ONLY=1: time the planning `synthesize` does (against an empty store) and stop.
    if std::env::var_os("PLAN_ONLY").is_some() {
        let store = texsyn::stages::synthesize::solid::solid_synthesis::MemoryBrickStore::new();
        let (t, c0) = (std::time::Instant::now(), cpu_seconds());
        let plan = synth.plan_report(&request, &store);
        println!(
            "planned in {:.2} s wall, {:.2} s CPU: bricks per level {:?}",
            t.elapsed().as_secs_f64(),
            cpu_seconds() - c0,
            plan.iter().map(|l| l.bricks_computed).collect::<Vec<_>>()
        );
        return;
    }
    // QUICK=1: the flat stencil's batched sets only (no cube, no exact targets).
    let quick = std::env::var_os("QUICK").is_some();
    let runs: &[(&str, &SolidSynthesis)] = if quick {
        &[("flat stencil", &synth)]
    } else {
        &[("flat stencil", &synth), ("cube stencil", &cube)]
    };
    for &(name, s) in runs {
        let t = std::time::Instant::now();
        let set = s.dependent_set(&request);
        println!("{name}: planned in {:.2} s", t.elapsed().as_secs_f64());
        for d in set {
            let dims = pyr.level_dims(d.level);
            let all = dims.x as f64 * dims.y as f64 * dims.z as f64;
            println!(
                "{name} L{}: bricks {} voxels {} ({:.0}% of the level) corr {} synthesized {}",
                d.level,
                d.bricks.len(),
                d.voxels,
                100.0 * d.voxels as f64 / all,
                d.corrections,
                d.batch_voxels
            );
        }
    }
    if quick {
        return;
    }
    let mut exact: Vec<IVec3> = targets.iter().map(|v| IVec3::from(*v)).collect();
    for level in (1..=4u32).rev() {
        let li = (level - 1) as usize;
        let boxes: Vec<(IVec3, IVec3)> = exact.iter().map(|&v| (v, v + 1)).collect();
        let g = dependent_set(
            &synth.schedules()[li],
            pyr.level_dims(level),
            &boxes,
            synth.stencil(li),
        );
        println!(
            "exact targets, flat stencil L{level}: voxels {} corr {}",
            g.voxels(),
            g.corrections()
        );
        let mut set = std::collections::BTreeSet::new();
        for (i, &x) in g.need.iter().enumerate() {
            if x > 0 {
                set.insert(<[i32; 3]>::from(g.position(i).div_euclid(IVec3::splat(2))));
            }
        }
        exact = set.into_iter().map(IVec3::from).collect();
    }
}
