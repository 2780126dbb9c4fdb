//! Surface colour: the [`SurfaceShader`] trait that the renderer and the baker ask, and the
//! usual implementations (constant, textured through per-corner uvs, vertex colours).

use crate::geom::Mesh;
use crate::image::ImageView;
use glam::{Vec2, Vec3};

/// The colour of a surface, asked per pixel (renderer) or per texel (baker), from many threads.
pub trait SurfaceShader: Sync {
    /// Colour (RGB, in \[0, 1\], sRGB-encoded like the textures) at a point of triangle `face` with
    /// barycentric coordinates `bary` (components sum to 1, ordered like the triangle's corners).
    fn albedo(&self, face: usize, bary: Vec3) -> Vec3;
}

/// The same colour everywhere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConstantShader(pub Vec3);

impl SurfaceShader for ConstantShader {
    fn albedo(&self, _face: usize, _bary: Vec3) -> Vec3 {
        self.0
    }
}

/// Colour used for faces a shader has no data for (a caller's inconsistency, shown loudly).
pub const MISSING_COLOR: Vec3 = Vec3::new(1.0, 0.0, 1.0);

/// A texture applied through per-face corner texture coordinates in OBJ convention (u right,
/// v up, [0, 1] over the image), sampled bilinearly. Coordinates outside [0, 1] repeat the
/// texture (OBJ's default wrapping); inside, the image border is clamped.
#[derive(Debug, Clone, Copy)]
pub struct CornerUvShader<'a> {
    /// Texture coordinates of each face's three corners, indexed by face.
    pub corner_uv: &'a [[Vec2; 3]],
    pub texture: ImageView<'a>,
}

impl<'a> CornerUvShader<'a> {
    pub fn new(corner_uv: &'a [[Vec2; 3]], texture: ImageView<'a>) -> Self {
        CornerUvShader { corner_uv, texture }
    }
}

#[inline]
fn wrap01(t: f32) -> f32 {
    if (0.0..=1.0).contains(&t) {
        t
    } else {
        t.rem_euclid(1.0)
    }
}

/// `texture` at the point `bary` of a face whose corners have texture coordinates `uv` (OBJ
/// convention: v up, repeat wrapping), bilinearly.
fn sample_corner_uv(texture: &ImageView<'_>, uv: &[Vec2; 3], bary: Vec3) -> Vec3 {
    if texture.width == 0 || texture.height == 0 {
        return MISSING_COLOR;
    }
    let p = uv[0] * bary.x + uv[1] * bary.y + uv[2] * bary.z;
    let (u, v) = (wrap01(p.x), wrap01(p.y));
    let (w, h) = (texture.width as f32, texture.height as f32);
    let texel = Vec2::new(u * w - 0.5, (1.0 - v) * h - 0.5);
    let c = texture.sample(texel);
    Vec3::new(c[0], c[1], c[2])
}

impl SurfaceShader for CornerUvShader<'_> {
    fn albedo(&self, face: usize, bary: Vec3) -> Vec3 {
        let Some(uv) = self.corner_uv.get(face) else {
            return MISSING_COLOR;
        };
        sample_corner_uv(&self.texture, uv, bary)
    }
}

/// Per-face textures through per-corner texture coordinates: face `f` samples
/// `textures[face_texture[f]]`, or is `untextured[f]` when it has none. This is an OBJ whose
/// materials name their `map_Kd` images, several pages of a baked atlas among them.
pub struct MaterialUvShader<'a> {
    pub corner_uv: &'a [[Vec2; 3]],
    pub face_texture: &'a [Option<u32>],
    pub textures: Vec<ImageView<'a>>,
    /// Colour of a face without a texture (its material's `Kd`, else neutral grey).
    pub untextured: &'a [Vec3],
}

impl SurfaceShader for MaterialUvShader<'_> {
    fn albedo(&self, face: usize, bary: Vec3) -> Vec3 {
        let (Some(uv), Some(&tex)) = (self.corner_uv.get(face), self.face_texture.get(face)) else {
            return MISSING_COLOR;
        };
        match tex.and_then(|k| self.textures.get(k as usize)) {
            Some(texture) => sample_corner_uv(texture, uv, bary),
            None => self.untextured.get(face).copied().unwrap_or(MISSING_COLOR),
        }
    }
}

