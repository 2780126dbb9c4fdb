//! Consistent corner coordinates and three-way blending (Zelinka & Garland, "Interactive
//! Texture Synthesis on Surfaces Using Jump Maps", §4.3 and §4.4).
//!
//! A triangle's corners get texture coordinates from one *base* corner: its vertex's address,
//! and for the other two corners that address plus the edge offsets from the base. The
//! triangle then maps undistorted into one place of the exemplar even where a jump was taken
//! across one of its edges. §4.3 picks one base at random; §4.4 uses all three sets, each
//! weighted by a linear alpha ramp that is 1 at its base corner and 0 at the other two (the
//! base corner's barycentric coordinate), which hides the seams between patches.

use crate::image::ImageView;
use crate::parameterize::jump_parameterization::ParamParts;
use crate::random::counter_hash;
use crate::reconstruct::wide_blend::WideBlend;
use crate::render::shader::SurfaceShader;
use glam::{Vec2, Vec3};

/// A triangle edge that the parameterization does not hold: it is not of this mesh.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("face {face}: edge {from}-{to} is not in the parameterization")]
pub struct MissingEdge {
    pub face: usize,
    pub from: u32,
    pub to: u32,
}

/// Per face, per base corner `b`, the texel address of each corner `c`: `sets[f][b][c]`.
pub type CornerSets = Vec<[[Vec2; 3]; 3]>;

/// Computes the three corner-coordinate sets of every triangle (§4.3 applied with each
/// corner as the base, as §4.4 needs). Edges are looked up in the parameterization; a missing
/// edge means the parameterization is not of this mesh.
pub fn corner_sets(
    triangles: &[[u32; 3]],
    param: &ParamParts,
    addresses: &[Vec2],
) -> Result<CornerSets, MissingEdge> {
    use rayon::prelude::*;
    let face_sets = |f: usize, t: &[u32; 3]| -> Result<[[Vec2; 3]; 3], MissingEdge> {
        let mut sets = [[Vec2::ZERO; 3]; 3];
        for b in 0..3 {
            let base = addresses[t[b] as usize];
            for c in 0..3 {
                sets[b][c] = if c == b {
                    base
                } else {
                    base + param.offset(t[b], t[c]).ok_or(MissingEdge {
                        face: f,
                        from: t[b],
                        to: t[c],
                    })?
                };
            }
        }
        Ok(sets)
    };
    // In parallel (a million faces); a failure is found again in order, so the error names
    // the first missing edge whatever the thread count.
    let sets: Option<CornerSets> = triangles
        .par_iter()
        .enumerate()
        .map(|(f, t)| face_sets(f, t).ok())
        .collect();
    match sets {
        Some(sets) => Ok(sets),
        None => triangles
            .iter()
            .enumerate()
            .map(|(f, t)| face_sets(f, t))
            .collect(),
    }
}

/// How far (texels, plus a fraction of the edge) the walk's addresses along an edge may stray
/// from the edge's offset and still count as one patch: the walk sets each vertex from one
/// neighbour exactly (§4.2.5's continuation), and the other edges of a patch agree up to the
/// offsets' own inconsistency, while a jump lands at least the jump map's exclusion radius
/// away.
const CONTINUITY_TEXELS: f32 = 0.1;
const CONTINUITY_FRACTION: f32 = 0.25;

/// Whether an edge with offset `offset` whose ends have the addresses `from` and `to` lies
/// inside one patch of the walk (no jump taken across it).
pub fn one_patch(offset: Vec2, from: Vec2, to: Vec2) -> bool {
    ((to - from) - offset).length() <= CONTINUITY_TEXELS + CONTINUITY_FRACTION * offset.length()
}

/// One set per face with a random base corner (§4.3), for formats that hold one set. The
/// choice is a fixed hash of the face index: §4.3 found no strategy better than random.
pub fn random_base_set(sets: &CornerSets) -> Vec<[Vec2; 3]> {
    sets.iter()
        .enumerate()
        .map(|(f, s)| s[(counter_hash(0, 7, f as u64) % 3) as usize])
        .collect()
}

/// The blended surface colour of §4.4: Σ_b λ_b · T(Σ_c λ_c · sets[f][b][c]), λ the
/// barycentric coordinates (so the alpha ramp of set b is λ_b and the weights sum to 1); or,
/// with `wide`, the blend over several triangles of [`crate::reconstruct::wide_blend`].
pub struct BlendShader<'a> {
    pub sets: &'a CornerSets,
    pub texture: ImageView<'a>,
    pub wide: Option<&'a WideBlend>,
}

impl BlendShader<'_> {
    pub fn rgba(&self, face: usize, bary: Vec3) -> [f32; 4] {
        if let Some(wide) = self.wide {
            return wide.rgba(&self.texture, face, bary);
        }
        let s = &self.sets[face];
        let l = bary.to_array();
        let mut out = [0.0f32; 4];
        for b in 0..3 {
            if l[b] <= 0.0 {
                continue;
            }
            let p = s[b][0] * l[0] + s[b][1] * l[1] + s[b][2] * l[2];
            let c = self.texture.sample(p);
            for k in 0..4 {
                out[k] += l[b] * c[k];
            }
        }
        out
    }
}

impl SurfaceShader for BlendShader<'_> {
    fn albedo(&self, face: usize, bary: Vec3) -> Vec3 {
        let c = self.rgba(face, bary);
        Vec3::new(c[0], c[1], c[2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;

    #[test]
    fn blend_equals_plain_lookup_when_the_three_sets_agree() {
        // When the corner sets agree (no jump across the triangle's edges) the blend is the
        // ordinary textured triangle: weights sum to one.
        let mut img = Image::new(8, 8);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            *p = [i as f32 / 64.0, 0.5, 1.0 - i as f32 / 64.0, 1.0];
        }
        let tri = [
            Vec2::new(1.0, 1.0),
            Vec2::new(5.0, 1.5),
            Vec2::new(2.0, 6.0),
        ];
        let sets = vec![[tri; 3]];
        let shader = BlendShader {
            sets: &sets,
            texture: img.view(),
            wide: None,
        };
        for bary in [
            Vec3::new(0.2, 0.3, 0.5),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.1, 0.8, 0.1),
        ] {
            let p = tri[0] * bary.x + tri[1] * bary.y + tri[2] * bary.z;
            let want = img.view().sample(p);
            let got = shader.rgba(0, bary);
            for k in 0..4 {
                assert!((got[k] - want[k]).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn at_a_corner_only_that_corners_set_is_seen() {
        let mut img = Image::new(4, 1);
        img.pixels[0] = [1.0, 0.0, 0.0, 1.0];
        img.pixels[3] = [0.0, 0.0, 1.0, 1.0];
        // Set 0 places the triangle at x=0, sets 1 and 2 at x=3.
        let a = [Vec2::new(0.0, 0.0); 3];
        let b = [Vec2::new(3.0, 0.0); 3];
        let sets = vec![[a, b, b]];
        let shader = BlendShader {
            sets: &sets,
            texture: img.view(),
            wide: None,
        };
        assert_eq!(
            shader.rgba(0, Vec3::new(1.0, 0.0, 0.0)),
            [1.0, 0.0, 0.0, 1.0]
        );
        assert_eq!(
            shader.rgba(0, Vec3::new(0.0, 1.0, 0.0)),
            [0.0, 0.0, 1.0, 1.0]
        );
        let mid = shader.rgba(0, Vec3::new(0.5, 0.25, 0.25));
        assert!((mid[0] - 0.5).abs() < 1e-6 && (mid[2] - 0.5).abs() < 1e-6);
    }
}
