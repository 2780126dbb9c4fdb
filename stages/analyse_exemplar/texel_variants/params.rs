//! The analysis' parameters (orientations, scales, pyramid levels, templates, feature weights),
//! their validation, and its errors.

use crate::check::{ParamError, check_range};
use crate::image::knn::KdTreeError;
use serde::{Deserialize, Serialize};

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

pub(super) fn in_range<T: PartialOrd + std::fmt::Display>(
    name: &str,
    v: T,
    lo: T,
    hi: T,
) -> Result<(), ParamError> {
    check_range(name, v, lo, hi).map_err(|e| e.within("texel variants"))
}

pub(super) fn odd(name: &str, expected: &str, v: u32) -> Result<(), ParamError> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::assert_validation;

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
}
