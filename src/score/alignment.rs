//! How well a texture's lines follow the direction they should take: the angle between the
//! local dominant direction of an image (its structure tensor) and an expected direction.
//!
//! Feature-aligned texturing (Xu et al. 2009, §4–5) lays the exemplar's principal feature line
//! along the field, so a correct result's lines run along the field, as the exemplar's run at
//! its principal angle. The structure tensor (the window sum of `∇I ∇Iᵀ` over luminance) gives each window's
//! dominant gradient direction; lines run across it. Windows without a dominant direction
//! (coherence `(λ₁ − λ₂) / (λ₁ + λ₂)` below 0.3: flat or isotropic content) say nothing
//! about alignment and are left out. The median over the rest is the measure, in degrees,
//! 0 (every line along the direction) to 90 (every line across it).
//!
//! On a surface ([`surface_alignment`]) the same measure is taken where the texture lies,
//! without unfolding: windows are the triangles around the vertices within a radius of
//! every k-th vertex (at most 4,000 windows),
//! the tensor sums each triangle's luminance gradient (area-weighted) in the centre's tangent
//! frame, and the expected direction is the field at the centre. Unfolded discs would
//! measure the unfolding too: a disc is laid out in one frame, and where the field turns
//! inside it (a few degrees per texel on an elephant's crest-line field) a correct texture
//! turns with the field and away from the disc's one expected direction. The exemplar's own
//! measure ([`alignment`] on its pixels, 9-pixel windows) is the floor: a brick wall's head
//! joints or a basket weave's crossing boards cross the principal line in the exemplar too.

use crate::geom::Mesh;
use crate::image::ImageView;
use glam::Vec3;
use texsyn_core::math::PureMath;

/// Side of the square windows the tensor sums over, in pixels.
pub const WINDOW: usize = 9;
/// Windows whose coherence is below this are isotropic and not counted.
const MIN_COHERENCE: f32 = 0.3;

/// The alignment of an image's lines with a direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alignment {
    /// Median angle between the windows' line directions and the expected one, degrees.
    pub median_degrees: f32,
    /// Windows counted (coherent; in an image, wholly inside the mask; on a surface, with at
    /// least half a flat disc's area).
    pub windows: usize,
}

/// The alignment of `image`'s lines with `direction` (radians, in pixel axes: x right, y
/// down), over the windows wholly inside `mask` (row-major, one flag per pixel; `None`: all).
/// `None` when no window is coherent.
pub fn alignment(image: ImageView, mask: Option<&[bool]>, direction: f32) -> Option<Alignment> {
    let (w, h) = (image.width as usize, image.height as usize);
    if w < WINDOW + 2 || h < WINDOW + 2 {
        return None;
    }
    let luma = |x: usize, y: usize| {
        let c = image.get(x as u32, y as u32);
        0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2]
    };
    let inside = |x: usize, y: usize| mask.is_none_or(|m| m[y * w + x]);
    let mut angles = Vec::new();
    for y0 in (1..h - WINDOW).step_by(WINDOW) {
        for x0 in (1..w - WINDOW).step_by(WINDOW) {
            let (mut jxx, mut jxy, mut jyy) = (0.0f32, 0.0f32, 0.0f32);
            let mut whole = true;
            for y in y0..y0 + WINDOW {
                for x in x0..x0 + WINDOW {
                    let neighbours = [(x, y), (x - 1, y), (x + 1, y), (x, y - 1), (x, y + 1)];
                    if !neighbours.iter().all(|&(x, y)| inside(x, y)) {
                        whole = false;
                        continue;
                    }
                    let gx = 0.5 * (luma(x + 1, y) - luma(x - 1, y));
                    let gy = 0.5 * (luma(x, y + 1) - luma(x, y - 1));
                    jxx += gx * gx;
                    jxy += gx * gy;
                    jyy += gy * gy;
                }
            }
            let trace = jxx + jyy;
            if !whole || trace <= 1e-12 {
                continue;
            }
            let spread = ((jxx - jyy) * (jxx - jyy) + 4.0 * jxy * jxy).sqrt();
            if spread / trace < MIN_COHERENCE {
                continue;
            }
            // The dominant gradient's direction; lines run at a right angle to it.
            let gradient = 0.5 * (2.0 * jxy).atan2_pure(jxx - jyy);
            let line = gradient + std::f32::consts::FRAC_PI_2;
            angles.push(line_angle(line, direction).to_degrees());
        }
    }
    median_of(angles)
}

