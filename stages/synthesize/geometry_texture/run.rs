//! The synthesis driver: each level started (random start or upsampled coarser level), its
//! scanline pass in anti-diagonal waves, its boundary passes, and mate groups made
//! bit-identical after each pass.

use super::ParamField;
use super::controls::{TexelControls, texel_controls};
use super::grid::{LevelGrid, quarter_turn};
use super::level::{
    Ctx, INIT_PASS, Level, MAX_CHANNELS, STREAM_INIT, STREAM_MATE, Scratch, Src, choice_index,
    pack_src,
};
use super::params::{GeometrySynthParams, GeometryTextureError, Search, Taps, check_inputs};
use crate::analyse_exemplar::texel_variants::{
    Template, TexelVariantsRef, coarse_taps, template_taps,
};
use crate::geom::geometry_image::{GeometryImage, TexelImage};
use crate::random::counter_hash;
use rayon::prelude::*;

/// Gives every mate group of `lv` one member's value (chosen by hash), turned into each
/// member's axes.
pub(super) fn unify_mates(lv: &mut Level, c: usize, seed: u64, level: usize, pass: u32) {
    for g in &lv.grid.groups {
        let pick = counter_hash(seed, STREAM_MATE, choice_index(level, pass, g[0] as usize))
            % g.len() as u64;
        let m = g[pick as usize] as usize;
        let mut v = [0.0f32; MAX_CHANNELS];
        v[..c].copy_from_slice(&lv.data[m * c..(m + 1) * c]);
        let rm = lv.grid.to_rep[m];
        for &q in g {
            let q = q as usize;
            let mut w = v;
            // Into the representative's axes, then into q's.
            quarter_turn((rm + 4 - lv.grid.to_rep[q]) % 4, &mut w);
            lv.data[q * c..(q + 1) * c].copy_from_slice(&w[..c]);
        }
    }
}

/// The sources of a finer level's starting values: texel `(i, j)` takes its parent
/// `(i / 2, j / 2)`'s source texel `q` (in the coarser level of the parent's variant) as
/// `2 q + (j mod 2, i mod 2)` in that variant's finer level (`size` gives its width and
/// height), clamped inside; with the surface metric, the child's offset `(j mod 2, i mod 2)`
/// goes through `fine`'s map to sample offsets, rounded.
pub(super) fn upsample_sources(
    coarse: &Level,
    fine: &Level,
    size: impl Fn(usize) -> (u32, u32),
) -> Vec<Src> {
    let nc = coarse.grid.n;
    let nf = fine.grid.n;
    let mut out = vec![Src::default(); nf * nf];
    for i in 0..nf {
        for j in 0..nf {
            let src = coarse.src[(i / 2) * nc + j / 2];
            let (v, k) = (
                (src.packed >> 32) as usize,
                (src.packed & 0xFFFF_FFFF) as u32,
            );
            let (w, h) = size(v);
            let cw = w.div_ceil(2);
            let o = fine.sample_shift(i * nf + j, ((j % 2) as i32, (i % 2) as i32));
            // The continuous position 2 (q + frac) + o, rounded to a texel inside; the
            // remainder is kept (zero without the surface metric).
            let at = |base: u32, frac: f32, d: f64, len: u32| {
                let x = 2.0 * frac as f64 + d;
                let r = (x + 0.5).floor();
                let t = ((2 * base) as i64 + r as i64).clamp(0, len as i64 - 1) as u32;
                (t, (x - r) as f32)
            };
            let (x, fx) = at(k % cw, src.frac[0], o[0], w);
            let (y, fy) = at(k / cw, src.frac[1], o[1], h);
            out[i * nf + j] = Src {
                packed: pack_src(v, (y * w + x) as usize),
                frac: [fx, fy],
            };
        }
    }
    out
}

