//! Building the variant set: per variant and level, the resampled texels, the template features
//! (channel-weighted, PCA-reduced) with their kd-trees, and the k-coherent candidate sets.

use super::params::{TexelVariantParams, VariantsError};
use super::resample::{resample_variant, texel_pyramid};
use super::sample_size::{FEW_CANDIDATES, check_sample_size, shortfall, side_needed};
use super::store::{LevelMeta, SetMeta, TexelVariants, VariantsMeta};
use super::templates::{Template, candidates, coarse_taps, feature_dim, template_taps};
use crate::geom::geometry_image::TexelImage;
use crate::image::knn::KdTree;
use crate::image::neighbourhood::mirror;
use crate::image::pca::{Pca, PcaParams};
use rayon::prelude::*;

/// Writes the raw feature vector of the template `kind` (side `side`) centred on `(x, y)` of
/// `level`, with `coarser` the next level if any. The template must lie inside (a candidate).
#[allow(clippy::too_many_arguments)]
pub(super) fn write_feature(
    level: &TexelImage,
    coarser: Option<&TexelImage>,
    taps: &[(i32, i32)],
    ctaps: &[(i32, i32)],
    weights: &[f32],
    coarse_weight: f32,
    x: u32,
    y: u32,
    out: &mut [f32],
) {
    let c = level.channels as usize;
    let mut o = 0;
    for &(dx, dy) in taps {
        let t = level.texel((x as i32 + dx) as u32, (y as i32 + dy) as u32);
        for k in 0..c {
            out[o + k] = t[k] * weights[k];
        }
        o += c;
    }
    if let Some(cl) = coarser {
        let (cx, cy) = ((x / 2) as i32, (y / 2) as i32);
        for &(dx, dy) in ctaps {
            let t = cl.texel((cx + dx) as u32, (cy + dy) as u32);
            for k in 0..c {
                out[o + k] = t[k] * weights[k] * coarse_weight;
            }
            o += c;
        }
    }
    debug_assert_eq!(o, out.len());
}

/// Channel weights of the feature vectors (see the module docs).
pub(super) fn channel_weights(sample: &TexelImage, color_weight: f32) -> Vec<f32> {
    let c = sample.channels as usize;
    let n = (sample.width * sample.height) as f64;
    let mut var = vec![0.0f64; c];
    for k in 0..c {
        let mean: f64 = sample
            .data
            .iter()
            .skip(k)
            .step_by(c)
            .map(|&v| v as f64)
            .sum::<f64>()
            / n;
        var[k] = sample
            .data
            .iter()
            .skip(k)
            .step_by(c)
            .map(|&v| (v as f64 - mean).powi(2))
            .sum::<f64>()
            / n;
    }
    let mut w = vec![1.0f32; c];
    if c == 6 {
        let geo = (var[..3].iter().sum::<f64>() / 3.0).sqrt();
        let col = (var[3..].iter().sum::<f64>() / 3.0).sqrt();
        let f = if geo > 0.0 && col > 0.0 {
            geo / col
        } else {
            1.0
        };
        for v in &mut w[3..] {
            *v = (f * color_weight as f64) as f32;
        }
    }
    w
}

/// Candidates a PCA basis is fitted to at most (a regular subsample of the rest).
pub const PCA_FIT_SAMPLES: usize = 4096;

/// Raw feature vectors of template `kind` (side `side`) at level `l` of `pyr`, for `centres`.
pub(super) fn features(
    pyr: &[TexelImage],
    l: usize,
    kind: Template,
    side: u32,
    weights: &[f32],
    coarse_weight: f32,
    centres: &[u32],
) -> Vec<f32> {
    let level = &pyr[l];
    let coarser = pyr.get(l + 1);
    let taps = template_taps(kind, side);
    let ctaps = coarse_taps(side);
    let dim_in = feature_dim(kind, side, coarser.is_some(), level.channels);
    let mut raw = vec![0.0f32; centres.len() * dim_in];
    raw.par_chunks_mut(dim_in)
        .zip(centres.par_iter())
        .for_each(|(out, &ci)| {
            let (x, y) = (ci % level.width, ci / level.width);
            write_feature(
                level,
                coarser,
                &taps,
                &ctaps,
                weights,
                coarse_weight,
                x,
                y,
                out,
            );
        });
    raw
}

