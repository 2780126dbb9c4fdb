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
//!   variant without candidates and names the size needed; [`build_texel_variants`] warns when
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

use crate::check::{ParamError, check_range};
use crate::geom::geometry_image::TexelImage;
use crate::image::knn::{KdNode, KdTree, KdTreeError, KdTreeRef};
use crate::image::neighbourhood::mirror;
use crate::image::pca::{Pca, PcaParams};
use crate::image::{Image, pyramid};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use texsyn_core::math::PureMath;

/// The `texel_variants` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("texel_variants", 2);

/// Parameters of the variant set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TexelVariantParams {
    /// Number of equally spaced orientations, 1..=64. Default: 8 (§4.3).
    pub orientations: u32,
    /// Number of scales, odd, 1..=5: the middle one is the sample's size, each step a factor 2.
    /// Default: 3 (§4.3: T1 scaled up, T2 original, T3 scaled down).
    pub scales: u32,
    /// Gaussian pyramid levels, 1..=6. Default: 3 (§5: "a three-level Gaussian pyramid").
    pub levels: u32,
    /// Side of the causal Γ template of the main synthesis, odd, 3..=15. Default: 5.
    pub template: u32,
    /// Side of the full template of boundary resynthesis (§4.2.2), odd, 3..=15. Default: 5.
    pub boundary_template: u32,
    /// PCA components kept per feature set, 0..=64; 0 = automatic (the fewest explaining 99.9%
    /// of the variance, 8 to 24). Default: 16 (on the bumps of the tests, 4 components — what
    /// 95% of the variance asks for — blurred the result into blobs; 8 was clearly worse than
    /// 16, 24 no better).
    pub pca_dims: u32,
    /// Factor on the coarser level's taps, 0..=4 (its squared distances count `coarse_weight²`
    /// each). Default: 0.3. With 1, a 64² sample's coarse levels (16² texels at the third) are
    /// too small to synthesize faithfully and the finer levels copied their oversized blobs:
    /// on the tests' bumps the autocorrelation error was 0.30 at 1, 0.21 at 0.5 and 0.12 at 0.3.
    pub coarse_weight: f32,
    /// Weight of the colour channels (r, g, b) relative to the geometric ones after both are
    /// normalized by their spread, 0..=100. Ignored for 3-channel samples. Default: 1.
    pub color_weight: f32,
    /// Size `k` of the k-coherent sets (Tong et al. 2002) of the default synthesis search,
    /// 1..=16: for each texel of the sample's pyramid, the `k` texels with the most similar
    /// neighbourhoods. Default: 6.
    pub coherent_k: u32,
}

impl Default for TexelVariantParams {
    fn default() -> Self {
        TexelVariantParams {
            orientations: 8,
            scales: 3,
            levels: 3,
            template: 5,
            boundary_template: 5,
            pca_dims: 16,
            coarse_weight: 0.3,
            color_weight: 1.0,
            coherent_k: 6,
        }
    }
}

/// Why a variant set could not be built or read back. Messages name the sample or the
/// damaged part of a stored set.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VariantsError {
    #[error(transparent)]
    Params(#[from] ParamError),
    #[error(
        "texel variants: the sample is {width}×{height} texels, too small: at scale {scale} of \
         {scales} and orientation {degrees}° its cropped pyramid level {level} has only \
         {side}×{side} texels, too few for the {template}×{template} template and the \
         {boundary_template}×{boundary_template} boundary template (with the coarser level's \
         neighbourhood above the coarsest level); with these parameters the sample must be at \
         least {need}×{need}"
    )]
    TooSmall {
        width: u32,
        height: u32,
        /// 1-based.
        scale: usize,
        scales: u32,
        degrees: f64,
        level: usize,
        side: u32,
        template: u32,
        boundary_template: u32,
        need: u32,
    },
    #[error(
        "texel variants: the sample has {channels} channels, expected 3 (dx, dy, dn) or 6 (dx, dy, dn, r, g, b)"
    )]
    SampleChannels { channels: u32 },
    #[error(
        "texel variants: a {width}×{height} sample with {channels} channels needs {} values, got {got}",
        .width * .height * .channels
    )]
    SampleLength {
        width: u32,
        height: u32,
        channels: u32,
        got: usize,
    },
    #[error("texel variants: sample texel ({x}, {y}) channel {channel} is not a finite number")]
    SampleNotFinite { x: u32, y: u32, channel: u32 },
    #[error("texel variants: no array {name:?}")]
    NoArray { name: String },
    #[error(
        "texel variants: array {name:?} ({bytes} bytes) is not a {size}-byte aligned array: {cause}"
    )]
    Misaligned {
        name: String,
        bytes: usize,
        size: usize,
        cause: bytemuck::PodCastError,
    },
    #[error("texel variants: {what} ({len} values at {off}) lies outside its array ({array_len})")]
    OutsideArray {
        what: String,
        len: u64,
        off: u64,
        array_len: usize,
    },
    #[error("texel variants: {channels} channels, expected 3 or 6")]
    MetaChannels { channels: u32 },
    #[error("texel variants: bad channel weights")]
    ChannelWeights,
    #[error(
        "texel variants: metadata lists {levels} levels and {sets} feature sets, expected {want_levels} and {want_sets}"
    )]
    MetaCounts {
        levels: usize,
        sets: usize,
        want_levels: usize,
        want_sets: usize,
    },
    #[error("texel variants: {what} is not where the layout puts it")]
    Layout { what: String },
    #[error(
        "texel variants: {what} has dimensions {dim_in}→{dims} and {count} candidates (raw length {want} expected)"
    )]
    SetDims {
        what: String,
        dim_in: u32,
        dims: u32,
        count: u32,
        want: usize,
    },
    #[error("texel variants: {what} has a candidate outside its level")]
    CandidateOutside { what: String },
    #[error("texel variants: {what}: {cause}")]
    Tree { what: String, cause: KdTreeError },
}

