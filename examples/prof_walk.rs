use std::time::Instant;
use texsyn::artifact::Artifact;
use texsyn::artifact::jump_maps::*;
use texsyn::stages::analyse_exemplar::jump_map::{JumpMapParams, build_jump_map};
use texsyn::stages::field::orientation_field::{FieldParams, orientation_field};
use texsyn::stages::parameterize::edge_offsets::{edge_offsets, validity_boxes};
use texsyn::stages::parameterize::region_growing::region_growing_order;
use texsyn::stages::synthesize::jump_walk::{WalkParams, jump_walk};
fn main() {
    let p = std::path::Path::new("../shared/data/meshes/refined_elephant.off");
    let mesh = texsyn::geom::io::read_mesh(p).unwrap();
    let mesh = texsyn::bench::subdivide(&texsyn::bench::subdivide(&mesh));
    let n = mesh.vertex_count();
    let img_p = std::path::Path::new("tests/data/exemplars/marble1.png");
    let img = texsyn::image::decode_image(img_p, &std::fs::read(img_p).unwrap()).unwrap();
    let jm = build_jump_map(img.view(), &JumpMapParams::default(), &|_| {});
    let field = orientation_field(
        &mesh,
        &FieldParams {
            isotropic: true,
            ..Default::default()
        },
    )
    .unwrap();
    let adj = mesh.adjacency();
    let scale = 4.0 / mesh.mean_edge_length();
    let off = edge_offsets(&mesh, adj, &field, scale);
    let boxes = validity_boxes(adj, &off);
    let order = region_growing_order(adj, 0);
    let bytes = write_parameterization(&ParamParts {
        meta: ParamMeta {
            vertices: n as u64,
            scale,
            exemplar: (jm.width, jm.height),
            components: 1,
        },
        order: &order.order,
        seeds: &order.seeds,
        adj_offsets: &adj.offsets,
        neighbors: &adj.neighbors,
        edge_offsets: &off,
        boxes: &boxes,
    });
    let art = Artifact::from_bytes(bytes).unwrap();
    let param = view_parameterization(&art).unwrap();
    for _ in 0..5 {
        let t = Instant::now();
        let w = jump_walk(
            param.walk_input(),
            jm.as_ref(),
            &WalkParams::default(),
            &|_| {},
        );
        println!("{n} walk {:?} jumps {}", t.elapsed(), w.jumps);
    }
}
