//! The per-sample controls synthesis matches each texel with: orientation and scale indices
//! from the field (§4.3), the surface metric, and the maps from grid offsets to sample offsets
//! they lay the texture out with.

use super::ParamField;
use super::params::{GeometrySynthParams, ScaleChoice};
use crate::analyse_exemplar::texel_variants::{TexelVariantParams, TexelVariantsRef};
use crate::field::param_field::local_spacing;
use crate::geom::geometry_image::GeometryImage;
use crate::synthesize::surface_metric::{SurfaceMetric, surface_metrics_clamped};
use glam::Vec2;
use texsyn_core::math::PureMath;

/// `(cos θ, sin θ)` of the rotation taking the sample's up `(0, 1)` to `dir`.
#[inline]
pub(super) fn dir_rotation(dir: Vec2) -> (f32, f32) {
    let d = dir.normalize_or_zero();
    if d == Vec2::ZERO {
        (1.0, 0.0)
    } else {
        (d.y, -d.x)
    }
}

/// The level-0 controls of each sample (`i * n + j`), as synthesis reads them.
pub struct TexelControls {
    /// The surface metric ([`SurfaceMetric`]); empty without `anisotropic`.
    pub metric: Vec<SurfaceMetric>,
    /// Fractional orientation index in `[0, orientations)`: the variant angle is
    /// `orient · 360° / orientations`.
    pub orient: Vec<f32>,
    /// Fractional scale index in `[0, scales − 1]` (0 = most enlarged).
    pub scale: Vec<f32>,
}

/// The per-sample orientation, scale and metric that [`synthesize_geometry_texture`] matches
/// each texel with (§4.3; with the surface metric, see the module docs).
///
/// [`synthesize_geometry_texture`]: super::synthesize_geometry_texture
pub fn texel_controls(
    gi: &GeometryImage,
    field: &ParamField,
    vp: &TexelVariantParams,
    p: &GeometrySynthParams,
) -> TexelControls {
    let anisotropic = p.anisotropic;
    let kk = vp.orientations as usize;
    let ss = vp.scales as usize;
    let mid = vp.middle_scale();
    // Per-sample controls at level 0. With the surface metric, the field's direction (grid
    // axes) is turned into the sample axes by A, and R takes the metric's isotropic spacing in
    // place of the mean neighbour distance (which the longer grid direction dominates).
    let metric0 = if anisotropic {
        surface_metrics_clamped(gi, p.max_stretch as f64)
    } else {
        Vec::new()
    };
    let spacing = if anisotropic {
        local_spacing(gi)
    } else {
        Vec::new()
    };
    let tau = std::f64::consts::TAU;
    let orient0: Vec<f32> = field
        .dir
        .iter()
        .enumerate()
        .map(|(k, &d)| {
            let d = match metric0.get(k) {
                Some(m) if d != Vec2::ZERO => m.to_sample(d),
                _ => d,
            };
            let (cos, sin) = dir_rotation(d);
            let theta = (sin as f64).atan2_pure(cos as f64);
            let f = (theta / (tau / kk as f64)).rem_euclid(kk as f64);
            if f >= kk as f64 { 0.0 } else { f as f32 }
        })
        .collect();
    // R = S / S̄ · 2^offset becomes g / ḡ · 2^offset (means over the samples where both are
    // known), so the texture's density over the whole image stays where the field put it.
    let (sum_s, sum_g) = metric0
        .iter()
        .zip(&spacing)
        .filter(|(m, s)| m.spacing > 0.0 && **s > 0.0)
        .fold((0.0f64, 0.0f64), |(a, b), (m, s)| {
            (a + *s as f64, b + m.spacing as f64)
        });
    let mean_ratio = if sum_g > 0.0 {
        (sum_s / sum_g) as f32
    } else {
        1.0
    };
    let scale0: Vec<f32> = field
        .rel_scale
        .iter()
        .enumerate()
        .map(|(k, &r)| {
            let r = match (metric0.get(k), spacing.get(k)) {
                (Some(m), Some(&s)) if m.spacing > 0.0 && s > 0.0 => r * m.spacing / s * mean_ratio,
                _ => r,
            };
            let s = (r.log2_pure() + mid as f32).clamp(0.0, (ss - 1) as f32);
            match p.scale_choice {
                ScaleChoice::Random => s,
                // A whole index: the choice then takes that scale with probability 1.
                ScaleChoice::Nearest => (s + 0.5).floor(),
            }
        })
        .collect();

    TexelControls {
        metric: metric0,
        orient: orient0,
        scale: scale0,
    }
}