fn in_range<T: PartialOrd + std::fmt::Display>(
    name: &str,
    v: T,
    lo: T,
    hi: T,
) -> Result<(), ParamError> {
    check_range(name, v, lo, hi).map_err(|e| e.within("texel variants"))
}

fn odd(name: &str, expected: &str, v: u32) -> Result<(), ParamError> {
    if v.is_multiple_of(2) {
        Err(
            ParamError::invalid(name, format!("must be odd ({expected}), got {v}"))
                .within("texel variants"),
        )
    } else {
        Ok(())
    }
}

impl TexelVariantParams {
    /// Checks every field; the error names the field, its range and the value. Float ranges
    /// have finite bounds, so NaN and infinities are out of range too.
    pub fn validate(&self) -> Result<(), ParamError> {
        in_range("orientations", self.orientations, 1, 64)?;
        in_range("scales", self.scales, 1, 5)?;
        odd("scales", "1, 3 or 5", self.scales)?;
        in_range("levels", self.levels, 1, 6)?;
        for (name, v) in [
            ("template", self.template),
            ("boundary_template", self.boundary_template),
        ] {
            in_range(name, v, 3, 15)?;
            odd(name, "3..=15", v)?;
        }
        in_range("pca_dims", self.pca_dims, 0, 64)?;
        in_range("coarse_weight", self.coarse_weight, 0.0, 4.0)?;
        in_range("color_weight", self.color_weight, 0.0, 100.0)?;
        in_range("coherent_k", self.coherent_k, 1, 16)
    }

    /// Levels of the sample pyramid that the k-coherent sets cover: variant level `l` of scale
    /// `s` corresponds to sample level `l + s − middle`, so `levels + middle`.
    pub fn kset_levels(&self) -> usize {
        self.levels as usize + self.middle_scale()
    }

    /// Number of variants (`orientations × scales`).
    pub fn variant_count(&self) -> usize {
        (self.orientations * self.scales) as usize
    }

    /// Index of the scale with the sample's own size (0-based; `T2` of the paper is 1).
    pub fn middle_scale(&self) -> usize {
        (self.scales as usize - 1) / 2
    }

    /// Estimated peak memory, in bytes, of the variants of a sample of `size`² texels:
    /// `orientations × scales` resampled copies, scale `j` steps from the middle holding `4^j`
    /// times the sample's texels, with their pyramids, feature vectors and trees. Measured on
    /// `configs/dragon_knot.toml` (a geometry-only sample; 8 orientations): peak 0.42 GB at
    /// 128² with 3 scales, 1.62 GB at 128² with 5, 5.93 GB at 256² with 5; about 580 bytes
    /// per texel of the unscaled variants' total. A sample with colour has twice the channels
    /// and up to twice the need. Without the per-texel search structures (`per_texel` false,
    /// the default k-coherence search) the variants are their pyramids' texels (12 bytes
    /// each, 16 with the pyramid) and the resampling's copies: estimated at 40 bytes per
    /// texel.
    pub fn memory_estimate(&self, size: u64, per_texel: bool) -> u64 {
        let mid = (self.scales as i32 - 1) / 2;
        let spread: f64 = (-mid..=mid).map(|j| 4f64.powi(j)).sum();
        let bytes = if per_texel { 580.0 } else { 40.0 };
        let per_texel = (bytes * self.orientations as f64 * spread) as u64;
        per_texel * size * size + (64 << 20)
    }
}

/// Which template a feature set describes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Template {
    /// The causal Γ half window of the scanline synthesis (§4.2.1).
    Causal,
    /// The full window of boundary resynthesis (§4.2.2).
    Full,
}

/// Side of the full coarser-level neighbourhood added to a template of side `side`:
/// `side − 2`, at least 3.
pub fn coarse_window(side: u32) -> u32 {
    side.saturating_sub(2).max(3)
}

/// Offsets `(dx, dy)` of a template's taps at its own level, in feature order (row by row):
/// for [`Template::Causal`] the `side / 2` rows above the centre and the texels left of it on
/// its row, for [`Template::Full`] the whole window.
pub fn template_taps(kind: Template, side: u32) -> Vec<(i32, i32)> {
    let r = (side / 2) as i32;
    let mut taps = Vec::new();
    for dy in -r..=r {
        for dx in -r..=r {
            if kind == Template::Causal && (dy > 0 || (dy == 0 && dx >= 0)) {
                continue;
            }
            taps.push((dx, dy));
        }
    }
    taps
}

/// Offsets of the coarser-level taps (the full window of [`coarse_window`]), in feature order.
pub fn coarse_taps(side: u32) -> Vec<(i32, i32)> {
    template_taps(Template::Full, coarse_window(side))
}

/// Feature length of a template with `channels` values per tap.
pub fn feature_dim(kind: Template, side: u32, with_coarse: bool, channels: u32) -> usize {
    let mut taps = template_taps(kind, side).len();
    if with_coarse {
        taps += coarse_taps(side).len();
    }
    taps * channels as usize
}