/// Bilinear interpolation of the coarser level `coarse` onto a grid of side `nf` (sample `i` of
/// `coarse` is sample `2 i` of the result).
pub(super) fn upsample(coarse: &Level, nf: usize, c: usize) -> Vec<f32> {
    let nc = coarse.grid.n;
    debug_assert_eq!((nc - 1) * 2 + 1, nf);
    let mut fine = vec![0.0f32; nf * nf * c];
    fine.par_chunks_mut(nf * c)
        .enumerate()
        .for_each(|(i, row)| {
            let (i0, i1) = (i / 2, i.div_ceil(2));
            for (j, out) in row.chunks_exact_mut(c).enumerate() {
                let (j0, j1) = (j / 2, j.div_ceil(2));
                for ch in 0..c {
                    let at = |a: usize, b: usize| coarse.data[(a * nc + b) * c + ch];
                    out[ch] = 0.25 * (at(i0, j0) + at(i0, j1) + at(i1, j0) + at(i1, j1));
                }
            }
        });
    fine
}

/// Synthesizes a texel image over `gi` (see the module docs). The result has `gi.n × gi.n`
/// texels with the variants' channels; `(dx, dy, dn)` are in the local frames of
/// [`crate::geom::geometry_image::local_frames`]. `progress` gets the fraction done, 0 to 1,
/// from the calling thread.
pub fn synthesize_geometry_texture(
    gi: &GeometryImage,
    field: &ParamField,
    variants: &TexelVariantsRef<'_>,
    p: &GeometrySynthParams,
    progress: &dyn Fn(f32),
) -> Result<TexelImage, GeometryTextureError> {
    synthesize_impl(gi, field, variants, p, progress, true)
}