/// Per level-0 sample, the linear map `M` (row-major, acting on `(x = column, y = row)`) from
/// grid offsets to offsets in the sample's own texels (level 0, unrotated) that synthesis lays
/// the texture out with there: `M = f · R(−θ) · A`, with `A` the surface metric (the identity
/// without it), `θ` the field's angle as a continuous orientation index and `f` the variants'
/// texel size in sample texels at the continuous scale index (geometric between the two scales
/// the synthesis mixes). A synthesized neighbour `o` grid steps away copies, in coherent runs,
/// the sample point `M o` away from the texel's; this is what the surface-space score reads
/// the relief along.
pub fn sample_frame_maps(
    controls: &TexelControls,
    variants: &TexelVariantsRef<'_>,
) -> Vec<[f32; 4]> {
    let vp = variants.params();
    let kk = vp.orientations as f64;
    let ss = vp.scales as usize;
    // Texel size of scale s's variants in sample texels (orientation 0: a pure scaling).
    let log_size: Vec<f64> = (0..ss)
        .map(|s| variants.sample_map(variants.variant(s, 0), 0).a[0][0].log2_pure())
        .collect();
    controls
        .orient
        .iter()
        .zip(&controls.scale)
        .enumerate()
        .map(|(k, (&o, &s))| {
            let s = s as f64;
            let s0 = (s.floor() as usize).min(ss - 1);
            let t = s - s0 as f64;
            let ls = if s0 + 1 < ss {
                (1.0 - t) * log_size[s0] + t * log_size[s0 + 1]
            } else {
                log_size[s0]
            };
            let f = ls.exp2_pure();
            let theta = std::f64::consts::TAU * o as f64 / kk;
            let (sin, cos) = (theta.sin_pure(), theta.cos_pure());
            // f R(−θ) = f [[cos, sin], [−sin, cos]], as the variants' sample maps.
            let r = [f * cos, f * sin, -f * sin, f * cos];
            let a = controls
                .metric
                .get(k)
                .map_or([1.0f64, 0.0, 0.0, 1.0], |m| m.a.map(|v| v as f64));
            [
                r[0] * a[0] + r[1] * a[2],
                r[0] * a[1] + r[1] * a[3],
                r[2] * a[0] + r[3] * a[2],
                r[2] * a[1] + r[3] * a[3],
            ]
            .map(|v| v as f32)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::geometry_image::TexelImage;
    use crate::random::counter_unit;

    #[test]
    fn sample_frame_maps_are_the_variants_maps_times_the_metric() {
        use crate::analyse_exemplar::texel_variants::{TexelVariantParams, build_texel_variants};
        let mut sample = TexelImage::new(40, 40, 3);
        for (k, v) in sample.data.iter_mut().enumerate() {
            *v = counter_unit(3, 0, k as u64);
        }
        let vp = TexelVariantParams {
            orientations: 4,
            ..Default::default()
        };
        let owned = build_texel_variants(&sample, &vp, &|_| {}).unwrap();
        let vr = owned.as_ref();
        let stretched = SurfaceMetric::from_metric(9.0, 0.0, 1.0);
        let controls = TexelControls {
            metric: vec![SurfaceMetric::IDENTITY, SurfaceMetric::IDENTITY, stretched],
            orient: vec![0.0, 1.0, 0.0],
            scale: vec![1.0, 2.0, 1.5],
        };
        let maps = sample_frame_maps(&controls, &vr);
        let close =
            |a: [f32; 4], b: [f64; 4]| a.iter().zip(b).all(|(&x, y)| (x as f64 - y).abs() < 1e-5);
        // The middle scale unrotated: the sample's own texels.
        assert!(close(maps[0], [1.0, 0.0, 0.0, 1.0]), "{:?}", maps[0]);
        // Orientation 1 of 4 at the coarser scale: the variant's own sample map.
        let a = vr.sample_map(vr.variant(2, 1), 0).a;
        assert!(
            close(maps[1], [a[0][0], a[0][1], a[1][0], a[1][1]]),
            "{:?} against {a:?}",
            maps[1]
        );
        assert!(close(maps[1], [0.0, 2.0, -2.0, 0.0]), "{:?}", maps[1]);
        // Halfway between two scales a factor √2, times the metric's A: a grid step along x
        // covers 3 times the surface of one along y, so A = diag(√3, 1/√3).
        let (r2, r3) = (std::f64::consts::SQRT_2, 3f64.sqrt());
        assert!(
            close(maps[2], [r2 * r3, 0.0, 0.0, r2 / r3]),
            "{:?}",
            maps[2]
        );
    }
}
