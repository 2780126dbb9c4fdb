//! The field smoothed for coarse levels (Zhang, Du, Lai, Ni & Hu, "Sketch guided solid
//! texturing", §6): "in coarser levels, the field is further smoothed and downsampled to
//! reduce discontinuity".
//!
//! A coarse level's voxel spans several field nodes; the field's variation below that size
//! cannot be followed by the level's neighbourhoods, and sampled at the level's voxels it shows
//! up as jumps of the frame from voxel to voxel, which the level's corrections turn into
//! seams. The field is therefore smoothed with a Gaussian of σ proportional to the level's
//! voxel side (`synthesize.field_smoothing` voxels): passes of the binomial `[1 2 1] / 4`
//! along each grid axis (each pass adds a variance of ½ node², so `⌈2 σ² / spacing²⌉` passes),
//! on the quaternions — each neighbour brought to the centre's hemisphere first (`q` and `−q`
//! are one rotation), renormalized after every pass — and on the scales. Borders repeat their
//! node. The smoothed field stays on the field's own grid: the paper also downsamples it,
//! which saves memory but adds nothing the smoothing does not already remove.

use super::quaternion_field::RotationField;
use glam::DQuat;

/// Largest number of filter passes (σ of 10 nodes): beyond it the field is as good as its
/// mean over the grid.
const MAX_PASSES: usize = 200;

/// `field` smoothed by a Gaussian of standard deviation `sigma` (object units). A constant
/// field, or `sigma` below half a node spacing, comes back unchanged.
pub fn smooth_field(field: &RotationField, sigma: f32) -> RotationField {
    let spacing = field.grid.spacing as f64;
    let passes =
        ((2.0 * (sigma as f64).powi(2) / (spacing * spacing)).ceil() as usize).min(MAX_PASSES);
    let mut out = field.clone();
    if passes == 0 || sigma < 0.5 * field.grid.spacing {
        return out;
    }
    let d = field.grid.dims.map(|x| x as usize);
    let index = |i: usize, j: usize, k: usize| (k * d[1] + j) * d[0] + i;
    let mut q: Vec<DQuat> = field.rotations.iter().map(|r| r.as_dquat()).collect();
    let mut s: Vec<f64> = field.scales.iter().map(|&x| x as f64).collect();
    for _ in 0..passes {
        for axis in 0..3 {
            let (q0, s0) = (q.clone(), s.clone());
            for k in 0..d[2] {
                for j in 0..d[1] {
                    for i in 0..d[0] {
                        let c = [i, j, k];
                        let mut lo = c;
                        let mut hi = c;
                        lo[axis] = c[axis].saturating_sub(1);
                        hi[axis] = (c[axis] + 1).min(d[axis] - 1);
                        let (n, a, b) = (
                            index(i, j, k),
                            index(lo[0], lo[1], lo[2]),
                            index(hi[0], hi[1], hi[2]),
                        );
                        let centre = q0[n];
                        let align = |x: DQuat| if x.dot(centre) < 0.0 { -x } else { x };
                        let sum = align(q0[a]) + centre * 2.0 + align(q0[b]);
                        q[n] = if sum.length_squared() > 1e-24 {
                            sum.normalize()
                        } else {
                            centre
                        };
                        s[n] = 0.25 * (s0[a] + 2.0 * s0[n] + s0[b]);
                    }
                }
            }
        }
    }
    out.rotations = q.iter().map(|x| x.as_quat()).collect();
    out.scales = s.iter().map(|&x| x as f32).collect();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::quaternion_field::FieldGrid;
    use glam::{Quat, Vec3};

    fn grid() -> FieldGrid {
        FieldGrid::covering(Vec3::ZERO, Vec3::splat(16.0), 16)
    }

    /// Rotations about z by an angle that jumps by `jump` radians between alternate nodes
    /// along x on top of a smooth ramp: a noisy field.
    fn noisy(jump: f32) -> RotationField {
        let mut f = RotationField::trivial(grid());
        let d = f.grid.dims;
        for k in 0..d[2] {
            for j in 0..d[1] {
                for i in 0..d[0] {
                    let n = ((k * d[1] + j) * d[0] + i) as usize;
                    let a = 0.05 * i as f32 + if (i + j) % 2 == 0 { jump } else { -jump };
                    f.rotations[n] = Quat::from_rotation_z(a);
                }
            }
        }
        f
    }

    /// Mean angle between the rotations of neighbouring nodes along x.
    fn roughness(f: &RotationField) -> f64 {
        let d = f.grid.dims.map(|x| x as usize);
        let mut sum = 0.0;
        let mut n = 0;
        for k in 0..d[2] {
            for j in 0..d[1] {
                for i in 0..d[0] - 1 {
                    let a = f.rotations[(k * d[1] + j) * d[0] + i];
                    let b = f.rotations[(k * d[1] + j) * d[0] + i + 1];
                    sum += a.angle_between(b) as f64;
                    n += 1;
                }
            }
        }
        sum / n as f64
    }

    #[test]
    fn smoothing_removes_jumps_but_keeps_the_trend() {
        let f = noisy(0.3);
        let g = smooth_field(&f, 2.0);
        assert!(
            roughness(&g) < 0.3 * roughness(&f),
            "{} vs {}",
            roughness(&g),
            roughness(&f)
        );
        // Unit quaternions, and the ramp (0.05 rad per node) survives in the middle.
        assert!(g.rotations.iter().all(|q| (q.length() - 1.0).abs() < 1e-5));
        let mid = |f: &RotationField, i: u32| {
            let d = f.grid.dims;
            f.rotations[((8 * d[1] + 8) * d[0] + i) as usize]
        };
        let turn = mid(&g, 6).angle_between(mid(&g, 10));
        assert!((turn - 0.2).abs() < 0.05, "{turn}");
    }

    #[test]
    fn a_smooth_field_and_a_small_sigma_are_left_alone() {
        let f = noisy(0.0);
        assert_eq!(smooth_field(&f, 0.4), f);
        let g = smooth_field(&f, 2.0);
        let worst = f
            .rotations
            .iter()
            .zip(&g.rotations)
            .skip(8)
            .map(|(a, b)| a.angle_between(*b))
            .fold(0.0f32, f32::max);
        // A linear ramp is kept by a symmetric filter away from the borders; at the borders
        // it bends by at most a few steps of the ramp.
        assert!(worst < 0.15, "{worst}");
    }
}
