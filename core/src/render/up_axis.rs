//! Which way is up for a mesh's previews, when the config does not say: the axis (±X, ±Y,
//! ±Z) on which the shape would stand most steadily, the way a scanned animal or statue
//! stands on its feet.
//!
//! For each of the six directions the shape is set down on a floor at right angles to it:
//! the vertices within 2 % of its height above the floor touch it, and the convex hull of
//! their footprints is the support. The shape stands when the centroid of its surface lies
//! over the support; how steadily is the support's area against the area of the shape's own
//! footprint. Four hooves spread under a body give a large support under the centroid; a body
//! on its side touches along a thin strip; an upturned one on its back, a patch. Heuristics of
//! the same kind (the support polygon, static stability) are what upright-orientation methods
//! start from (Fu, Cohen-Or, Dror and Sheffer, "Upright Orientation of Man-Made Objects", 2008).
//!
//! +Y, the glTF convention and the default before a guess, is kept unless another direction
//! stands clearly more steadily ([`CLEARLY`]) on a real support ([`MIN_SUPPORT`]): shapes
//! that stand on no side, or on several alike, keep it. Measured on the shared meshes: a
//! standing man modelled Z-up gets +Z (support 82 % of his footprint against 0 % on +Y), the
//! mushroom +Z (98 % against 39 %), the cow keeps +Y (52 %), the elephant and the Chinese
//! dragon keep +Y (no side reaches 10 %), a knot lies flat (±Z, 35 %).
//!
//! A node's key leaves `up` out when it is `"auto"` and never holds the guess (the guess
//! follows from the mesh, an input of the node): a change to this rule changes what a cached
//! key stands for, so it must come with a version bump of every node that calls
//! [`UpAxis::resolve`].

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// Another direction must stand this many times more steadily than +Y to replace it.
pub const CLEARLY: f32 = 1.5;
/// ... and on a support of at least this share of its footprint: a shape that stands on no
/// side (the elephant rearing on two feet: at most 1.6 % on any side) keeps +Y.
pub const MIN_SUPPORT: f32 = 0.1;
/// The share of the height above the floor within which vertices touch it.
const CONTACT: f32 = 0.02;

/// `up` in a method's `[reconstruct]`: a direction, or `"auto"` (the default), which guesses
/// it from the mesh ([`guess_up`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum UpAxis {
    Auto(Auto),
    Given([f32; 3]),
}

/// The word `"auto"`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Auto {
    #[serde(rename = "auto")]
    Auto,
}

impl Default for UpAxis {
    fn default() -> Self {
        UpAxis::Auto(Auto::Auto)
    }
}

impl UpAxis {
    pub fn is_auto(&self) -> bool {
        matches!(self, UpAxis::Auto(_))
    }

    /// A given direction must be finite and non-zero: the reason when it is not.
    pub fn check(&self) -> Result<(), String> {
        match self {
            UpAxis::Given(v)
                if !v.iter().all(|x| x.is_finite()) || Vec3::from(*v).length() < 1e-12 =>
            {
                Err(format!(
                    "must be a finite non-zero vector or \"auto\", got {v:?}"
                ))
            }
            _ => Ok(()),
        }
    }

    /// The direction: the given one, or the guess for the mesh (`positions`, `triangles`),
    /// which is logged with `what` (the node) so the user knows which axis was used.
    pub fn resolve(&self, positions: &[Vec3], triangles: &[[u32; 3]], what: &str) -> Vec3 {
        match *self {
            UpAxis::Given(v) => Vec3::from(v),
            UpAxis::Auto(_) => {
                let guess = guess_up(positions, triangles);
                tracing::info!(
                    "{what}: previews stand the mesh with {} up (guessed from the mesh: it stands \
                     on that side most steadily; set reconstruct.up to choose)",
                    axis_name(guess)
                );
                guess
            }
        }
    }
}