/// Per-vertex colours (RGBA in [0, 1], sRGB-encoded; alpha ignored), interpolated linearly.
#[derive(Debug, Clone, Copy)]
pub struct VertexColorShader<'a> {
    pub triangles: &'a [[u32; 3]],
    pub colors: &'a [[f32; 4]],
}

impl<'a> VertexColorShader<'a> {
    pub fn new(triangles: &'a [[u32; 3]], colors: &'a [[f32; 4]]) -> Self {
        VertexColorShader { triangles, colors }
    }

    /// The mesh's own vertex colours, if it has them (one per vertex).
    pub fn from_mesh(mesh: &'a Mesh) -> Option<Self> {
        let colors = mesh.colors.as_deref()?;
        (colors.len() == mesh.positions.len()).then(|| Self::new(&mesh.triangles, colors))
    }
}

impl SurfaceShader for VertexColorShader<'_> {
    fn albedo(&self, face: usize, bary: Vec3) -> Vec3 {
        let Some(t) = self.triangles.get(face) else {
            return MISSING_COLOR;
        };
        let mut out = Vec3::ZERO;
        for k in 0..3 {
            let Some(c) = self.colors.get(t[k] as usize) else {
                return MISSING_COLOR;
            };
            out += Vec3::new(c[0], c[1], c[2]) * bary[k];
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;

    #[test]
    fn corner_uv_shader_maps_obj_uv_to_the_right_texels() {
        // 2x2 texture: top row red, green; bottom row blue, white.
        let mut img = Image::new(2, 2);
        img.pixels = vec![
            [1.0, 0.0, 0.0, 1.0],
            [0.0, 1.0, 0.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
            [1.0, 1.0, 1.0, 1.0],
        ];
        // One face whose corners sit at the texel centres; bary picks a single corner.
        let uv = [[
            Vec2::new(0.25, 0.75),
            Vec2::new(0.75, 0.75),
            Vec2::new(0.25, 0.25),
        ]];
        let s = CornerUvShader::new(&uv, img.view());
        assert_eq!(s.albedo(0, Vec3::X), Vec3::new(1.0, 0.0, 0.0)); // top left
        assert_eq!(s.albedo(0, Vec3::Y), Vec3::new(0.0, 1.0, 0.0)); // top right
        assert_eq!(s.albedo(0, Vec3::Z), Vec3::new(0.0, 0.0, 1.0)); // bottom left
        // Repeat wrapping: u = 1.25 is u = 0.25.
        let uv2 = [[Vec2::new(1.25, 0.75); 3]];
        let s2 = CornerUvShader::new(&uv2, img.view());
        assert_eq!(s2.albedo(0, Vec3::X), Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(s.albedo(5, Vec3::X), MISSING_COLOR);
    }

    #[test]
    fn material_uv_shader_takes_each_faces_own_texture() {
        let solid = |c: [f32; 4]| {
            let mut img = Image::new(2, 2);
            img.pixels = vec![c; 4];
            img
        };
        let (red, blue) = (solid([1.0, 0.0, 0.0, 1.0]), solid([0.0, 0.0, 1.0, 1.0]));
        let uv = [[Vec2::new(0.5, 0.5); 3]; 4];
        let face_texture = [Some(1), Some(0), None, Some(7)];
        let untextured = [Vec3::ZERO, Vec3::ZERO, Vec3::new(0.2, 0.3, 0.4), Vec3::ZERO];
        let s = MaterialUvShader {
            corner_uv: &uv,
            face_texture: &face_texture,
            textures: vec![red.view(), blue.view()],
            untextured: &untextured,
        };
        assert_eq!(s.albedo(0, Vec3::X), Vec3::new(0.0, 0.0, 1.0));
        assert_eq!(s.albedo(1, Vec3::X), Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(s.albedo(2, Vec3::X), Vec3::new(0.2, 0.3, 0.4));
        // A texture index past the list is the face's untextured colour, not a panic.
        assert_eq!(s.albedo(3, Vec3::X), Vec3::ZERO);
        assert_eq!(s.albedo(4, Vec3::X), MISSING_COLOR);
    }

    #[test]
    fn vertex_colors_interpolate() {
        let tris = [[0u32, 1, 2]];
        let cols = [
            [1.0, 0.0, 0.0, 1.0],
            [0.0, 1.0, 0.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
        ];
        let s = VertexColorShader::new(&tris, &cols);
        let c = s.albedo(0, Vec3::new(0.5, 0.25, 0.25));
        assert!((c - Vec3::new(0.5, 0.25, 0.25)).length() < 1e-6);
    }
}
