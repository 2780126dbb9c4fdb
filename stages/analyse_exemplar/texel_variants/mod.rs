//! Oriented and scaled versions of a geometric-texture sample, prepared for synthesis.
//!
//! Implements the preprocessing of Y.-K. Lai, S.-M. Hu, D. X. Gu and R. R. Martin, "Geometric
//! Texture Synthesis and Transfer via Geometry Images" (SPM 2005): §4.3, "a set of 8 equally
//! spaced orientations and 3 levels of scaling … built in advance … for each orientation and
//! scaling, we also build in advance an approximate nearest neighbor searching structure", and
//! the sample side of §4.2.1 (a Gaussian pyramid of the sample, a causal Γ template at each
//! level plus the full neighbourhood one level coarser).
//!
//! For orientation `k` (angle `θ = k · 360° / orientations`) and scale `s` (`T1` the largest;
//! the middle one is the sample's own size and neighbours differ by a factor 2, so that
//! `level = log2 R + (scales + 1) / 2` of §4.3 picks them) a variant holds:
//! - the resampled sample: rotated by `θ` about its centre (texel coordinates `x` right along
//!   columns, `y` along rows; the content at offset `u` from the centre moves to `R(θ) u`) and
//!   scaled, sampled bilinearly and cropped to the largest axis-aligned square inside the
//!   rotated sample, so no texel is invented. The `(dx, dy)` channels, vectors in the sample's
//!   tangent plane, are rotated by `R(θ)` as well, so a variant's texels are expressed in its
//!   own image axes. Scaling down samples the sample's Gaussian pyramid (prefiltered) rather
//!   than skipping texels;
//! - its Gaussian pyramid ([`crate::image::pyramid::downsample`]: binomial blur, every second
//!   texel; a side `w` gives `⌈w/2⌉`), `levels` levels;
//! - per level, two feature sets, each with its own PCA basis and kd-tree: the causal Γ
//!   template of side `template` (the rows above the centre and the texels left of it) used by
//!   the main scanline synthesis, and the full `boundary_template`² window used by boundary
//!   resynthesis (§4.2.2). Both add the full neighbourhood of side [`coarse_window`] at the
//!   next coarser level, centred on texel `(x / 2, y / 2)` (integer division, as in Wei &
//!   Levoy 2000), when there is a coarser level.
//!
//! Choices the paper leaves open:
//! - The boundary template is analysed here, with the rest of the sample (its features and
//!   trees are part of the cached artifact), rather than per synthesis run: building the 24 × 3
//!   extra PCA bases and trees takes longer than a whole synthesis. Its size is therefore a parameter
//!   of this stage, not of synthesis.
//! - The coarser level's taps are multiplied by `coarse_weight` (default 0.3, see the field):
//!   with equal weights the finer levels copied the oversized blobs that a 64² sample's tiny
//!   coarse levels produce.
//! - Only texels whose whole template lies inside the level are candidates (no padding, so no
//!   invented neighbourhoods). [`check_sample_size`] rejects samples that leave a level of some
//!   variant without candidates and names the size needed (when the set is built for the
//!   template synthesizer, which reads candidates); [`build_texel_variants`] warns when
//!   one keeps fewer than [`FEW_CANDIDATES`] (a 64² sample does, at the third level of its
//!   scaled-down variants; 127² is enough for the defaults).
//! - Feature vectors weight geometric channels (dx, dy, dn) equally and colour channels (r, g, b)
//!   by `color_weight · σ_geometry / σ_colour` (root-mean-square standard deviations over the
//!   sample), so colour and geometry count alike whatever their units. The weights are stored
//!   in the metadata so synthesis builds identical vectors.
//! - PCA keeps `pca_dims` components (default 16), or with 0 the fewest explaining 99.9% of
//!   the variance (8 to 24), each set its own basis, fitted to at most [`PCA_FIT_SAMPLES`] of
//!   its candidates (a regular subsample). One basis shared by all orientations was tried (the
//!   eigendecompositions are 90% of the analysis time for colour samples): on vertical stripes
//!   the unrotated variant then lost the directions that tell its neighbourhoods apart and the
//!   synthesis collapsed into one flat value.
//!
//! The result is an owned [`TexelVariants`] (flat arrays plus small [`VariantsMeta`]), which
//! [`TexelVariants::arrays`] exports and [`TexelVariantsRef::from_arrays`] views again in place
//! (e.g. in a memory-mapped artifact), checking every length and index. Building is parallel
//! and gives identical bytes for any number of threads.