/// Size of one level of a variant pyramid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LevelMeta {
    pub width: u32,
    pub height: u32,
    /// Offset into the `texels` array, in f32 values.
    pub texel_offset: u64,
}

/// One feature set (a template at one level of one variant): where its arrays lie.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SetMeta {
    /// Raw feature length and PCA components kept.
    pub dim_in: u32,
    pub dims: u32,
    /// Candidate texels; their level-texel indices are `centres[centre_offset..][..count]`
    /// and the tree's ids `tree_ids[centre_offset..][..count]`.
    pub count: u32,
    pub centre_offset: u64,
    /// Offsets of the PCA mean (`dim_in` values) and basis (`dims × dim_in`).
    pub mean_offset: u64,
    pub basis_offset: u64,
    /// Offset of the tree points (`count × dims` values).
    pub point_offset: u64,
    pub node_offset: u64,
    pub node_count: u64,
}

/// The small, serializable part of [`TexelVariants`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VariantsMeta {
    pub params: TexelVariantParams,
    pub channels: u32,
    /// Size of the sample the variants were made from.
    pub sample_width: u32,
    pub sample_height: u32,
    /// Per channel, the factor applied before features are compared.
    pub channel_weights: Vec<f32>,
    /// Per (variant, level), variant-major: `levels[v * levels + l]`. Variant `v` has scale
    /// `v / orientations` and orientation `v % orientations`.
    pub levels: Vec<LevelMeta>,
    /// Per (variant, level, template), `sets[(v * levels + l) * 2 + t]`, `t` 0 for the causal
    /// and 1 for the full template. Empty unless `per_texel`.
    pub sets: Vec<SetMeta>,
    /// Whether the per-texel search structures (PCA bases, kd-trees) were built.
    pub per_texel: bool,
    /// Per level of the sample pyramid ([`TexelVariantParams::kset_levels`]), its size and
    /// where its k-coherent sets (`coherent_k` texel indices per texel) start in `kset`.
    pub ksets: Vec<LevelMeta>,
}

/// The variant set, owned: flat arrays described by [`VariantsMeta`].
#[derive(Clone, Debug, PartialEq)]
pub struct TexelVariants {
    pub meta: VariantsMeta,
    pub texels: Vec<f32>,
    pub centres: Vec<u32>,
    pub pca_mean: Vec<f32>,
    pub pca_basis: Vec<f32>,
    pub tree_points: Vec<f32>,
    pub tree_ids: Vec<u32>,
    pub tree_nodes: Vec<KdNode>,
    /// The k-coherent sets, see [`VariantsMeta::ksets`]; `u32::MAX` pads a set of a level with
    /// too few texels.
    pub kset: Vec<u32>,
}

/// Names of the arrays of [`TexelVariants::arrays`], in order.
pub const ARRAY_NAMES: [&str; 8] = [
    "texels",
    "centres",
    "pca_mean",
    "pca_basis",
    "tree_points",
    "tree_ids",
    "tree_nodes",
    "kset",
];

/// One level of the sample pyramid's k-coherent sets, borrowed.
#[derive(Clone, Copy, Debug)]
pub struct KsetRef<'a> {
    pub width: u32,
    pub height: u32,
    /// `k` texel indices (`y * width + x`) per texel, row-major; `u32::MAX` for none.
    pub entries: &'a [u32],
}

/// The affine map from a variant level's texel coordinates to the sample's level-0 texel
/// coordinates (`x0 = a · q + b`), and back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleMap {
    pub a: [[f64; 2]; 2],
    pub b: [f64; 2],
    pub inv: [[f64; 2]; 2],
}

impl SampleMap {
    #[inline]
    pub fn to_sample(&self, q: [f64; 2]) -> [f64; 2] {
        let a = &self.a;
        [
            a[0][0] * q[0] + a[0][1] * q[1] + self.b[0],
            a[1][0] * q[0] + a[1][1] * q[1] + self.b[1],
        ]
    }

    #[inline]
    pub fn from_sample(&self, x: [f64; 2]) -> [f64; 2] {
        let (u, v) = (x[0] - self.b[0], x[1] - self.b[1]);
        let m = &self.inv;
        [m[0][0] * u + m[0][1] * v, m[1][0] * u + m[1][1] * v]
    }
}

/// One level of one variant, borrowed: `width × height` texels of `channels` values.
#[derive(Clone, Copy, Debug)]
pub struct LevelRef<'a> {
    pub width: u32,
    pub height: u32,
    pub texels: &'a [f32],
}

/// One feature set, borrowed.
#[derive(Clone, Copy, Debug)]
pub struct SetRef<'a> {
    pub dim_in: usize,
    pub dims: usize,
    /// Level-texel index (`y * width + x`) of each candidate.
    pub centres: &'a [u32],
    pub mean: &'a [f32],
    pub basis: &'a [f32],
    /// Over the PCA-reduced features; ids index `centres`.
    pub tree: KdTreeRef<'a>,
}

impl SetRef<'_> {
    /// PCA coordinates of a raw feature vector (as [`Pca::project`]).
    #[inline]
    pub fn project(&self, v: &[f32], out: &mut [f32]) {
        debug_assert_eq!(v.len(), self.dim_in);
        for (o, b) in out.iter_mut().zip(self.basis.chunks_exact(self.dim_in)) {
            let mut acc = 0.0f32;
            for ((&x, &m), &e) in v.iter().zip(self.mean).zip(b) {
                acc += (x - m) * e;
            }
            *o = acc;
        }
    }
}

