//! Jump maps: for every exemplar pixel, a short weighted list of other pixels whose
//! neighbourhoods look like its own.
//!
//! Implements the analysis phase of S. Zelinka and M. Garland, "Towards real-time texture
//! synthesis with the jump map", Eurographics Workshop on Rendering 2002, as summarized in §4.2.1
//! and §4.2.5 of Zelinka and Garland, "Interactive texture synthesis on surfaces using jump maps"
//! (2003): each pixel is described by Gaussian-weighted neighbourhoods over a few levels of a
//! Gaussian pyramid, the descriptors are reduced by PCA, and a kd-tree finds the best matches.
//! Jump weights are "normalized to sum to one, or a lower value if the jumps at that pixel were
//! not very good".
//!
//! Departures and choices the papers leave open:
//! - Matches are exact nearest neighbours in the PCA space by default (the 2002 paper used
//!   approximate search for speed); `search_eps > 0` switches to approximate search.
//! - Spatially close matches are excluded inside the search (a filtered kNN) instead of by
//!   post-filtering a longer list, and a match within `exclusion_radius` of a better match
//!   already chosen for the same pixel is skipped as well, so the k jumps lead to k different
//!   places.
//! - Similarity is `s = exp(-d² / 2σ²)`, with `d` the feature distance and σ the median over
//!   pixels of the best jump's distance; weights are `s / max(1, Σ s)`, and never below
//!   [`MIN_WEIGHT`] so that a found jump is never mistaken for an empty slot.
//! - The PCA basis is fitted on at most `pca_samples` pixels (a regular subsample), then applied
//!   to every pixel.
//!
//! Output is identical for any number of threads: neighbourhoods, PCA and kd-tree are
//! deterministic and every pixel's search writes only its own slots.

use crate::image::ImageView;
use rayon::prelude::*;

/// The smallest weight a found jump gets (weight 0 marks an unused slot).
pub const MIN_WEIGHT: f32 = 1e-9;

/// Largest exemplar side: addresses are stored as u16.
pub const MAX_EXEMPLAR_SIDE: u32 = u16::MAX as u32 + 1;

/// One jump: a destination pixel and its weight. `weight == 0` marks an unused slot.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Jump {
    pub x: u16,
    pub y: u16,
    pub weight: f32,
}

/// Parameters of the jump-map analysis.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct JumpMapParams {
    /// Gaussian pyramid levels compared, 1..=8 (fewer are used if the exemplar is too small to
    /// have them). Default: 3.
    pub levels: u32,
    /// Neighbourhood window side at the finest level, odd, 1..=15; coarser levels use
    /// `window - 2·level`, at least 3. Default: 5.
    pub window: u32,
    /// PCA components kept, 0..=64; 0 = automatic (the fewest explaining 95% of the variance,
    /// at least 4, at most 16). Default: 0.
    pub pca_dims: u32,
    /// Jumps stored per pixel (k), 1..=32. Default: 4.
    pub jumps_per_pixel: u32,
    /// In pixels, 0..=10000: jumps go farther than this from their source pixel and from each
    /// other. Default: 4.
    pub exclusion_radius: f32,
    /// Pixels used to fit the PCA basis, 256..=16777216 (a regular subsample if the exemplar
    /// has more). Default: 65536.
    pub pca_samples: u32,
    /// Approximate-search factor, 0..=10: a found match is at most `1 + search_eps` times
    /// farther than the true one. 0 = exact. Default: 0.
    pub search_eps: f32,
}

impl Default for JumpMapParams {
    fn default() -> Self {
        JumpMapParams {
            levels: 3,
            window: 5,
            pca_dims: 0,
            jumps_per_pixel: 4,
            exclusion_radius: 4.0,
            pca_samples: 65536,
            search_eps: 0.0,
        }
    }
}

