//! Neighbourhoods sampled along the field at coarse levels (Zhang, Du, Lai, Ni & Hu, "Sketch
//! guided solid texturing", §4.3): "For fine levels, the tensor field at the center voxel is
//! used to sample the local neighborhood. For coarse levels, a numerical integration along the
//! directions is used instead to improve the sampling accuracy, similar in spirit to the
//! surface case in [Kwatra et al. 2007, Texturing fluids]".
//!
//! At a coarse level one voxel spans many finest voxels, and an `N × N` neighbourhood a good
//! part of the volume: the centre's frame, held straight over it, leaves a curved field's
//! layers (a neighbourhood of bent wood grain is compared with a straight exemplar patch cut
//! across the grain at its ends). Here the plane-`P` neighbourhood's sample `(i, j)` is reached
//! by walking from the voxel `|j|` steps along the frame's axis `P + 1` (image y), then `|i|`
//! steps along axis `P` (image x), each step one sample spacing `s` long in the direction the
//! field has *where the walk is* — Kwatra et al. build their surface neighbourhoods the same
//! way, walking along the local tangent directions. Steps are explicit midpoint (RK2): the
//! frame at the step's start moves half a step, and the frame there makes the step.
//!
//! The walk's order (rows along image y first, then each row along image x) is a choice: the
//! paper does not give one. Along a constant field every step is the same vector and the
//! samples are the centre-frame samples; the synthesis then keeps the straight gather (the
//! same positions without rounding differences). A walk of `|i| + |j|` steps of at most
//! `s_max` reaches at most `2 N_h s_max` voxels per axis, which is what the dependency stencil
//! allows for (`widen_for_integration` in `solid_synthesis/plan.rs`); positions are clamped to it.

use glam::{Mat3, Vec3};

/// The `N × N` (`N = 2 nh + 1`) sample positions of plane `plane`'s neighbourhood of the point
/// `v` (voxel coordinates of the level), row-major (`j` along image y, then `i` along image
/// x), into `out`. `frame(x)` is the scaled frame at `x`: its column `k` is the field's axis
/// `k` times the scale, in voxels of the level. Every position lies within `bound` of `v`
/// per axis.
pub fn integrated_neighbourhood(
    frame: impl Fn(Vec3) -> Mat3,
    v: Vec3,
    plane: usize,
    nh: i32,
    bound: f32,
    out: &mut Vec<Vec3>,
) {
    let (a1, a2) = (plane, (plane + 1) % 3);
    let n = (2 * nh + 1) as usize;
    let step = |x: Vec3, axis: usize, sign: f32| {
        let half = x + frame(x).col(axis) * (0.5 * sign);
        x + frame(half).col(axis) * sign
    };
    let (lo, hi) = (v - bound, v + bound);
    out.clear();
    out.resize(n * n, v);
    // Row starts along axis a2, both ways from v.
    let mut starts = vec![v; n];
    for sign in [1.0f32, -1.0] {
        let mut x = v;
        for k in 1..=nh {
            x = step(x, a2, sign);
            starts[(nh + sign as i32 * k) as usize] = x;
        }
    }
    for (r, &start) in starts.iter().enumerate() {
        let row = &mut out[r * n..(r + 1) * n];
        row[nh as usize] = start;
        for sign in [1.0f32, -1.0] {
            let mut x = start;
            for k in 1..=nh {
                x = step(x, a1, sign);
                row[(nh + sign as i32 * k) as usize] = x;
            }
        }
        for x in row.iter_mut() {
            *x = x.clamp(lo, hi);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;
    use texsyn_core::math::PureMath;

    /// A field whose x axis runs around circles about the z axis through `c` (a vortex), unit
    /// scale: the frame at `x` is the rotation about z by the polar angle + 90°.
    fn vortex(c: Vec3) -> impl Fn(Vec3) -> Mat3 {
        move |x: Vec3| {
            let d = x - c;
            let t = Vec3::new(-d.y, d.x, 0.0).normalize_or(Vec3::X);
            Mat3::from_cols(t, Vec3::Z.cross(t), Vec3::Z)
        }
    }

    #[test]
    fn samples_follow_the_field_lines_where_the_centre_frame_leaves_them() {
        let c = Vec3::new(0.0, 0.0, 0.0);
        let v = Vec3::new(6.0, 0.0, 0.0); // radius 6, the x axis points along +y here
        let frame = vortex(c);
        let mut out = Vec::new();
        integrated_neighbourhood(&frame, v, 0, 4, 100.0, &mut out);
        // The centre row (j = 0) walks along the circle of radius 6.
        let mid = &out[4 * 9..5 * 9];
        let f0 = frame(v);
        let mut worst_integrated = 0.0f32;
        let mut worst_straight = 0.0f32;
        for (k, x) in mid.iter().enumerate() {
            let i = k as f32 - 4.0;
            worst_integrated = worst_integrated.max((x.length() - 6.0).abs());
            let straight = v + f0.col(0) * i;
            worst_straight = worst_straight.max((straight.length() - 6.0).abs());
            // Arc length i from the centre (unit steps, up to the midpoint rule's error).
            let arc = x.y.atan2_pure(x.x) * 6.0;
            assert!((arc - i).abs() < 0.05, "sample {i}: arc {arc}");
        }
        assert!(worst_straight > 1.0, "{worst_straight}");
        assert!(worst_integrated < 0.02, "{worst_integrated}");
    }

    #[test]
    fn a_constant_frame_gives_the_straight_samples_and_bound_clamps() {
        let m = Mat3::from_quat(Quat::from_rotation_z(0.3) * Quat::from_rotation_x(0.5)) * 1.5;
        let v = Vec3::new(1.0, 2.0, 3.0);
        let mut out = Vec::new();
        integrated_neighbourhood(|_| m, v, 1, 3, 100.0, &mut out);
        for j in -3..=3 {
            for i in -3..=3 {
                let want = v + m.col(2) * j as f32 + m.col(1) * i as f32;
                let got = out[((j + 3) * 7 + i + 3) as usize];
                assert!((got - want).length() < 1e-4, "{got} vs {want}");
            }
        }
        integrated_neighbourhood(|_| m, v, 1, 3, 2.0, &mut out);
        assert!(out.iter().all(|x| (*x - v).abs().max_element() <= 2.0));
    }
}