/// The variant set, borrowed (from a [`TexelVariants`] or a mapped artifact) and checked.
#[derive(Clone, Debug)]
pub struct TexelVariantsRef<'a> {
    pub meta: VariantsMeta,
    levels: Vec<LevelRef<'a>>,
    sets: Vec<SetRef<'a>>,
    ksets: Vec<KsetRef<'a>>,
}

impl<'a> TexelVariantsRef<'a> {
    pub fn params(&self) -> &TexelVariantParams {
        &self.meta.params
    }

    pub fn channels(&self) -> usize {
        self.meta.channels as usize
    }

    /// Pyramid levels of every variant.
    pub fn levels(&self) -> usize {
        self.meta.params.levels as usize
    }

    pub fn variant_count(&self) -> usize {
        self.meta.params.variant_count()
    }

    /// Variant index of scale `scale` (0 = most enlarged) and orientation `orientation`.
    #[inline]
    pub fn variant(&self, scale: usize, orientation: usize) -> usize {
        scale * self.meta.params.orientations as usize + orientation
    }

    #[inline]
    pub fn level(&self, variant: usize, level: usize) -> LevelRef<'a> {
        self.levels[variant * self.levels() + level]
    }

    /// The per-texel feature set; `None` when the set was built without them
    /// (`meta.per_texel` false).
    #[inline]
    pub fn try_set(&self, variant: usize, level: usize, kind: Template) -> Option<&SetRef<'a>> {
        let t = match kind {
            Template::Causal => 0,
            Template::Full => 1,
        };
        self.sets.get((variant * self.levels() + level) * 2 + t)
    }

    /// As [`Self::try_set`]; panics without per-texel structures.
    #[inline]
    pub fn set(&self, variant: usize, level: usize, kind: Template) -> &SetRef<'a> {
        self.try_set(variant, level, kind)
            .expect("texel variants built without per-texel search structures")
    }

    /// The k-coherent sets of sample pyramid level `level`.
    #[inline]
    pub fn kset(&self, level: usize) -> &KsetRef<'a> {
        &self.ksets[level]
    }

    /// `k` of the k-coherent sets.
    pub fn coherent_k(&self) -> usize {
        self.meta.params.coherent_k as usize
    }

    /// Sample pyramid level matching level `level` of `variant` (see
    /// [`TexelVariantParams::kset_levels`]).
    pub fn kset_level_of(&self, variant: usize, level: usize) -> usize {
        let p = &self.meta.params;
        let s = variant / p.orientations as usize;
        (level + s)
            .saturating_sub(p.middle_scale())
            .min(p.kset_levels() - 1)
    }

    /// The map between level `level` of `variant` and the sample's level 0 (see
    /// [`resample_variant`]: the variant's level-0 texel `p` shows the source level's point
    /// `c + R(−θ) (p − h) / m`).
    pub fn sample_map(&self, variant: usize, level: usize) -> SampleMap {
        let p = &self.meta.params;
        let (s, k) = (
            variant / p.orientations as usize,
            (variant % p.orientations as usize) as u32,
        );
        let rs = resampling(self.meta.sample_width, self.meta.sample_height, p, s, k);
        let (mut w, mut h) = (self.meta.sample_width, self.meta.sample_height);
        for _ in 0..rs.source_level {
            w = w.div_ceil(2);
            h = h.div_ceil(2);
        }
        let (cos, sin) = orientation_cos_sin(k, p.orientations);
        let f = (1u64 << rs.source_level) as f64;
        let g = (1u64 << level) as f64 / rs.magnification;
        let half = (rs.side as f64 - 1.0) / 2.0;
        let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
        // x0 = f (c + R(−θ) (g q − h (1, 1)) / 1) with R(−θ) = [[cos, sin], [−sin, cos]] and
        // g folding the level's spacing and the magnification.
        let a = [[f * g * cos, f * g * sin], [-f * g * sin, f * g * cos]];
        let hm = half / rs.magnification;
        let b = [
            f * (cx - (cos * hm + sin * hm)),
            f * (cy - (-sin * hm + cos * hm)),
        ];
        let ig = 1.0 / (f * g);
        let inv = [[ig * cos, -ig * sin], [ig * sin, ig * cos]];
        SampleMap { a, b, inv }
    }

    /// Views arrays exported by [`TexelVariants::arrays`]. `get` returns an array's bytes by
    /// name (`None` if absent); they must be aligned for their element type (artifact arrays
    /// are). Every size, offset and index is checked against the metadata, so damaged input is
    /// an error, never a panic or an out-of-bounds read during synthesis.
    pub fn from_arrays(
        meta: VariantsMeta,
        get: impl Fn(&str) -> Option<&'a [u8]>,
    ) -> Result<TexelVariantsRef<'a>, VariantsError> {
        use VariantsError as E;
        fn arr<'b, T: bytemuck::Pod>(
            get: &impl Fn(&str) -> Option<&'b [u8]>,
            name: &str,
        ) -> Result<&'b [T], VariantsError> {
            let raw = get(name).ok_or_else(|| E::NoArray { name: name.into() })?;
            bytemuck::try_cast_slice(raw).map_err(|e| E::Misaligned {
                name: name.into(),
                bytes: raw.len(),
                size: std::mem::size_of::<T>(),
                cause: e,
            })
        }
        fn sub<'b, T>(
            a: &'b [T],
            off: u64,
            len: u64,
            what: &str,
        ) -> Result<&'b [T], VariantsError> {
            let end = off.checked_add(len);
            match end {
                Some(e) if e <= a.len() as u64 => Ok(&a[off as usize..e as usize]),
                _ => Err(E::OutsideArray {
                    what: what.into(),
                    len,
                    off,
                    array_len: a.len(),
                }),
            }
        }
        meta.params.validate()?;
        let c = meta.channels;
        if c != 3 && c != 6 {
            return Err(E::MetaChannels { channels: c });
        }
        if meta.channel_weights.len() != c as usize
            || meta.channel_weights.iter().any(|w| !w.is_finite())
        {
            return Err(E::ChannelWeights);
        }
        let nv = meta.params.variant_count();
        let nl = meta.params.levels as usize;
        let want_sets = if meta.per_texel { nv * nl * 2 } else { 0 };
        if meta.levels.len() != nv * nl || meta.sets.len() != want_sets {
            return Err(E::MetaCounts {
                levels: meta.levels.len(),
                sets: meta.sets.len(),
                want_levels: nv * nl,
                want_sets,
            });
        }
        if meta.ksets.len() != meta.params.kset_levels() {
            return Err(E::Layout {
                what: "the k-coherent set levels".into(),
            });
        }
        let texels: &[f32] = arr(&get, "texels")?;
        let centres: &[u32] = arr(&get, "centres")?;
        let pca_mean: &[f32] = arr(&get, "pca_mean")?;
        let pca_basis: &[f32] = arr(&get, "pca_basis")?;
        let tree_points: &[f32] = arr(&get, "tree_points")?;
        let tree_ids: &[u32] = arr(&get, "tree_ids")?;
        let tree_nodes: &[KdNode] = arr(&get, "tree_nodes")?;
        let kset: &[u32] = arr(&get, "kset")?;
        // The layout is the canonical one (arrays concatenated in order, nothing between or
        // after), so a metadata entry that disagrees with its neighbours is caught.
        let layout_err = |what: &str| E::Layout { what: what.into() };
        let mut next_texel = 0u64;
        let mut levels = Vec::with_capacity(meta.levels.len());
        for (i, lm) in meta.levels.iter().enumerate() {
            let n = lm.width as u64 * lm.height as u64 * c as u64;
            if lm.texel_offset != next_texel {
                return Err(layout_err(&format!("level {i}")));
            }
            next_texel += n;
            let t = sub(texels, lm.texel_offset, n, &format!("level {i}"))?;
            levels.push(LevelRef {
                width: lm.width,
                height: lm.height,
                texels: t,
            });
        }
        if next_texel != texels.len() as u64 {
            return Err(layout_err("the end of the texels"));
        }
        let mut next = [0u64; 5]; // centres/ids, mean, basis, points, nodes
        let mut sets = Vec::with_capacity(meta.sets.len());
        for (i, sm) in meta.sets.iter().enumerate() {
            let vl = i / 2;
            let kind = if i % 2 == 0 {
                Template::Causal
            } else {
                Template::Full
            };
            let side = match kind {
                Template::Causal => meta.params.template,
                Template::Full => meta.params.boundary_template,
            };
            let with_coarse = vl % nl + 1 < nl;
            let want = feature_dim(kind, side, with_coarse, c);
            let what = format!("feature set {i}");
            if sm.dim_in as usize != want || sm.dims == 0 || sm.dims > sm.dim_in || sm.count == 0 {
                return Err(E::SetDims {
                    what,
                    dim_in: sm.dim_in,
                    dims: sm.dims,
                    count: sm.count,
                    want,
                });
            }
            let offsets = [
                sm.centre_offset,
                sm.mean_offset,
                sm.basis_offset,
                sm.point_offset,
                sm.node_offset,
            ];
            if offsets != next {
                return Err(layout_err(&what));
            }
            next[0] += sm.count as u64;
            next[1] += sm.dim_in as u64;
            next[2] += sm.dims as u64 * sm.dim_in as u64;
            next[3] += sm.count as u64 * sm.dims as u64;
            next[4] += sm.node_count;
            let lv = levels[vl];
            let cs = sub(centres, sm.centre_offset, sm.count as u64, &what)?;
            let texel_count = lv.width * lv.height;
            if cs.iter().any(|&x| x >= texel_count) {
                return Err(E::CandidateOutside { what });
            }
            let ids = sub(tree_ids, sm.centre_offset, sm.count as u64, &what)?;
            let points = sub(
                tree_points,
                sm.point_offset,
                sm.count as u64 * sm.dims as u64,
                &what,
            )?;
            let nodes = sub(tree_nodes, sm.node_offset, sm.node_count, &what)?;
            let tree = KdTreeRef::from_parts(sm.dims as usize, points, ids, nodes, sm.count)
                .map_err(|e| E::Tree {
                    what: what.clone(),
                    cause: e,
                })?;
            sets.push(SetRef {
                dim_in: sm.dim_in as usize,
                dims: sm.dims as usize,
                centres: cs,
                mean: sub(pca_mean, sm.mean_offset, sm.dim_in as u64, &what)?,
                basis: sub(
                    pca_basis,
                    sm.basis_offset,
                    sm.dims as u64 * sm.dim_in as u64,
                    &what,
                )?,
                tree,
            });
        }
        let lens = [
            centres.len(),
            pca_mean.len(),
            pca_basis.len(),
            tree_points.len(),
            tree_nodes.len(),
        ];
        if next.iter().zip(lens).any(|(&a, b)| a != b as u64) || tree_ids.len() != centres.len() {
            return Err(layout_err("the end of the feature arrays"));
        }
        let k = meta.params.coherent_k as u64;
        let mut next_k = 0u64;
        let mut ksets = Vec::with_capacity(meta.ksets.len());
        for (i, km) in meta.ksets.iter().enumerate() {
            let count = km.width as u64 * km.height as u64;
            let what = format!("k-coherent sets of sample level {i}");
            if km.texel_offset != next_k {
                return Err(layout_err(&what));
            }
            next_k += count * k;
            let entries = sub(kset, km.texel_offset, count * k, &what)?;
            if entries.iter().any(|&e| e != u32::MAX && e as u64 >= count) {
                return Err(E::CandidateOutside { what });
            }
            ksets.push(KsetRef {
                width: km.width,
                height: km.height,
                entries,
            });
        }
        if next_k != kset.len() as u64 {
            return Err(layout_err("the end of the k-coherent sets"));
        }
        Ok(TexelVariantsRef {
            meta,
            levels,
            sets,
            ksets,
        })
    }
}