/// [`synthesize_geometry_texture`]; `wavefront` false runs the scanline pass texel by texel
/// (the reference the wavefront order must reproduce).
pub(super) fn synthesize_impl(
    gi: &GeometryImage,
    field: &ParamField,
    variants: &TexelVariantsRef<'_>,
    p: &GeometrySynthParams,
    progress: &dyn Fn(f32),
    wavefront: bool,
) -> Result<TexelImage, GeometryTextureError> {
    p.validate()?;
    let vp = variants.params().clone();
    let nl = vp.levels as usize;
    check_inputs(gi, field, nl)?;
    progress(0.0);
    let n0 = gi.n as usize;
    let c = variants.channels();
    let kk = vp.orientations as usize;
    let ss = vp.scales as usize;

    let TexelControls {
        metric: metric0,
        orient: orient0,
        scale: scale0,
    } = texel_controls(gi, field, &vp, p);

    // Level grids: mates from the level-0 samples on each level's lattice.
    let mut levels: Vec<Level> = Vec::with_capacity(nl);
    for l in 0..nl {
        let grid = LevelGrid::of_level(gi, l, p.boundary_strip);
        let n = grid.n;
        let fine = |i: usize, j: usize| (i << l) * n0 + (j << l);
        let mut orient = vec![0.0f32; n * n];
        let mut scale = vec![0.0f32; n * n];
        for i in 0..n {
            for j in 0..n {
                orient[i * n + j] = orient0[fine(i, j)];
                scale[i * n + j] = scale0[fine(i, j)];
            }
        }
        // The metric is scale-free: a level's texel takes its level-0 sample's.
        let metric = if metric0.is_empty() {
            Vec::new()
        } else {
            (0..n * n).map(|k| metric0[fine(k / n, k % n)]).collect()
        };
        levels.push(Level {
            grid,
            data: Vec::new(),
            init: Vec::new(),
            orient,
            scale,
            src: Vec::new(),
            init_src: Vec::new(),
            metric,
        });
    }
    if p.search == Search::PerTexel && !variants.meta.per_texel {
        return Err(GeometryTextureError::NoPerTexelSets);
    }
    if p.search == Search::KCoherence && !variants.meta.coherent {
        return Err(GeometryTextureError::NoCoherentSets);
    }
    let maps: Vec<_> = (0..variants.variant_count() * nl)
        .map(|vl| variants.sample_map(vl / nl, vl % nl))
        .collect();

    let ctx = Ctx {
        variants,
        channels: c,
        weights: &variants.meta.channel_weights,
        coarse_weight: match p.search {
            Search::KCoherence => p.coarse_weight,
            Search::PerTexel => vp.coarse_weight,
        },
        seed: p.seed,
        eps: p.search_eps,
        orientations: kk,
        scales: ss,
        block: vp.template as usize,
        search: p.search,
        coherence: p.coherence,
        nearest_taps: p.taps == Taps::Nearest,
        subtexel: p.subtexel && p.anisotropic,
        maps,
        wave: (vp.template / 2) as i64 + 1,
    };
    let causal_taps = template_taps(Template::Causal, vp.template);
    let causal_ctaps = coarse_taps(vp.template);
    let full_taps = template_taps(Template::Full, vp.boundary_template);
    let full_ctaps = coarse_taps(vp.boundary_template);

    // Work units for progress: texels per level, times (1 + a share for the boundary).
    let total: f64 = levels
        .iter()
        .map(|lv| (lv.grid.n * lv.grid.n) as f64)
        .sum::<f64>()
        + levels
            .iter()
            .map(|lv| lv.grid.strip.len() as f64 * p.boundary_passes as f64)
            .sum::<f64>();
    let mut done = 0.0f64;

    for l in (0..nl).rev() {
        let n = levels[l].grid.n as i64;
        // 1. Starting values: at the coarsest level texels drawn at random from the variant
        // each texel would be matched in (the sample's statistics at that level and scale),
        // above it the coarser result, interpolated.
        let init = if l + 1 == nl {
            let lv = &levels[l];
            let mut init = vec![0.0f32; lv.grid.n * lv.grid.n * c];
            let mut src = vec![Src::default(); lv.grid.n * lv.grid.n];
            init.par_chunks_mut(c)
                .zip(src.par_iter_mut())
                .enumerate()
                .for_each(|(t, (out, src))| {
                    let v = ctx.choose(lv, l, INIT_PASS, t);
                    let img = variants.level(v, l);
                    let count = (img.width * img.height) as u64;
                    let key = choice_index(l, INIT_PASS, t);
                    let k = (counter_hash(p.seed, STREAM_INIT, key) % count) as usize;
                    out.copy_from_slice(&img.texels[k * c..(k + 1) * c]);
                    *src = Src::whole(v, k);
                });
            (init, src)
        } else {
            let src = upsample_sources(&levels[l + 1], &levels[l], |v| {
                let img = variants.level(v, l);
                (img.width, img.height)
            });
            (upsample(&levels[l + 1], levels[l].grid.n, c), src)
        };
        let (init, init_src) = init;
        levels[l].data = init.clone();
        levels[l].init = init;
        levels[l].src = init_src.clone();
        levels[l].init_src = init_src;
        // 2. Scanline synthesis, one anti-diagonal wave at a time (or in plain scanline order).
        let f = if wavefront {
            (vp.template / 2) as i64 + 1
        } else {
            n
        };
        let last_wave = (n - 1) + f * (n - 1);
        let mut results: Vec<([f32; MAX_CHANNELS], Src)> = Vec::new();
        for w in 0..=last_wave {
            let i_lo = if w > n - 1 {
                (w - (n - 1) + f - 1) / f
            } else {
                0
            };
            let i_hi = (w / f).min(n - 1);
            if i_lo > i_hi {
                continue;
            }
            let compute = |scratch: &mut Scratch, i: i64| {
                let mut out = [0.0f32; MAX_CHANNELS];
                let src = ctx.synthesize_texel(
                    &levels,
                    l,
                    0,
                    Template::Causal,
                    &causal_taps,
                    &causal_ctaps,
                    i,
                    w - f * i,
                    scratch,
                    &mut out,
                );
                (out, src)
            };
            results.clear();
            if i_hi - i_lo < 8 || !wavefront {
                let mut scratch = Scratch::default();
                results.extend((i_lo..=i_hi).map(|i| compute(&mut scratch, i)));
            } else {
                (i_lo as usize..i_hi as usize + 1)
                    .into_par_iter()
                    .map_init(Scratch::default, |s, i| compute(s, i as i64))
                    .collect_into_vec(&mut results);
            }
            let lv = &mut levels[l];
            for (i, (px, src)) in (i_lo..=i_hi).zip(&results) {
                let t = lv.grid.idx(i, w - f * i);
                lv.data[t * c..(t + 1) * c].copy_from_slice(&px[..c]);
                lv.src[t] = *src;
            }
        }
        // 2b. Correction passes (k-coherence only): each texel rematched in the variant of its
        // scanline match, from the level as the previous pass left it, so the texels do not
        // depend on one another and any thread count gives the same result.
        let corrections = if p.search == Search::KCoherence {
            p.correction_passes
        } else {
            0
        };
        for _ in 0..corrections {
            let nn = levels[l].grid.n * levels[l].grid.n;
            let res: Vec<([f32; MAX_CHANNELS], Src)> = (0..nn)
                .into_par_iter()
                .map_init(Scratch::default, |scratch, t| {
                    let (i, j) = levels[l].grid.coords(t as u32);
                    let mut out = [0.0f32; MAX_CHANNELS];
                    let src = ctx.synthesize_texel(
                        &levels,
                        l,
                        0,
                        Template::Full,
                        &full_taps,
                        &full_ctaps,
                        i,
                        j,
                        scratch,
                        &mut out,
                    );
                    (out, src)
                })
                .collect();
            let lv = &mut levels[l];
            for (t, (px, src)) in res.iter().enumerate() {
                lv.data[t * c..(t + 1) * c].copy_from_slice(&px[..c]);
                lv.src[t] = *src;
            }
        }
        unify_mates(&mut levels[l], c, p.seed, l, 0);
        done += (n * n) as f64;
        progress((done / total) as f32);

        // 3. Boundary resynthesis.
        let mut scratch = Scratch::default();
        for pass in 1..=p.boundary_passes {
            let strip = std::mem::take(&mut levels[l].grid.strip);
            for &t in &strip {
                let (i, j) = levels[l].grid.coords(t);
                let mut out = [0.0f32; MAX_CHANNELS];
                let src = ctx.synthesize_texel(
                    &levels,
                    l,
                    pass,
                    Template::Full,
                    &full_taps,
                    &full_ctaps,
                    i,
                    j,
                    &mut scratch,
                    &mut out,
                );
                let t = t as usize;
                levels[l].data[t * c..(t + 1) * c].copy_from_slice(&out[..c]);
                levels[l].src[t] = src;
            }
            done += strip.len() as f64;
            levels[l].grid.strip = strip;
            unify_mates(&mut levels[l], c, p.seed, l, pass);
            progress((done / total) as f32);
        }
    }

    // Output: mated samples in their representative's axes.
    let lv = levels.swap_remove(0);
    let mut out = TexelImage {
        width: gi.n,
        height: gi.n,
        channels: c as u32,
        data: lv.data,
    };
    for g in &lv.grid.groups {
        for &q in g {
            let q = q as usize;
            quarter_turn(lv.grid.to_rep[q], &mut out.data[q * c..q * c + 2]);
        }
    }
    progress(1.0);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::random::counter_unit;
    use crate::synthesize::geometry_texture::params::ScaleChoice;
    use glam::Vec2;
    use texsyn_core::math::PureMath;

    #[test]
    fn wavefront_order_reproduces_the_scanline_order() {
        use crate::analyse_exemplar::texel_variants::{TexelVariantParams, build_texel_variants};
        use glam::Vec3;
        let mut sample = TexelImage::new(40, 40, 3);
        for y in 0..40u32 {
            for x in 0..40u32 {
                let h = counter_unit(9, 0, (y * 40 + x) as u64);
                let t = sample.texel_mut(x, y);
                t[0] = (x as f32 * 0.7).sin_pure() * 0.2;
                t[1] = h - 0.5;
                t[2] = (x as f32 * 0.9 + y as f32 * 0.3).sin_pure() + 0.3 * h;
            }
        }
        let vp = TexelVariantParams {
            orientations: 4,
            ..Default::default()
        };
        let n = 33u32;
        let nn = (n * n) as usize;
        let mut mate_rep: Vec<u32> = (0..nn as u32).collect();
        for i in 0..n {
            mate_rep[(i * n + n - 1) as usize] = i * n;
        }
        // Stretched 3:1 down the rows, sheared and bent: the surface metric spreads the
        // causal taps past the causal half, where both orders must read the starting values.
        let gi = GeometryImage {
            n,
            positions: (0..nn)
                .map(|k| {
                    let (i, j) = ((k / n as usize) as f32, (k % n as usize) as f32);
                    Vec3::new(j + 0.5 * i, 3.0 * i + 0.02 * j * j, 0.0)
                })
                .collect(),
            normals: vec![Vec3::Z; nn],
            mate_rep,
        };
        let field = ParamField {
            dir: (0..nn)
                .map(|k| Vec2::from_angle(k as f32 * 0.01).rotate(Vec2::Y))
                .collect(),
            rel_scale: (0..nn).map(|k| 0.6 + (k % 7) as f32 * 0.25).collect(),
        };
        for template in [3u32, 5] {
            let p = GeometrySynthParams::default();
            // The causal template radius decides the waves.
            let owned = build_texel_variants(
                &sample,
                &TexelVariantParams {
                    template,
                    ..vp.clone()
                },
                &|_| {},
            )
            .unwrap();
            let vr = owned.as_ref();
            for (search, anisotropic, options) in [
                (Search::KCoherence, true, false),
                (Search::KCoherence, true, true),
                (Search::KCoherence, false, false),
                (Search::PerTexel, true, false),
            ] {
                let p = GeometrySynthParams {
                    search,
                    anisotropic,
                    ..p.clone()
                };
                // The experiments' options keep the order exact too.
                let p = if options {
                    GeometrySynthParams {
                        taps: Taps::Nearest,
                        scale_choice: ScaleChoice::Nearest,
                        subtexel: true,
                        max_stretch: 2.0,
                        ..p
                    }
                } else {
                    p
                };
                let a = synthesize_impl(&gi, &field, &vr, &p, &|_| {}, true).unwrap();
                let b = synthesize_impl(&gi, &field, &vr, &p, &|_| {}, false).unwrap();
                let bits = |t: &TexelImage| t.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(
                    bits(&a),
                    bits(&b),
                    "template {template} {search:?} anisotropic {anisotropic} {options}"
                );
            }
        }
        // A variant set built for the appearance synthesizer (without the search structures
        // the template synthesizer reads) is refused, naming what it lacks.
        use crate::analyse_exemplar::texel_variants::build_texel_variants_with;
        let p = GeometrySynthParams::default();
        let lean = build_texel_variants_with(&sample, &vp, false, false, &|_| {}).unwrap();
        assert!(lean.kset.iter().all(|&e| e == u32::MAX));
        let err = synthesize_impl(&gi, &field, &lean.as_ref(), &p, &|_| {}, true).unwrap_err();
        assert!(matches!(err, GeometryTextureError::NoCoherentSets), "{err}");
        let per_texel = GeometrySynthParams {
            search: Search::PerTexel,
            ..p
        };
        let err = synthesize_impl(&gi, &field, &lean.as_ref(), &per_texel, &|_| {}, true);
        assert!(matches!(
            err.unwrap_err(),
            GeometryTextureError::NoPerTexelSets
        ));
    }
}