/// Builds the variant set of `sample` (3 channels dx, dy, dn, or 6 with r, g, b), with the
/// per-texel search structures. `progress` gets the fraction done, from 0 to 1, from the
/// calling thread.
pub fn build_texel_variants(
    sample: &TexelImage,
    params: &TexelVariantParams,
    progress: &dyn Fn(f32),
) -> Result<TexelVariants, VariantsError> {
    build_texel_variants_with(sample, params, true, true, progress)
}

/// The k-coherent sets of every level of the sample pyramid `pyr`: per texel, the
/// `k` texels with the nearest feature vectors (the full `side`² window plus the coarser
/// level's [`coarse_window`], read mirrored at the borders so every texel has one; PCA-reduced
/// as the per-texel sets are), leaving out the texel's own `side`² window, whose texels the
/// coherent candidates already bring. Returns the level sizes and the concatenated sets.
///
/// [`coarse_window`]: super::coarse_window
pub(super) fn k_coherent_sets(
    pyr: &[TexelImage],
    params: &TexelVariantParams,
    weights: &[f32],
) -> (Vec<LevelMeta>, Vec<u32>) {
    let side = params.template;
    let k = params.coherent_k as usize;
    let r = (side / 2) as i64;
    let taps = template_taps(Template::Full, side);
    let ctaps = coarse_taps(side);
    let mut metas = Vec::new();
    let mut out = Vec::new();
    for l in 0..pyr.len() {
        let level = &pyr[l];
        let coarser = pyr.get(l + 1);
        let c = level.channels as usize;
        let (w, h) = (level.width as i64, level.height as i64);
        let count = (w * h) as usize;
        let dim = (taps.len() + if coarser.is_some() { ctaps.len() } else { 0 }) * c;
        let mut raw = vec![0.0f32; count * dim];
        raw.par_chunks_mut(dim).enumerate().for_each(|(t, o)| {
            let (x, y) = (t as i64 % w, t as i64 / w);
            let mut at = 0;
            for &(dx, dy) in &taps {
                let px = level.texel(
                    mirror(x + dx as i64, w) as u32,
                    mirror(y + dy as i64, h) as u32,
                );
                for ch in 0..c {
                    o[at + ch] = px[ch] * weights[ch];
                }
                at += c;
            }
            if let Some(cl) = coarser {
                let (cw, chh) = (cl.width as i64, cl.height as i64);
                for &(dx, dy) in &ctaps {
                    let px = cl.texel(
                        mirror(x / 2 + dx as i64, cw) as u32,
                        mirror(y / 2 + dy as i64, chh) as u32,
                    );
                    for ch in 0..c {
                        o[at + ch] = px[ch] * weights[ch] * params.coarse_weight;
                    }
                    at += c;
                }
            }
        });
        let stride = count.div_ceil(PCA_FIT_SAMPLES).max(1);
        let fit: Vec<f32> = raw
            .chunks_exact(dim)
            .step_by(stride)
            .flatten()
            .copied()
            .collect();
        let pca = Pca::fit(
            &fit,
            dim,
            &PcaParams {
                components: params.pca_dims,
                variance: 0.999,
                min_auto: 8,
                max_auto: 24,
            },
        );
        let points = pca.project_all(&raw);
        let dims = pca.components();
        let tree = KdTree::build(&points, dims);
        let tree = tree.as_ref();
        let mut sets = vec![u32::MAX; count * k];
        sets.par_chunks_mut(k).enumerate().for_each(|(t, o)| {
            let (x, y) = (t as i64 % w, t as i64 / w);
            let found = tree.nearest_approx(&points[t * dims..(t + 1) * dims], k, 0.25, |id| {
                let (ix, iy) = (id as i64 % w, id as i64 / w);
                (ix - x).abs() > r || (iy - y).abs() > r
            });
            for (slot, (id, _)) in o.iter_mut().zip(found) {
                *slot = id;
            }
        });
        metas.push(LevelMeta {
            width: level.width,
            height: level.height,
            texel_offset: out.len() as u64,
        });
        out.extend_from_slice(&sets);
    }
    (metas, out)
}