impl TexelVariants {
    /// The flat arrays, named as in [`ARRAY_NAMES`], as little-endian bytes.
    pub fn arrays(&self) -> Vec<(&'static str, &[u8])> {
        vec![
            ("texels", bytemuck::cast_slice(&self.texels)),
            ("centres", bytemuck::cast_slice(&self.centres)),
            ("pca_mean", bytemuck::cast_slice(&self.pca_mean)),
            ("pca_basis", bytemuck::cast_slice(&self.pca_basis)),
            ("tree_points", bytemuck::cast_slice(&self.tree_points)),
            ("tree_ids", bytemuck::cast_slice(&self.tree_ids)),
            ("tree_nodes", bytemuck::cast_slice(&self.tree_nodes)),
            ("kset", bytemuck::cast_slice(&self.kset)),
        ]
    }

    /// A checked borrowed view.
    pub fn as_ref(&self) -> TexelVariantsRef<'_> {
        let arrays = self.arrays();
        TexelVariantsRef::from_arrays(self.meta.clone(), |name| {
            arrays.iter().find(|(n, _)| *n == name).map(|(_, b)| *b)
        })
        .expect("freshly built texel variants are consistent")
    }
}

/// `cos θ` and `sin θ` of orientation `k` of `count`, exact at multiples of 90°.
pub fn orientation_cos_sin(k: u32, count: u32) -> (f64, f64) {
    let theta = std::f64::consts::TAU * k as f64 / count as f64;
    let snap = |v: f64| {
        if v.abs() < 1e-12 {
            0.0
        } else if (v.abs() - 1.0).abs() < 1e-12 {
            v.signum()
        } else {
            v
        }
    };
    (snap(theta.cos_pure()), snap(theta.sin_pure()))
}

