use glam::IVec3;
use texsyn::stages::analyse_exemplar::candidate_triples::{CandidateParams, analyse_transposed};
use texsyn::stages::field::quaternion_field::{FieldGrid, RotationField};
use texsyn::stages::parameterize::volume_embedding::{embed, surface_voxels};
use texsyn::stages::synthesize::solid::dependent_set::dependent_set;
use texsyn::stages::synthesize::solid::solid_synthesis::{
    Pyramid, SolidParams, SolidSynthesis, VoxelRequest,
};

fn main() {
    let p = std::path::Path::new("configs/assets/cow.obj");
    let mesh = texsyn::geom::io::read_mesh_bytes(p, &std::fs::read(p).unwrap()).unwrap();
    let ip = std::path::Path::new("configs/assets/wood2.png");
    let img = texsyn::image::decode_image(ip, &std::fs::read(ip).unwrap()).unwrap();
    let cp = CandidateParams {
        plane_weights: [1.0, 0.0, 1.0],
        ..Default::default()
    };
    let analysis = analyse_transposed([img.view(); 3], [false, false, true], &cp).unwrap();
    let emb = embed(&mesh, 512, 0.25).unwrap();
    let pyr = Pyramid {
        volume: emb,
        levels: 4,
    };
    let field = RotationField::trivial(FieldGrid::covering(emb.min(), emb.max(), 24));
    let surface: Vec<[i32; 3]> = surface_voxels(&mesh, &emb)
        .iter()
        .map(|v| v.to_array())
        .collect();
    let request = VoxelRequest::from_voxels(&surface);
    let synth = SolidSynthesis::new(analysis.as_ref(), &field, emb, SolidParams::paper(4)).unwrap();
    println!("reach {:?}", synth.reach());
    for d in synth.dependent_set(&request) {
        println!(
            "current L{}: bricks {} voxels {} corr {}",
            d.level,
            d.bricks.len(),
            d.voxels,
            d.corrections
        );
    }
    for dr in [0, 1] {
        let mut targets: Vec<IVec3> = surface.iter().map(|v| IVec3::from(*v)).collect();
        for level in (1..=4u32).rev() {
            let li = (level - 1) as usize;
            let boxes: Vec<(IVec3, IVec3)> = targets.iter().map(|&v| (v, v + 1)).collect();
            let g = dependent_set(
                &synth.schedules()[li],
                pyr.level_dims(level),
                &boxes,
                synth.reach()[li] - dr,
            );
            println!(
                "exact targets, reach-{dr} L{level}: voxels {} corr {}",
                g.voxels(),
                g.corrections()
            );
            let mut set = std::collections::BTreeSet::new();
            for (i, &x) in g.need.iter().enumerate() {
                if x > 0 {
                    set.insert(<[i32; 3]>::from(g.position(i).div_euclid(IVec3::splat(2))));
                }
            }
            targets = set.into_iter().map(IVec3::from).collect();
        }
    }
}