/// The layout of [`k_coherent_sets`] with every entry none (`u32::MAX`).
fn no_coherent_sets(pyr: &[TexelImage], params: &TexelVariantParams) -> (Vec<LevelMeta>, Vec<u32>) {
    let k = params.coherent_k as usize;
    let mut metas = Vec::new();
    let mut offset = 0u64;
    for level in pyr {
        metas.push(LevelMeta {
            width: level.width,
            height: level.height,
            texel_offset: offset,
        });
        offset += level.width as u64 * level.height as u64 * k as u64;
    }
    (metas, vec![u32::MAX; offset as usize])
}

/// [`build_texel_variants`]; `per_texel` false leaves out the per-texel search structures
/// (PCA bases and kd-trees of every variant, level and template: nearly all of the set's size
/// and build time), which only `synthesize.search = "per_texel"` reads; `coherent` false leaves
/// out the sample's k-coherent sets (every entry none), which only the template synthesizer
/// reads (most of the remaining build time: 22 of 27 s for a 512² sample).
pub fn build_texel_variants_with(
    sample: &TexelImage,
    params: &TexelVariantParams,
    per_texel: bool,
    coherent: bool,
    progress: &dyn Fn(f32),
) -> Result<TexelVariants, VariantsError> {
    params.validate()?;
    let c = sample.channels;
    if c != 3 && c != 6 {
        return Err(VariantsError::SampleChannels { channels: c });
    }
    if sample.data.len() != (sample.width * sample.height * c) as usize {
        return Err(VariantsError::SampleLength {
            width: sample.width,
            height: sample.height,
            channels: c,
            got: sample.data.len(),
        });
    }
    if let Some(i) = sample.data.iter().position(|v| !v.is_finite()) {
        let t = i as u32 / c;
        return Err(VariantsError::SampleNotFinite {
            x: t % sample.width,
            y: t / sample.width,
            channel: i as u32 % c,
        });
    }
    // Without the template synthesizer's structures no candidates are counted, and every
    // level of every variant has at least one texel whatever the sample's size.
    let counted = per_texel || coherent;
    if counted {
        check_sample_size(sample.width, sample.height, params)?;
    }
    if let Some((scale, k, l, side, count)) =
        shortfall(sample.width, sample.height, params, FEW_CANDIDATES).filter(|_| counted)
    {
        tracing::warn!(
            target: "texsyn::texel_variants",
            "the {}×{} sample leaves only {count} candidates ({side}×{side} texels) at pyramid \
             level {l} of scale {} and orientation {}°: synthesis there will repeat a few \
             texels; a sample of {n}×{n} would give every level {FEW_CANDIDATES}",
            sample.width,
            sample.height,
            scale + 1,
            k as f64 * 360.0 / params.orientations as f64,
            n = side_needed(params, FEW_CANDIDATES, sample.width.max(sample.height)),
        );
    }
    progress(0.0);
    let weights = channel_weights(sample, params.color_weight);
    let sources = texel_pyramid(sample, params.kset_levels());
    let (kset_meta, kset) = if coherent {
        k_coherent_sets(&sources, params, &weights)
    } else {
        no_coherent_sets(&sources, params)
    };
    let nl = params.levels as usize;
    let k_count = params.orientations;
    let jobs: Vec<(usize, u32)> = (0..params.scales as usize)
        .flat_map(|s| (0..k_count).map(move |k| (s, k)))
        .collect();
    let nv = jobs.len();
    let pyramids: Vec<Vec<TexelImage>> = jobs
        .par_iter()
        .map(|&(s, k)| texel_pyramid(&resample_variant(&sources, params, s, k), nl))
        .collect();
    let kinds = [
        (Template::Causal, params.template),
        (Template::Full, params.boundary_template),
    ];
    // Sets in (variant, level, template) order.
    let set_of = |v: usize, l: usize, t: usize| (v * nl + l) * 2 + t;
    let sets = if per_texel { nv * nl * 2 } else { 0 };
    let centres: Vec<Vec<u32>> = (0..sets)
        .into_par_iter()
        .map(|idx| {
            let (v, l, t) = (idx / (2 * nl), idx / 2 % nl, idx % 2);
            let (kind, side) = kinds[t];
            let (level, coarser) = (&pyramids[v][l], pyramids[v].get(l + 1));
            candidates(
                kind,
                side,
                level.width,
                level.height,
                coarser.map(|c| (c.width, c.height)),
            )
        })
        .collect();
    // A PCA basis per set, fitted to a regular subsample of at most PCA_FIT_SAMPLES of its
    // candidates.
    let bases: Vec<Pca> = (0..sets)
        .into_par_iter()
        .map(|idx| {
            let (v, l, t) = (idx / (2 * nl), idx / 2 % nl, idx % 2);
            let (kind, side) = kinds[t];
            let stride = centres[idx].len().div_ceil(PCA_FIT_SAMPLES).max(1);
            let chosen: Vec<u32> = centres[idx].iter().step_by(stride).copied().collect();
            let fit = features(
                &pyramids[v],
                l,
                kind,
                side,
                &weights,
                params.coarse_weight,
                &chosen,
            );
            Pca::fit(
                &fit,
                feature_dim(kind, side, l + 1 < nl, c),
                &PcaParams {
                    components: params.pca_dims,
                    variance: 0.999,
                    min_auto: 8,
                    max_auto: 24,
                },
            )
        })
        .collect();
    let basis_of = |v: usize, l: usize, t: usize| &bases[set_of(v, l, t)];
    let trees: Vec<KdTree> = (0..sets)
        .into_par_iter()
        .map(|idx| {
            let (v, l, t) = (idx / (2 * nl), idx / 2 % nl, idx % 2);
            let (kind, side) = kinds[t];
            let raw = features(
                &pyramids[v],
                l,
                kind,
                side,
                &weights,
                params.coarse_weight,
                &centres[idx],
            );
            let pca = basis_of(v, l, t);
            KdTree::build(&pca.project_all(&raw), pca.components())
        })
        .collect();

    // Concatenate in (variant, level, template) order.
    let mut out = TexelVariants {
        meta: VariantsMeta {
            params: params.clone(),
            channels: c,
            sample_width: sample.width,
            sample_height: sample.height,
            channel_weights: weights,
            levels: Vec::new(),
            sets: Vec::new(),
            per_texel,
            coherent,
            ksets: kset_meta,
        },
        texels: Vec::new(),
        centres: Vec::new(),
        pca_mean: Vec::new(),
        pca_basis: Vec::new(),
        tree_points: Vec::new(),
        tree_ids: Vec::new(),
        tree_nodes: Vec::new(),
        kset,
    };
    for (v, pyr) in pyramids.iter().enumerate() {
        for img in pyr {
            out.meta.levels.push(LevelMeta {
                width: img.width,
                height: img.height,
                texel_offset: out.texels.len() as u64,
            });
            out.texels.extend_from_slice(&img.data);
        }
        for l in 0..nl * per_texel as usize {
            for t in 0..2 {
                let idx = set_of(v, l, t);
                let pca = basis_of(v, l, t);
                let (dim, points, ids, nodes) = trees[idx].parts();
                debug_assert_eq!(dim, pca.components());
                out.meta.sets.push(SetMeta {
                    dim_in: pca.dim as u32,
                    dims: dim as u32,
                    count: centres[idx].len() as u32,
                    centre_offset: out.centres.len() as u64,
                    mean_offset: out.pca_mean.len() as u64,
                    basis_offset: out.pca_basis.len() as u64,
                    point_offset: out.tree_points.len() as u64,
                    node_offset: out.tree_nodes.len() as u64,
                    node_count: nodes.len() as u64,
                });
                out.centres.extend_from_slice(&centres[idx]);
                out.pca_mean.extend_from_slice(&pca.mean);
                out.pca_basis.extend_from_slice(&pca.basis);
                out.tree_points.extend_from_slice(points);
                out.tree_ids.extend_from_slice(ids);
                out.tree_nodes.extend_from_slice(nodes);
            }
        }
    }
    progress(1.0);
    Ok(out)
}
