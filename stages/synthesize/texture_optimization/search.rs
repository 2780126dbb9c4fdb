//! The nearest-neighbour step: every sample's best exemplar patch for the current colours,
//! with the occurrence penalty that keeps rarely used exemplar blocks in play.

use super::candidates::{Candidates, Level, Rot};
use super::params::TextureOptimizationParams;
use super::patches::{Patches, SampleInfo};
use crate::image::knn::squared_distance;
use crate::synthesize::occurrence::BlockUse;
use rayon::prelude::*;

/// Nearest candidates in PCA space re-ranked by the full distance; more for samples whose grid
/// has empty cells (their query is partly the current match, which biases the tree search).
const SEARCH_K: usize = 4;
const SEARCH_K_PARTIAL: usize = 16;

/// Side, in texels, of the exemplar blocks whose use is counted by [`occurrence_penalty`]:
/// single positions are used too rarely (there are more candidates than samples) for a count
/// to mean anything.
pub(super) const HISTOGRAM_BLOCK: usize = 8;

/// Per candidate, `1 + weight · max(0, use/fair − 1)`: how much more than its fair share the
/// exemplar block around the candidate's centre is used by the current matches (Kopf et al.
/// 2007 §3.3 re-weight by the same excess). Counts come from `z` alone, so the result does not
/// depend on the thread count.
pub(super) fn occurrence_penalty(z: &[u32], cands: &Candidates, weight: f32) -> Vec<f32> {
    let n = cands.len();
    if weight == 0.0 || n == 0 {
        return vec![1.0; n];
    }
    let nx = cands.nx;
    let at = |c: usize| (c % nx, c / nx);
    // A block's fair share is proportional to the candidates it holds.
    let blocks = BlockUse::new(
        nx,
        n / nx,
        HISTOGRAM_BLOCK,
        z.iter().map(|&c| at(c as usize)),
        (0..n).map(at),
    );
    (0..n)
        .map(|c| {
            let (x, y) = at(c);
            blocks.factor(x, y, weight)
        })
        .collect()
}

/// The nearest-neighbour step: every sample's best exemplar patch for the current colours.
#[allow(clippy::too_many_arguments)]
pub(super) fn search(
    patches: &Patches,
    info: &SampleInfo,
    colours: &[[f32; 3]],
    z: &[u32],
    cands: &Candidates,
    level: Level,
    p: &TextureOptimizationParams,
    penalty: &[f32],
    source: &[[f32; 2]],
    rot: Rot,
) -> Vec<u32> {
    let dim = level.dim();
    let cells_per = level.w * level.w;
    let k = cands.pca.components();
    let tree = cands.tree.as_ref();
    (0..z.len())
        .into_par_iter()
        .map_init(
            || (vec![0.0f32; dim], vec![0.0f32; cells_per], vec![0.0f32; k]),
            |(query, weight, proj), i| {
                let current = z[i] as usize;
                let cur_vec = &cands.full[current * dim..(current + 1) * dim];
                // Bilinear splat of the patch's vertices onto the grid: the tent filter the
                // exemplar patches were sampled with.
                query.fill(0.0);
                weight.fill(0.0);
                let centre = (level.w as f32 - 1.0) * 0.5;
                for e in patches.start[i]..patches.start[i + 1] {
                    let o = patches.offset[e];
                    let fx = o[0] / level.step + centre;
                    let fy = o[1] / level.step + centre;
                    let (x0, y0) = (fx.floor(), fy.floor());
                    let (tx, ty) = (fx - x0, fy - y0);
                    let col = colours[patches.vertex[e] as usize];
                    for (dx, dy, wgt) in [
                        (0, 0, (1.0 - tx) * (1.0 - ty)),
                        (1, 0, tx * (1.0 - ty)),
                        (0, 1, (1.0 - tx) * ty),
                        (1, 1, tx * ty),
                    ] {
                        let (cx, cy) = (x0 as i64 + dx, y0 as i64 + dy);
                        if wgt <= 0.0
                            || cx < 0
                            || cy < 0
                            || cx >= level.w as i64
                            || cy >= level.w as i64
                        {
                            continue;
                        }
                        let c = cy as usize * level.w + cx as usize;
                        weight[c] += wgt;
                        for t in 0..3 {
                            query[c * 3 + t] += wgt * col[t];
                        }
                    }
                }
                let mut missing = 0usize;
                for c in 0..cells_per {
                    if weight[c] > 1e-4 {
                        for t in 0..3 {
                            query[c * 3 + t] /= weight[c];
                        }
                    } else {
                        weight[c] = 0.0;
                        missing += 1;
                        query[c * 3..c * 3 + 3].copy_from_slice(&cur_vec[c * 3..c * 3 + 3]);
                    }
                }
                // The occurrence penalty needs alternatives to choose from.
                let search_k = if missing * 10 > cells_per || p.histogram > 0.0 {
                    SEARCH_K_PARTIAL
                } else {
                    SEARCH_K
                };
                // Distance over the grid cells the patch's vertices reach.
                let masked = |cand: &[f32]| -> f32 {
                    if missing == 0 {
                        return squared_distance(query, cand);
                    }
                    let mut acc = 0.0f32;
                    for c in 0..cells_per {
                        if weight[c] > 0.0 {
                            for t in 0..3 {
                                let d = query[c * 3 + t] - cand[c * 3 + t];
                                acc += d * d;
                            }
                        }
                    }
                    acc
                };
                cands.pca.project(query, proj);
                let found = match (info.constraint[i], &cands.distance) {
                    (Some(d), Some((dist, _))) => {
                        let tol = p.feature_tolerance;
                        tree.nearest_approx(proj, search_k, p.search_eps, |c| {
                            (dist[c as usize] - d).abs() <= tol
                        })
                    }
                    _ => tree.nearest_approx(proj, search_k, p.search_eps, |_| true),
                };
                // §5.2's constraint for candidates the tree did not filter.
                let allowed = |c: usize| match (info.constraint[i], &cands.distance) {
                    (Some(d), Some((dist, _))) => (dist[c] - d).abs() <= p.feature_tolerance,
                    _ => true,
                };
                // The current match competes too, if it satisfies the constraint.
                let mut best = (f32::INFINITY, u32::MAX);
                if allowed(current) {
                    best = (masked(cur_vec) * penalty[current], current as u32);
                }
                let coherent = if p.coherence > 0.0 {
                    coherent_candidates(patches, i, source, cands, rot)
                } else {
                    Vec::new()
                };
                let pull = 1.0 - p.coherence;
                for c in coherent {
                    let cu = c as usize;
                    if !allowed(cu) {
                        continue;
                    }
                    let d = masked(&cands.full[cu * dim..(cu + 1) * dim]) * penalty[cu] * pull;
                    if d < best.0 || (d == best.0 && c < best.1) {
                        best = (d, c);
                    }
                }
                for (c, _) in found {
                    let cu = c as usize;
                    let d = masked(&cands.full[cu * dim..(cu + 1) * dim]) * penalty[cu];
                    if d < best.0 || (d == best.0 && c < best.1) {
                        best = (d, c);
                    }
                }
                if best.1 == u32::MAX { z[i] } else { best.1 }
            },
        )
        .collect()
}