/// Window centres on a surface: at most this many, every k-th vertex.
const SURFACE_WINDOWS: usize = 4000;

/// The alignment of a textured surface's lines with a tangent field: over windows around
/// every k-th vertex (at most [`SURFACE_WINDOWS`]), the triangles around the vertices reached
/// from it by edges within `radius` (object units; [`WINDOW`] / 2 texels matches the
/// exemplar's windows), each triangle's luminance gradient (linear over the
/// triangle from `luma` at its corners) summed into a structure tensor in the centre's
/// tangent frame, whose line direction is compared with `direction[centre]`, the tangent the
/// principal line should take there. Triangles facing away from the centre's normal (the far
/// side of a thin part) are left out, and so are windows with less than half a flat disc's
/// area (mesh borders), flat, without a dominant direction (coherence below [`MIN_COHERENCE`]), or
/// whose centre has no direction (zero vector). `None` when no window is counted.
pub fn surface_alignment(
    mesh: &Mesh,
    luma: &[f32],
    direction: &[Vec3],
    radius: f32,
) -> Option<Alignment> {
    let n = mesh.positions.len();
    if luma.len() != n || direction.len() != n || radius.is_nan() || radius <= 0.0 {
        return None;
    }
    let normals = mesh.vertex_normals();
    // Per triangle: the luminance gradient (a vector in its plane), its area and unit normal.
    let faces: Vec<(Vec3, f32, Vec3)> = mesh
        .triangles
        .iter()
        .map(|t| {
            let p = t.map(|v| mesh.positions[v as usize]);
            let cross = (p[1] - p[0]).cross(p[2] - p[0]);
            let twice = cross.length();
            if twice.is_nan() || twice <= 0.0 {
                return (Vec3::ZERO, 0.0, Vec3::ZERO);
            }
            let nrm = cross / twice;
            // ∇ of corner i's hat function is n × (the opposite edge) / twice the area; the
            // hat functions sum to one, so corner 0's value drops out and a flat triangle's
            // gradient is exactly zero.
            let l = t.map(|v| luma[v as usize]);
            let hat = |i: usize| nrm.cross(p[(i + 2) % 3] - p[(i + 1) % 3]) / twice;
            let g = hat(1) * (l[1] - l[0]) + hat(2) * (l[2] - l[0]);
            (g, 0.5 * twice, nrm)
        })
        .collect();
    let faces_of = mesh.vertex_faces();
    let min_area = 0.5 * std::f32::consts::PI * radius * radius;
    let mut seen = vec![usize::MAX; n];
    let mut counted = vec![usize::MAX; mesh.triangles.len()];
    let mut angles = Vec::new();
    for centre in (0..n).step_by(n.div_ceil(SURFACE_WINDOWS).max(1)) {
        let (c, nc) = (mesh.positions[centre], normals[centre]);
        let u = direction[centre] - nc * direction[centre].dot(nc);
        let Some(u) = u.try_normalize() else { continue };
        let v = nc.cross(u);
        // The window: triangles around the vertices reached from the centre within `radius`.
        let (mut juu, mut juv, mut jvv, mut area) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        let mut stack = vec![centre];
        seen[centre] = centre;
        while let Some(x) = stack.pop() {
            for &f in faces_of.row(x) {
                let f = f as usize;
                if counted[f] == centre {
                    continue;
                }
                counted[f] = centre;
                let (g, a, nf) = faces[f];
                if nf.dot(nc) > 0.0 {
                    let (gu, gv) = (g.dot(u), g.dot(v));
                    juu += a * gu * gu;
                    juv += a * gu * gv;
                    jvv += a * gv * gv;
                    area += a;
                }
                for &w in &mesh.triangles[f] {
                    let w = w as usize;
                    if seen[w] != centre && mesh.positions[w].distance(c) <= radius {
                        seen[w] = centre;
                        stack.push(w);
                    }
                }
            }
        }
        // Flat windows (mean squared luminance change across the radius below 10⁻⁸, far
        // under one 8-bit level) have no direction.
        let trace = juu + jvv;
        if area < min_area || !trace.is_finite() || trace * radius * radius <= 1e-8 * area {
            continue;
        }
        let spread = ((juu - jvv) * (juu - jvv) + 4.0 * juv * juv).sqrt();
        if spread.is_nan() || spread / trace < MIN_COHERENCE {
            continue;
        }
        let gradient = 0.5 * (2.0 * juv).atan2_pure(juu - jvv);
        let line = gradient + std::f32::consts::FRAC_PI_2;
        // The expected direction is the frame's first axis: angle 0.
        angles.push(line_angle(line, 0.0).to_degrees());
    }
    median_of(angles)
}