/// Rotates `(dx, dy)` by the angle with cosine `c` and sine `s` (`x' = c x − s y`).
#[inline]
fn rotate(c: f64, s: f64, dx: f32, dy: f32) -> (f32, f32) {
    let (dx, dy) = (dx as f64, dy as f64);
    ((c * dx - s * dy) as f32, (s * dx + c * dy) as f32)
}

/// How a variant is resampled: from which level of the sample's pyramid, at what
/// magnification relative to it, and the side of the resulting square.
#[derive(Clone, Copy, Debug)]
struct Resampling {
    source_level: usize,
    magnification: f64,
    side: u32,
}

fn resampling(
    sample_w: u32,
    sample_h: u32,
    params: &TexelVariantParams,
    scale: usize,
    orientation: u32,
) -> Resampling {
    // Scale factor 2^(middle − scale): 2 for T1, 1 for T2, 1/2 for T3.
    let e = params.middle_scale() as i32 - scale as i32;
    let (source_level, magnification) = if e >= 0 {
        (0usize, (1u32 << e) as f64)
    } else {
        ((-e) as usize, 1.0)
    };
    let (mut w, mut h) = (sample_w, sample_h);
    for _ in 0..source_level {
        w = w.div_ceil(2);
        h = h.div_ceil(2);
    }
    let (c, s) = orientation_cos_sin(orientation, params.orientations);
    let extent = (w.min(h).max(1) - 1) as f64;
    let side = (magnification * extent / (c.abs() + s.abs()) + 1e-6).floor() as u32 + 1;
    Resampling {
        source_level,
        magnification,
        side,
    }
}

/// Sizes of the pyramid levels of a square of side `side`.
fn level_sides(side: u32, levels: u32) -> Vec<u32> {
    let mut out = vec![side];
    for _ in 1..levels {
        let last = *out.last().unwrap();
        out.push(last.div_ceil(2));
    }
    out
}

/// Candidate centres of a template on a `w × h` level (`coarse` the size of the next coarser
/// level, if any), row-major.
fn candidates(kind: Template, side: u32, w: u32, h: u32, coarse: Option<(u32, u32)>) -> Vec<u32> {
    let r = side / 2;
    let y_hi = match kind {
        Template::Causal => h as i64 - 1,
        Template::Full => h as i64 - 1 - r as i64,
    };
    let x_hi = w as i64 - 1 - r as i64;
    let rc = coarse_window(side) / 2;
    let mut out = Vec::new();
    for y in r as i64..=y_hi {
        for x in r as i64..=x_hi {
            if let Some((cw, ch)) = coarse {
                let (cx, cy) = (x / 2, y / 2);
                if cx < rc as i64
                    || cy < rc as i64
                    || cx > cw as i64 - 1 - rc as i64
                    || cy > ch as i64 - 1 - rc as i64
                {
                    continue;
                }
            }
            out.push((y * w as i64 + x) as u32);
        }
    }
    out
}