impl JumpMapParams {
    /// Checks every field's range; the error names the field, its range and the value.
    pub fn validate(&self) -> Result<(), String> {
        fn range<T: PartialOrd + std::fmt::Display>(
            name: &str,
            v: T,
            lo: T,
            hi: T,
        ) -> Result<(), String> {
            if v >= lo && v <= hi {
                Ok(())
            } else {
                Err(format!("jump map: {name} must be in {lo}..={hi}, got {v}"))
            }
        }
        range("levels", self.levels, 1, 8)?;
        range("window", self.window, 1, 15)?;
        if self.window % 2 == 0 {
            return Err(format!(
                "jump map: window must be odd (1..=15), got {}",
                self.window
            ));
        }
        range("pca_dims", self.pca_dims, 0, 64)?;
        range("jumps_per_pixel", self.jumps_per_pixel, 1, 32)?;
        if !self.exclusion_radius.is_finite() {
            return Err(format!(
                "jump map: exclusion_radius must be in 0..=10000, got {}",
                self.exclusion_radius
            ));
        }
        range("exclusion_radius", self.exclusion_radius, 0.0, 10000.0)?;
        range("pca_samples", self.pca_samples, 256, 1 << 24)?;
        if !self.search_eps.is_finite() {
            return Err(format!(
                "jump map: search_eps must be in 0..=10, got {}",
                self.search_eps
            ));
        }
        range("search_eps", self.search_eps, 0.0, 10.0)?;
        Ok(())
    }
}

/// Checks that an exemplar can have a jump map (addresses are u16).
pub fn check_exemplar_size(width: u32, height: u32) -> Result<(), String> {
    if width == 0 || height == 0 || width > MAX_EXEMPLAR_SIDE || height > MAX_EXEMPLAR_SIDE {
        return Err(format!(
            "jump map: exemplar must be 1..={MAX_EXEMPLAR_SIDE} pixels on each side, got {width}×{height}"
        ));
    }
    Ok(())
}

/// A jump map: `k` slots per exemplar pixel, row-major, best jump first, unused slots (weight
/// 0) last.
#[derive(Clone, Debug, PartialEq)]
pub struct JumpMap {
    pub width: u32,
    pub height: u32,
    pub k: u32,
    pub jumps: Vec<Jump>,
}

/// A borrowed jump map, e.g. viewed in place in a mapped artifact.
#[derive(Clone, Copy, Debug)]
pub struct JumpMapRef<'a> {
    pub width: u32,
    pub height: u32,
    pub k: u32,
    pub jumps: &'a [Jump],
}

impl JumpMap {
    pub fn as_ref(&self) -> JumpMapRef<'_> {
        JumpMapRef {
            width: self.width,
            height: self.height,
            k: self.k,
            jumps: &self.jumps,
        }
    }

    /// The used jumps of pixel `(x, y)`, best first.
    pub fn jumps_at(&self, x: u32, y: u32) -> &[Jump] {
        self.as_ref().jumps_at(x, y)
    }
}

impl<'a> JumpMapRef<'a> {
    /// Checks sizes and contents of data from outside (an artifact): the slot count matches,
    /// every used jump lies inside the exemplar, weights are finite and non-negative.
    pub fn new(width: u32, height: u32, k: u32, jumps: &'a [Jump]) -> Result<Self, String> {
        check_exemplar_size(width, height)?;
        let want = width as u64 * height as u64 * k as u64;
        if jumps.len() as u64 != want {
            return Err(format!(
                "jump map: {width}×{height} with {k} jumps per pixel needs {want} slots, got {}",
                jumps.len()
            ));
        }
        if let Some(i) = jumps.iter().position(|j| {
            !(j.weight.is_finite() && j.weight >= 0.0)
                || (j.weight > 0.0 && (j.x as u32 >= width || j.y as u32 >= height))
        }) {
            return Err(format!(
                "jump map: slot {i} is not a valid jump: {:?}",
                jumps[i]
            ));
        }
        Ok(JumpMapRef {
            width,
            height,
            k,
            jumps,
        })
    }

    /// The used jumps of pixel `(x, y)` (those with weight > 0), best first.
    #[inline]
    pub fn jumps_at(&self, x: u32, y: u32) -> &'a [Jump] {
        let k = self.k as usize;
        let i = (y as usize * self.width as usize + x as usize) * k;
        let slots = &self.jumps[i..i + k];
        let used = slots.iter().take_while(|j| j.weight > 0.0).count();
        &slots[..used]
    }
}

/// Builds the jump map of `img` (see the module docs). `progress` is called from the calling
/// thread with the fraction done, from 0 to 1.
///
/// Panics if a side of `img` exceeds [`MAX_EXEMPLAR_SIDE`] (see [`check_exemplar_size`]) or if
pub fn build_jump_map(_img: ImageView, _params: &JumpMapParams, _progress: &dyn Fn(f32)) -> JumpMap { unimplemented!("stub in engine worktree") }
