//! Scoring graph matching (Bangay & Morkel): colours per vertex, resampled into the
//! exemplar's frame.
//!
//! The method makes one colour per vertex of the finest √2-subdivision level and bakes no
//! texture (§3.5). Its synthesis reads the surface through one texture-space step per edge
//! (`Level::step` in stages/synthesize/graph_matching.rs): the edge projected onto the
//! vertex's (right, −up) frame of the sweep field, kept at its length, times `scale` texels
//! per unit. The same step, summed outward from 64 seeded vertices over the finest level's
//! triangulated edges, unfolds discs of the surface into exemplar texels
//! ([`super::charts::unfolded_discs`]); their triangles are filled by interpolating the
//! vertex colours, and the discs are scored against the exemplar. So the picture is the
//! texture as the method lays it out, at one texel per exemplar texel.
//!
//! Limits: colours between vertices are interpolated, so where edges are longer than a
//! texel the discs are smoother than the synthesis meant (the gradient ratio falls with the
//! edge length); near a singularity of the field the unfolding overlaps itself.

use super::charts::{EdgeOffsets, unfolded_discs};
use super::{Item, Run, ScoreFailure};
use crate::image::Image;
use crate::methods::graph_matching::GraphMatchingConfig;
use crate::stages::field::sweep_field::SweepField;
use crate::stages::parameterize::sqrt2_subdivision::Sqrt2Hierarchy;
use crate::stages::synthesize::graph_matching::GraphMatching;
use glam::{Vec2, Vec3};

pub(crate) fn graph_matching(run: &Run) -> Result<Item, ScoreFailure> {
    let c: GraphMatchingConfig = run
        .config
        .parse()
        .map_err(|e| ScoreFailure::new(e.to_string()))?;
    let scale = c.parameterize.scale;
    let h = run.view::<Sqrt2Hierarchy>("parameterize")?;
    let field = run.view::<SweepField>("field")?;
    let out = run.view::<GraphMatching>("synthesize")?;
    let ex = run.view::<Image>("import.exemplar")?;
    let level = h.level(h.levels() - 1);
    let normals = level.vertex_normals();
    let mesh = level.to_triangles();
    let n = mesh.positions.len();
    if out.colours.len() != n || field.orientation.len() < n {
        return Err(ScoreFailure::new(
            "internal error: colours, field and hierarchy disagree on the vertex count",
        ));
    }
    // The synthesis's frame per vertex: "up" is the field projected on the tangent plane.
    let (up, right): (Vec<Vec3>, Vec<Vec3>) = (0..n)
        .map(|v| {
            let (nrm, o) = (normals[v], field.orientation[v]);
            let t = (o - o.dot(nrm) * nrm)
                .try_normalize()
                .unwrap_or_else(|| nrm.any_orthonormal_vector());
            (t, t.cross(nrm))
        })
        .unzip();
    let step = |from: usize, to: usize| {
        let d = mesh.positions[to] - mesh.positions[from];
        let proj = Vec2::new(d.dot(right[from]), -d.dot(up[from]));
        let len = proj.length();
        if len > 0.0 {
            proj * (d.length() / len * scale)
        } else {
            Vec2::ZERO
        }
    };
    let mut nbrs: Vec<Vec<u32>> = vec![Vec::new(); n];
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            nbrs[a as usize].push(b);
            nbrs[b as usize].push(a);
        }
    }
    let (mut adj, mut neighbors, mut offsets) = (vec![0u32], Vec::new(), Vec::new());
    for (v, list) in nbrs.iter_mut().enumerate() {
        list.sort_unstable();
        list.dedup();
        for &w in list.iter() {
            neighbors.push(w);
            offsets.push(step(v, w as usize));
        }
        adj.push(neighbors.len() as u32);
    }
    let edges = EdgeOffsets {
        adj_offsets: &adj,
        neighbors: &neighbors,
        edge_offsets: &offsets,
    };
    let colours = &out.colours;
    let charts = unfolded_discs(&mesh.triangles, &edges, run.params.seed, |f, b| {
        let t = mesh.triangles[f];
        let mut c = [0.0f32, 0.0, 0.0, 1.0];
        for (k, w) in b.to_array().into_iter().enumerate() {
            for ch in 0..3 {
                c[ch] += w * colours[t[k] as usize][ch];
            }
        }
        c
    });
    let mut item = Item::new(
        format!(
            "the finest level's vertex colours, {} discs unfolded along the field",
            charts.discs
        ),
        "inputs.exemplar",
    );
    let mean_edge = mesh.mean_edge_length() * scale;
    item.extra
        .insert("texels_per_edge".into(), serde_json::json!(mean_edge));
    run.score_into(&mut item, charts.image.view(), Some(&charts.mask), ex)?;
    Ok(item)
}