mod build;
mod params;
mod resample;
mod sample_size;
mod store;
mod templates;

pub use build::{PCA_FIT_SAMPLES, build_texel_variants, build_texel_variants_with};
pub use params::{TexelVariantParams, VariantsError};
pub use resample::{downsample_texels, orientation_cos_sin, resample_variant, texel_pyramid};
pub use sample_size::{FEW_CANDIDATES, check_sample_size};
pub use store::{
    ARRAY_NAMES, KsetRef, LevelMeta, LevelRef, SampleMap, SetMeta, SetRef, TexelVariants,
    TexelVariantsRef, VariantsMeta,
};
pub use templates::{Template, coarse_taps, coarse_window, feature_dim, template_taps};

/// The `texel_variants` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("texel_variants", 3);

/// The analysis node's key: `[analyse_exemplar]`, whether synthesis searches per texel
/// (`synthesize.search = "per_texel"`), which alone needs the per-texel search structures
/// (nearly all of the variant set's size and build time), and whether it reads the sample's
/// k-coherent sets (the template synthesizer; the appearance synthesizer has its own).
#[derive(Debug, Clone, serde::Serialize)]
pub struct VariantsKey {
    pub variants: TexelVariantParams,
    pub per_texel: bool,
    pub coherent: bool,
}