/// Candidates per feature set below which [`build_texel_variants`] warns that the variant is
/// too small to synthesize well from.
pub const FEW_CANDIDATES: usize = 64;

/// The first (scale, orientation, level, level side, candidates) of a `w × h` sample's
/// variants with fewer than `min` candidates for one of the templates.
fn shortfall(
    w: u32,
    h: u32,
    p: &TexelVariantParams,
    min: usize,
) -> Option<(usize, u32, usize, u32, usize)> {
    for scale in 0..p.scales as usize {
        for k in 0..p.orientations {
            let rs = resampling(w, h, p, scale, k);
            let sides = level_sides(rs.side, p.levels);
            for l in 0..sides.len() {
                let coarse = sides.get(l + 1).map(|&s| (s, s));
                for (kind, t) in [
                    (Template::Causal, p.template),
                    (Template::Full, p.boundary_template),
                ] {
                    let count = candidates(kind, t, sides[l], sides[l], coarse).len();
                    if count < min {
                        return Some((scale, k, l, sides[l], count));
                    }
                }
            }
        }
    }
    None
}

/// The smallest square sample side from `start` up whose variants all have `min` candidates.
fn side_needed(p: &TexelVariantParams, min: usize, start: u32) -> u32 {
    let mut need = start.max(1);
    while shortfall(need, need, p, min).is_some() && need < 1 << 16 {
        need += 1;
    }
    need
}

/// Checks that `width × height` is large enough: every level of every variant must keep at
/// least one candidate for both templates. The error names the smallest square sample that
/// would do.
pub fn check_sample_size(
    width: u32,
    height: u32,
    params: &TexelVariantParams,
) -> Result<(), VariantsError> {
    params.validate()?;
    let Some((scale, k, l, side, _)) = shortfall(width, height, params, 1) else {
        return Ok(());
    };
    Err(VariantsError::TooSmall {
        width,
        height,
        scale: scale + 1,
        scales: params.scales,
        degrees: k as f64 * 360.0 / params.orientations as f64,
        level: l,
        side,
        template: params.template,
        boundary_template: params.boundary_template,
        need: side_needed(params, 1, width.max(height)),
    })
}

/// Packs a texel image's channels into RGBA images (3 channels each, alpha 1), so the image
/// pyramid code can filter them.
fn to_images(t: &TexelImage) -> Vec<Image> {
    let c = t.channels as usize;
    (0..c.div_ceil(3))
        .map(|g| {
            let pixels = t
                .data
                .chunks_exact(c)
                .map(|px| {
                    let mut p = [0.0, 0.0, 0.0, 1.0];
                    for k in 0..3 {
                        if let Some(&v) = px.get(g * 3 + k) {
                            p[k] = v;
                        }
                    }
                    p
                })
                .collect();
            Image {
                width: t.width,
                height: t.height,
                pixels,
            }
        })
        .collect()
}

fn from_images(imgs: &[Image], channels: u32) -> TexelImage {
    let (w, h) = (imgs[0].width, imgs[0].height);
    let c = channels as usize;
    let mut out = TexelImage::new(w, h, channels);
    for (i, px) in out.data.chunks_exact_mut(c).enumerate() {
        for (k, v) in px.iter_mut().enumerate() {
            *v = imgs[k / 3].pixels[i][k % 3];
        }
    }
    out
}

/// One Gaussian pyramid step of a texel image: the binomial blur and decimation of
/// [`pyramid::downsample`] on every channel (`w × h` gives `⌈w/2⌉ × ⌈h/2⌉`; texel `i` of the
/// result sits at `2 i`).
pub fn downsample_texels(t: &TexelImage) -> TexelImage {
    let imgs: Vec<Image> = to_images(t)
        .iter()
        .map(|i| pyramid::downsample(i.view()))
        .collect();
    from_images(&imgs, t.channels)
}

/// The Gaussian pyramid of a texel image, `levels` levels (level 0 is the input), however small
/// they get.
pub fn texel_pyramid(t: &TexelImage, levels: usize) -> Vec<TexelImage> {
    let mut out = vec![t.clone()];
    while out.len() < levels {
        let next = downsample_texels(out.last().unwrap());
        out.push(next);
    }
    out
}

/// Bilinear sample of a texel image at a continuous address (integers = texel centres),
/// coordinates clamped to the image.
fn bilinear(t: &TexelImage, x: f64, y: f64, out: &mut [f32]) {
    let x = x.clamp(0.0, (t.width - 1) as f64);
    let y = y.clamp(0.0, (t.height - 1) as f64);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    let (x0, y0) = (x0 as u32, y0 as u32);
    let x1 = (x0 + 1).min(t.width - 1);
    let y1 = (y0 + 1).min(t.height - 1);
    let (a, b, c, d) = (
        t.texel(x0, y0),
        t.texel(x1, y0),
        t.texel(x0, y1),
        t.texel(x1, y1),
    );
    for k in 0..out.len() {
        let top = a[k] + (b[k] - a[k]) * fx;
        let bot = c[k] + (d[k] - c[k]) * fx;
        out[k] = top + (bot - top) * fy;
    }
}