/// `+x`, `-z`, …: a unit axis's name.
pub fn axis_name(v: Vec3) -> String {
    let (i, x) = v
        .to_array()
        .into_iter()
        .enumerate()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .expect("three components");
    format!("{}{}", if x < 0.0 { '-' } else { '+' }, ['x', 'y', 'z'][i])
}

/// The guessed up direction of a mesh (see the module doc); +Y for an empty one.
pub fn guess_up(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec3 {
    let centroid = surface_centroid(positions, triangles);
    let Some(centroid) = centroid else {
        return Vec3::Y;
    };
    let axes = [
        Vec3::Y,
        Vec3::NEG_Y,
        Vec3::X,
        Vec3::NEG_X,
        Vec3::Z,
        Vec3::NEG_Z,
    ];
    let scores: Vec<f32> = axes
        .iter()
        .map(|&up| steadiness(positions, centroid, up))
        .collect();
    let (best, &score) = scores
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(&a.0)))
        .expect("six axes");
    if score >= MIN_SUPPORT && score > CLEARLY * scores[0] {
        axes[best]
    } else {
        Vec3::Y
    }
}

/// The area-weighted centroid of the surface (`None` without area).
fn surface_centroid(positions: &[Vec3], triangles: &[[u32; 3]]) -> Option<Vec3> {
    let (mut sum, mut area) = (Vec3::ZERO, 0.0f64);
    for t in triangles {
        let [a, b, c] = t.map(|i| positions.get(i as usize).copied().unwrap_or(Vec3::ZERO));
        let w = 0.5 * (b - a).cross(c - a).length();
        if w.is_finite() {
            sum += w * (a + b + c) / 3.0;
            area += w as f64;
        }
    }
    (area > 0.0).then(|| sum / area as f32)
}

/// How steadily the shape stands with `up` up: the support's area over the footprint's when
/// the centroid is over the support, else 0.
fn steadiness(positions: &[Vec3], centroid: Vec3, up: Vec3) -> f32 {
    // A frame of the floor.
    let u = if up.x.abs() > 0.5 { Vec3::Y } else { Vec3::X };
    let v = up.cross(u);
    let u = v.cross(up);
    let floor = |p: Vec3| Vec2::new(p.dot(u), p.dot(v));
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for p in positions {
        let h = p.dot(up);
        lo = lo.min(h);
        hi = hi.max(h);
    }
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return 0.0;
    }
    let touch = lo + CONTACT * (hi - lo);
    let contact: Vec<Vec2> = positions
        .iter()
        .filter(|p| p.dot(up) <= touch)
        .map(|&p| floor(p))
        .collect();
    let support = convex_hull(contact);
    let footprint = convex_hull(positions.iter().map(|&p| floor(p)).collect());
    let whole = polygon_area(&footprint);
    if whole <= 0.0 || !inside(&support, floor(centroid)) {
        return 0.0;
    }
    polygon_area(&support) / whole
}