/// How many of a patch's vertices propose a coherent candidate (spread over the patch).
const COHERENT_PROPOSERS: usize = 24;

/// k-coherence candidates (Ashikhmin 2001; Han et al. 2006, §4): the exemplar patches that
/// would continue, at sample `i`'s centre, what the vertices of its patch copy at the current
/// iteration. Vertex `q` at offset `o` in the sample's frame holds exemplar address `a_q`; the
/// patch centred at `a_q − R·o` puts that same texel on `q` and continues its neighbourhood
/// across the sample.
/// Distinct candidates only, at most [`COHERENT_PROPOSERS`], proposed by vertices spread
/// evenly through the patch's entries; a proposed centre outside the candidate rectangle is
/// dropped rather than clamped to an unrelated patch.
fn coherent_candidates(
    patches: &Patches,
    i: usize,
    source: &[[f32; 2]],
    cands: &Candidates,
    rot: Rot,
) -> Vec<u32> {
    let (a, b) = (patches.start[i], patches.start[i + 1]);
    let stride = (b - a).div_ceil(COHERENT_PROPOSERS).max(1);
    let mut out: Vec<u32> = Vec::with_capacity(COHERENT_PROPOSERS);
    for e in (a..b).step_by(stride) {
        let src = source[patches.vertex[e] as usize];
        if src[0] < -0.5 {
            continue;
        }
        let centre = glam::Vec2::from(src) - rot.apply(patches.offset[e]);
        if let Some(c) = cands.at(centre)
            && !out.contains(&c)
        {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::candidates::{Rgb, build_candidates};
    use super::*;
    use crate::graph::Csr;
    use texsyn_core::math::PureMath;

    /// A proposal continues the vertex's own address: the candidate's patch, read at the
    /// vertex's offset through the exemplar's rotation (as the lookups read it), lands on the
    /// address the vertex holds, within the rounding of the centre to a pixel (√2/2). A
    /// transposed rotation misses by 2·sin(0.3)·|offset|, over 2 texels here.
    #[test]
    fn a_coherent_candidate_puts_the_vertex_s_own_address_back_on_it() {
        let (w, h) = (48, 48);
        let rgb = Rgb {
            w,
            h,
            px: (0..w * h)
                .map(|i| [(i % w) as f32 / w as f32, (i / w) as f32 / h as f32, 0.5])
                .collect(),
        };
        let rot = Rot {
            c: 0.3f32.cos_pure(),
            s: 0.3f32.sin_pure(),
        };
        let cands = build_candidates(&rgb, None, Level { w: 9, step: 1.0 }, rot, 8).unwrap();
        let offset = vec![[0.0, 0.0], [3.0, 1.0], [-3.0, 2.5], [1.5, -3.5]];
        let source = vec![[20.0, 22.0], [25.3, 18.7], [17.2, 26.1], [27.6, 15.4]];
        let vertex: Vec<u32> = (0..4).collect();
        let patches = Patches {
            start: vec![0, 4],
            vertex: vertex.clone(),
            offset: offset.clone(),
            by_vertex: Csr::from_pairs(4, vertex.iter().map(|&v| (v as usize, v))),
            entry_sample: vec![0; 4],
        };
        let proposed = coherent_candidates(&patches, 0, &source, &cands, rot);
        assert_eq!(proposed.len(), 4, "{proposed:?}");
        for (e, &c) in proposed.iter().enumerate() {
            let read = cands.centre(c) + rot.apply(offset[e]);
            let miss = read.distance(glam::Vec2::from(source[e]));
            assert!(
                miss <= 0.71,
                "entry {e}: read at {read}, holds {:?}",
                source[e]
            );
        }
        // A vertex without an address proposes nothing, and one whose continued centre falls
        // outside the candidate rectangle is dropped, not clamped.
        let far = vec![[-1.0, -1.0], [47.0, 2.0], source[2], source[3]];
        let proposed = coherent_candidates(&patches, 0, &far, &cands, rot);
        assert_eq!(proposed.len(), 2, "{proposed:?}");
    }
}
