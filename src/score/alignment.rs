//! How well a texture's lines follow the direction they should take: the angle between the
//! local dominant direction of an image (its structure tensor) and an expected direction.
//!
//! Feature-aligned texturing (Xu et al. 2009, §4–5) lays the exemplar's principal feature line
//! along the field. On discs unfolded along the field and turned by the texture's principal
//! angle (score/surface.rs), a correct result shows its lines at that angle, as the exemplar
//! does. The structure tensor (the window sum of `∇I ∇Iᵀ` over luminance) gives each window's
//! dominant gradient direction; lines run across it. Windows without a dominant direction
//! (coherence `(λ₁ − λ₂) / (λ₁ + λ₂)` below 0.3: flat or isotropic content) say nothing
//! about alignment and are left out. The median over the rest is the measure, in degrees,
//! 0 (every line along the direction) to 90 (every line across it).

use crate::image::ImageView;
use texsyn_core::math::PureMath;

/// Side of the square windows the tensor sums over, in pixels.
const WINDOW: usize = 9;
/// Windows whose coherence is below this are isotropic and not counted.
const MIN_COHERENCE: f32 = 0.3;

/// The alignment of an image's lines with a direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alignment {
    /// Median angle between the windows' line directions and the expected one, degrees.
    pub median_degrees: f32,
    /// Windows counted (coherent, and wholly inside the mask).
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