/// The convex hull, counter-clockwise (Andrew's monotone chain).
fn convex_hull(mut points: Vec<Vec2>) -> Vec<Vec2> {
    points.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    points.dedup();
    if points.len() < 3 {
        return points;
    }
    let cross = |o: Vec2, a: Vec2, b: Vec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<Vec2> = Vec::with_capacity(2 * points.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &Vec2>> = if pass == 0 {
            Box::new(points.iter())
        } else {
            Box::new(points.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

fn polygon_area(poly: &[Vec2]) -> f32 {
    if poly.len() < 3 {
        return 0.0;
    }
    let mut a = 0.0;
    for i in 0..poly.len() {
        a += poly[i].perp_dot(poly[(i + 1) % poly.len()]);
    }
    0.5 * a.abs()
}

/// Whether `p` lies in the counter-clockwise convex polygon `poly` (on its border counts).
fn inside(poly: &[Vec2], p: Vec2) -> bool {
    poly.len() >= 3
        && (0..poly.len())
            .all(|i| (poly[(i + 1) % poly.len()] - poly[i]).perp_dot(p - poly[i]) >= -1e-9)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::PureMath;

    /// A box `size` at `at`, as 8 corners and 12 triangles appended to `p`, `t`.
    fn cuboid(p: &mut Vec<Vec3>, t: &mut Vec<[u32; 3]>, at: Vec3, size: Vec3) {
        let base = p.len() as u32;
        for k in 0..8 {
            let c = Vec3::new((k & 1) as f32, ((k >> 1) & 1) as f32, ((k >> 2) & 1) as f32);
            p.push(at + c * size);
        }
        for q in [
            [0, 1, 3, 2],
            [4, 6, 7, 5],
            [0, 4, 5, 1],
            [2, 3, 7, 6],
            [0, 2, 6, 4],
            [1, 5, 7, 3],
        ] {
            t.push([base + q[0], base + q[1], base + q[2]]);
            t.push([base + q[0], base + q[2], base + q[3]]);
        }
    }

    /// A creature (a rounded body on four thin legs) standing along `up`.
    fn creature(up: Vec3) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let (mut p, mut t) = (Vec::new(), Vec::new());
        // Modelled with +Y up: an ellipsoid body 4 × 1.2 × 1.6 centred at height 1.3.
        let (rings, segments) = (8u32, 16u32);
        for i in 0..=rings {
            let theta = std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..segments {
                let phi = std::f32::consts::TAU * j as f32 / segments as f32;
                let d = Vec3::new(
                    theta.sin_pure() * phi.cos_pure(),
                    theta.cos_pure(),
                    theta.sin_pure() * phi.sin_pure(),
                );
                p.push(Vec3::new(0.0, 1.3, 0.0) + d * Vec3::new(2.0, 0.6, 0.8));
            }
        }
        for i in 0..rings {
            for j in 0..segments {
                let a = i * segments + j;
                let b = i * segments + (j + 1) % segments;
                t.push([a, a + segments, b]);
                t.push([b, a + segments, b + segments]);
            }
        }
        for (x, z) in [(-1.3, -0.5), (1.2, -0.5), (-1.3, 0.4), (1.2, 0.4)] {
            cuboid(
                &mut p,
                &mut t,
                Vec3::new(x, 0.0, z),
                Vec3::new(0.15, 1.0, 0.15),
            );
        }
        let rot = glam::Quat::from_rotation_arc(Vec3::Y, up);
        (p.into_iter().map(|x| rot * x).collect(), t)
    }

    #[test]
    fn a_creature_is_stood_on_its_legs_whichever_axis_it_was_modelled_along() {
        for up in [Vec3::Y, Vec3::Z, Vec3::NEG_Z, Vec3::X, Vec3::NEG_Y] {
            let (p, t) = creature(up);
            let guess = guess_up(&p, &t);
            assert!(
                guess.abs_diff_eq(up, 1e-5),
                "modelled {up}: guessed {guess}"
            );
        }
    }

    #[test]
    fn a_shape_with_no_steadier_side_keeps_plus_y() {
        let (mut p, mut t) = (Vec::new(), Vec::new());
        cuboid(&mut p, &mut t, Vec3::ZERO, Vec3::splat(1.0));
        assert_eq!(guess_up(&p, &t), Vec3::Y);
        assert_eq!(guess_up(&[], &[]), Vec3::Y);
    }

    #[test]
    fn up_reads_auto_or_a_vector_and_names_axes() {
        #[derive(Deserialize)]
        struct R {
            up: UpAxis,
        }
        let r: R = toml::from_str("up = \"auto\"").unwrap();
        assert!(r.up.is_auto());
        let r: R = toml::from_str("up = [0.0, 0.0, 1.0]").unwrap();
        assert_eq!(r.up, UpAxis::Given([0.0, 0.0, 1.0]));
        assert!(toml::from_str::<R>("up = \"sideways\"").is_err());
        assert!(UpAxis::Given([0.0; 3]).check().is_err());
        assert_eq!(axis_name(Vec3::NEG_Z), "-z");
        assert_eq!(axis_name(Vec3::new(0.1, 0.9, 0.0)), "+y");
    }
}