/// The analyse-exemplar node: the sample's texel variants.
pub fn node(
    sample: &crate::geom::geometry_image::TexelImage,
    key: &VariantsKey,
    progress: &dyn Fn(f32),
) -> Result<TexelVariants, texsyn_core::algorithm::Failure> {
    build_texel_variants_with(sample, &key.variants, key.per_texel, key.coherent, progress)
        .map_err(texsyn_core::algorithm::Failure::input)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::geometry_image::TexelImage;
    use texsyn_core::math::PureMath;

    fn stripes(w: u32, h: u32, period: f32) -> TexelImage {
        let mut t = TexelImage::new(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                let p = t.texel_mut(x, y);
                p[0] = 1.0;
                p[1] = 0.25;
                p[2] = (std::f32::consts::TAU * x as f32 / period).sin_pure();
            }
        }
        t
    }

    #[test]
    fn identity_variant_is_the_sample_and_quarter_turn_rotates_pattern_and_vectors() {
        let sample = stripes(24, 24, 6.0);
        let p = TexelVariantParams {
            orientations: 4,
            scales: 1,
            levels: 1,
            ..Default::default()
        };
        let src = texel_pyramid(&sample, 1);
        let v0 = resample_variant(&src, &p, 0, 0);
        assert_eq!(v0, sample);
        let v1 = resample_variant(&src, &p, 0, 1); // 90°
        assert_eq!((v1.width, v1.height), (24, 24));
        for y in 0..24 {
            for x in 0..24 {
                let t = v1.texel(x, y);
                // (1, 0.25) rotated by 90°: (−0.25, 1).
                assert!((t[0] + 0.25).abs() < 1e-6 && (t[1] - 1.0).abs() < 1e-6);
                // Content at offset u moves to R(90°) u = (−u_y, u_x): the variant at (x, y)
                // shows the sample at u = (y − c, c − x), so dn varies with y only.
                let c = 11.5;
                let ux = y as f32 - c;
                let want = sample.texel((ux + c) as u32, 0)[2];
                assert!((t[2] - want).abs() < 1e-5, "({x}, {y}) {} {want}", t[2]);
            }
        }
    }

    #[test]
    fn too_small_sample_names_the_size_needed() {
        let p = TexelVariantParams::default();
        let e = build_texel_variants(&stripes(20, 20, 6.0), &p, &|_| {}).unwrap_err();
        let VariantsError::TooSmall { need: n, .. } = e else {
            panic!("{e}")
        };
        let e = e.to_string();
        assert!(e.contains("20×20") && e.contains("at least"), "{e}");
        let need: u32 = e
            .rsplit("at least ")
            .next()
            .unwrap()
            .split('×')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert_eq!(need, n);
        assert!(check_sample_size(need, need, &p).is_ok());
        assert!(check_sample_size(need - 1, need - 1, &p).is_err());
    }

    #[test]
    fn sample_map_points_at_the_texel_a_variant_copied() {
        let mut sample = TexelImage::new(30, 30, 3);
        for (k, v) in sample.data.iter_mut().enumerate() {
            *v = crate::random::counter_unit(5, 0, k as u64);
        }
        let p = TexelVariantParams {
            orientations: 4,
            scales: 3,
            levels: 1,
            ..Default::default()
        };
        let owned = build_texel_variants_with(&sample, &p, false, true, &|_| {}).unwrap();
        let v = owned.as_ref();
        assert!(!v.meta.per_texel && v.try_set(0, 0, Template::Causal).is_none());
        // Quarter turns at the sample's own scale copy texels exactly: each variant texel is
        // the sample texel its map points at.
        for k in 0..4 {
            let var = v.variant(1, k);
            let (lv, map) = (v.level(var, 0), v.sample_map(var, 0));
            for q in [[0.0, 0.0], [3.0, 17.0], [29.0, 1.0]] {
                let x = map.to_sample(q);
                let (sx, sy) = (x[0].round() as u32, x[1].round() as u32);
                assert!((x[0] - sx as f64).abs() < 1e-9 && (x[1] - sy as f64).abs() < 1e-9);
                let at = (q[1] as usize * lv.width as usize + q[0] as usize) * 3 + 2;
                assert_eq!(
                    lv.texels[at],
                    sample.texel(sx, sy)[2],
                    "orientation {k} {q:?}"
                );
                let back = map.from_sample(x);
                assert!((back[0] - q[0]).abs() < 1e-9 && (back[1] - q[1]).abs() < 1e-9);
            }
        }
        // The enlarged variant's texel 2q shows the sample's texel q.
        let big = v.sample_map(v.variant(0, 0), 0);
        assert_eq!(big.to_sample([10.0, 4.0]), [5.0, 2.0]);
    }

    #[test]
    fn k_coherent_sets_hold_similar_texels_away_from_the_texel() {
        // Stripes of period 6 along x: a texel's best matches are the texels one or more
        // periods away on its own column phase.
        let sample = stripes(48, 48, 6.0);
        let p = TexelVariantParams {
            orientations: 1,
            scales: 1,
            levels: 1,
            ..Default::default()
        };
        let owned = build_texel_variants_with(&sample, &p, false, true, &|_| {}).unwrap();
        let v = owned.as_ref();
        let ks = v.kset(0);
        let k = v.coherent_k();
        assert_eq!(ks.entries.len(), 48 * 48 * k);
        for t in [24 * 48 + 24, 10 * 48 + 31] {
            let (x, y) = (t % 48, t / 48);
            for &e in &ks.entries[t * k..(t + 1) * k] {
                let (ex, ey) = (e as usize % 48, e as usize / 48);
                assert!(
                    ex.abs_diff(x) > 2 || ey.abs_diff(y) > 2,
                    "{e} is inside {t}'s window"
                );
                assert_eq!(ex % 6, x % 6, "texel {t}: {e} is on another phase");
            }
        }
    }

    #[test]
    fn build_is_thread_count_independent() {
        let p = TexelVariantParams {
            orientations: 3,
            ..Default::default()
        };
        let s = stripes(50, 46, 5.0);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| build_texel_variants(&s, &p, &|_| {}).unwrap());
        let two = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap()
            .install(|| build_texel_variants(&s, &p, &|_| {}).unwrap());
        assert_eq!(one, two);
    }
}