/// The rotated, scaled and cropped sample of one variant (level 0), see the module docs.
/// `sources` is the sample's pyramid (as many levels as the smallest scale needs).
pub fn resample_variant(
    sources: &[TexelImage],
    params: &TexelVariantParams,
    scale: usize,
    orientation: u32,
) -> TexelImage {
    let s0 = &sources[0];
    let rs = resampling(s0.width, s0.height, params, scale, orientation);
    let src = &sources[rs.source_level];
    let (cos, sin) = orientation_cos_sin(orientation, params.orientations);
    let c = src.channels as usize;
    let side = rs.side;
    let mut out = TexelImage::new(side, side, src.channels);
    let half_v = (side as f64 - 1.0) / 2.0;
    let (cx, cy) = (
        (src.width as f64 - 1.0) / 2.0,
        (src.height as f64 - 1.0) / 2.0,
    );
    let m = rs.magnification;
    out.data
        .par_chunks_mut(side as usize * c)
        .enumerate()
        .for_each(|(py, row)| {
            for (px, o) in row.chunks_exact_mut(c).enumerate() {
                let (ux, uy) = (px as f64 - half_v, py as f64 - half_v);
                // Source point: R(−θ) u / m about the source centre.
                let sx = cx + (cos * ux + sin * uy) / m;
                let sy = cy + (-sin * ux + cos * uy) / m;
                bilinear(src, sx, sy, o);
                let (dx, dy) = rotate(cos, sin, o[0], o[1]);
                o[0] = dx;
                o[1] = dy;
            }
        });
    out
}

/// Writes the raw feature vector of the template `kind` (side `side`) centred on `(x, y)` of
/// `level`, with `coarser` the next level if any. The template must lie inside (a candidate).
#[allow(clippy::too_many_arguments)]
fn write_feature(
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
fn channel_weights(sample: &TexelImage, color_weight: f32) -> Vec<f32> {
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
fn features(
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
    build_texel_variants_with(sample, params, true, progress)
}

/// The k-coherent sets of every level of the sample pyramid `pyr`: per texel, the
/// `k` texels with the nearest feature vectors (the full `side`² window plus the coarser
/// level's [`coarse_window`], read mirrored at the borders so every texel has one; PCA-reduced
/// as the per-texel sets are), leaving out the texel's own `side`² window, whose texels the
/// coherent candidates already bring. Returns the level sizes and the concatenated sets.
fn k_coherent_sets(
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

/// [`build_texel_variants`]; `per_texel` false leaves out the per-texel search structures
/// (PCA bases and kd-trees of every variant, level and template: nearly all of the set's size
/// and build time), which only `synthesize.search = "per_texel"` reads.
pub fn build_texel_variants_with(
    sample: &TexelImage,
    params: &TexelVariantParams,
    per_texel: bool,
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
    check_sample_size(sample.width, sample.height, params)?;
    if let Some((scale, k, l, side, count)) =
        shortfall(sample.width, sample.height, params, FEW_CANDIDATES)
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
    let (kset_meta, kset) = k_coherent_sets(&sources, params, &weights);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::assert_validation;

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
    fn params_validate_names_the_field() {
        assert_validation!(TexelVariantParams {
            template: 4 => "texel variants: template must be odd (3..=15), got 4",
            scales: 2 => "texel variants: scales must be odd (1, 3 or 5), got 2",
            color_weight: f32::NAN =>
                "texel variants: color_weight must be in 0..=100, got NaN",
        });
        let e: Result<TexelVariantParams, _> = toml::from_str("orientation = 8");
        assert!(e.is_err(), "unknown fields are refused");
    }

    #[test]
    fn causal_template_reads_only_earlier_texels() {
        let taps = template_taps(Template::Causal, 5);
        assert_eq!(taps.len(), 12);
        assert!(taps.iter().all(|&(dx, dy)| dy < 0 || (dy == 0 && dx < 0)));
        assert_eq!(template_taps(Template::Full, 5).len(), 25);
        assert_eq!(coarse_taps(5).len(), 9);
        assert_eq!(feature_dim(Template::Causal, 5, true, 3), 63);
    }

    #[test]
    fn variant_sizes_crop_inside_the_rotated_sample() {
        let p = TexelVariantParams::default();
        // 0°: the whole sample (scaled); 45°: side / √2.
        assert_eq!(resampling(64, 64, &p, 1, 0).side, 64);
        assert_eq!(resampling(64, 64, &p, 0, 0).side, 127);
        assert_eq!(resampling(64, 64, &p, 2, 0).side, 32);
        assert_eq!(resampling(64, 64, &p, 1, 2).side, 64); // 90°
        assert_eq!(
            resampling(64, 64, &p, 1, 1).side,
            (63.0 / 2f64.sqrt()) as u32 + 1
        );
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
    fn small_variants_are_found_for_the_warning() {
        let p = TexelVariantParams::default();
        // 64²: the scaled-down unrotated variant is 32² texels, 8² at level 2: the causal
        // template has 4 × 6 candidates there.
        let (scale, k, l, side, count) = shortfall(64, 64, &p, FEW_CANDIDATES).unwrap();
        assert_eq!((scale, k, l, side, count), (2, 0, 2, 8, 24));
        assert!(shortfall(64, 64, &p, 1).is_none());
        let n = side_needed(&p, FEW_CANDIDATES, 64);
        assert!(shortfall(n, n, &p, FEW_CANDIDATES).is_none());
        assert!(shortfall(n - 1, n - 1, &p, FEW_CANDIDATES).is_some());
        println!("a sample of {n}² gives every level {FEW_CANDIDATES} candidates");
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
        let owned = build_texel_variants_with(&sample, &p, false, &|_| {}).unwrap();
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
        let owned = build_texel_variants_with(&sample, &p, false, &|_| {}).unwrap();
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
