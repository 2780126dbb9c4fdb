//! Whether a sample is large enough for the parameters: the variants with too few candidate
//! texels for their template, and the smallest sample side that gives every variant enough.

use super::params::{TexelVariantParams, VariantsError};
use super::resample::{level_sides, resampling};
use super::templates::{Template, candidates};

/// Candidates per feature set below which [`build_texel_variants`] warns that the variant is
/// too small to synthesize well from.
///
/// [`build_texel_variants`]: super::build_texel_variants
pub const FEW_CANDIDATES: usize = 64;

/// The first (scale, orientation, level, level side, candidates) of a `w × h` sample's
/// variants with fewer than `min` candidates for one of the templates.
pub(super) fn shortfall(
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
pub(super) fn side_needed(p: &TexelVariantParams, min: usize, start: u32) -> u32 {
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