/// The median of the windows' angles (degrees), `None` without any.
fn median_of(mut angles: Vec<f32>) -> Option<Alignment> {
    if angles.is_empty() {
        return None;
    }
    let mid = angles.len() / 2;
    let median = *angles.select_nth_unstable_by(mid, f32::total_cmp).1;
    Some(Alignment {
        median_degrees: median,
        windows: angles.len(),
    })
}

/// The angle between two undirected lines, radians in [0, π/2].
fn line_angle(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(std::f32::consts::PI);
    d.min(std::f32::consts::PI - d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;

    /// Stripes 6 pixels apart whose lines run at `angle` (radians, x right, y down).
    fn stripes(angle: f32) -> Image {
        let (s, c) = (angle.sin_pure(), angle.cos_pure());
        Image::from_fn(96, 96, |x, y| {
            // Distance across the lines: along their normal (−s, c).
            let across = -(x as f32) * s + y as f32 * c;
            let v = 0.5 + 0.4 * (across * std::f32::consts::TAU / 6.0).sin_pure();
            [v, v, v, 1.0]
        })
    }

    #[test]
    fn lines_along_the_direction_measure_zero_and_across_it_ninety() {
        for degrees in [0.0f32, 30.0, 90.0, 135.0] {
            let a = degrees.to_radians();
            let img = stripes(a);
            let along = alignment(img.view(), None, a).unwrap();
            assert!(along.median_degrees < 3.0, "{degrees}°: {along:?}");
            let across = alignment(img.view(), None, a + std::f32::consts::FRAC_PI_2).unwrap();
            assert!(across.median_degrees > 87.0, "{degrees}°: {across:?}");
            let tilted = alignment(img.view(), None, a + 0.5).unwrap();
            let want = 0.5f32.to_degrees();
            assert!(
                (tilted.median_degrees - want).abs() < 3.0,
                "{degrees}°: {tilted:?}"
            );
        }
    }

    /// A flat sheet (spacing 0.25) whose luminance has stripes 6 units apart with lines at
    /// `angle` (radians from x), measured against a field along x.
    fn striped_sheet(angle: f32) -> Option<Alignment> {
        let mesh = crate::geom::primitives::grid(121, 0.25);
        let (s, c) = (angle.sin_pure(), angle.cos_pure());
        let luma: Vec<f32> = (mesh.positions.iter())
            .map(|p| 0.5 + 0.4 * ((-p.x * s + p.y * c) * std::f32::consts::TAU / 6.0).sin_pure())
            .collect();
        let field = vec![Vec3::X; mesh.positions.len()];
        surface_alignment(&mesh, &luma, &field, 4.5)
    }

    #[test]
    fn on_a_sheet_the_surface_measure_is_the_angle_between_stripes_and_field() {
        for degrees in [0.0f32, 25.0, 60.0, 90.0, 150.0] {
            let a = striped_sheet(degrees.to_radians()).unwrap();
            let want = if degrees > 90.0 {
                180.0 - degrees
            } else {
                degrees
            };
            assert!((a.median_degrees - want).abs() < 3.0, "{degrees}°: {a:?}");
            assert!(a.windows > 100, "{a:?}");
        }
    }

    #[test]
    fn on_a_torus_stripes_are_measured_against_the_local_field() {
        // Stripes around the tube (lines along the tube's circle, b), 24 around the ring: they
        // follow a field along b and cross a field along the ring (a), wherever the tangent
        // planes turn.
        let (n, m) = (480u32, 120u32);
        let mesh = crate::geom::primitives::torus(n, m, 0.5);
        let angle = |p: Vec3| p.y.atan2_pure(p.x);
        let luma: Vec<f32> = (mesh.positions.iter())
            .map(|&p| 0.5 + 0.4 * (angle(p) * 24.0).sin_pure())
            .collect();
        let along_ring: Vec<Vec3> = (mesh.positions.iter())
            .map(|p| Vec3::new(-p.y, p.x, 0.0).normalize())
            .collect();
        let along_tube: Vec<Vec3> = (mesh.positions.iter().zip(&along_ring))
            .map(|(&p, &t)| {
                let centre = Vec3::new(p.x, p.y, 0.0).normalize() * 2.0;
                (p - centre).cross(t).normalize()
            })
            .collect();
        // Stripe period 2π·(2 ± 0.5)/24 ≈ 0.4–0.65; windows of radius 0.3.
        let follows = surface_alignment(&mesh, &luma, &along_tube, 0.3).unwrap();
        let crosses = surface_alignment(&mesh, &luma, &along_ring, 0.3).unwrap();
        assert!(follows.median_degrees < 5.0, "{follows:?}");
        assert!(crosses.median_degrees > 85.0, "{crosses:?}");
    }

    #[test]
    fn surface_windows_without_lines_or_direction_are_not_counted() {
        // A grid turned and spaced so that its coordinates are not exact in binary: a flat
        // colour's gradient must still be zero.
        let mut mesh = crate::geom::primitives::grid(41, 0.1);
        let turn = glam::Quat::from_rotation_z(0.3);
        mesh.positions.iter_mut().for_each(|p| *p = turn * *p * 2.5);
        let flat = vec![0.7; mesh.positions.len()];
        let field = vec![Vec3::X; mesh.positions.len()];
        assert_eq!(surface_alignment(&mesh, &flat, &field, 2.0), None);
        let stripes: Vec<f32> = mesh
            .positions
            .iter()
            .map(|p| (p.y * 2.0).sin_pure())
            .collect();
        let none = vec![Vec3::ZERO; mesh.positions.len()];
        assert_eq!(surface_alignment(&mesh, &stripes, &none, 2.0), None);
        // A field normal to the sheet has no tangent direction either.
        let normal = vec![Vec3::Z; mesh.positions.len()];
        assert_eq!(surface_alignment(&mesh, &stripes, &normal, 2.0), None);
        assert!(surface_alignment(&mesh, &stripes, &field, 2.0).is_some());
    }

    #[test]
    fn flat_images_and_masked_out_windows_are_not_counted() {
        let flat = Image::from_fn(64, 64, |_, _| [0.5, 0.5, 0.5, 1.0]);
        assert_eq!(alignment(flat.view(), None, 0.0), None);
        let img = stripes(0.0);
        let none = vec![false; 96 * 96];
        assert_eq!(alignment(img.view(), Some(&none), 0.0), None);
        let mut half = vec![false; 96 * 96];
        half[..48 * 96].iter_mut().for_each(|m| *m = true);
        let some = alignment(img.view(), Some(&half), 0.0).unwrap();
        let all = alignment(img.view(), None, 0.0).unwrap();
        assert!(
            some.windows > 0 && some.windows < all.windows,
            "{some:?} {all:?}"
        );
    }
}
