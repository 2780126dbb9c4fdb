//! A sample [`GlbMesh`] holding everything a glb can: shared by the glb writer's tests and the
//! `sample_glb` example, which writes it for the Khronos glTF validator. A child of the module
//! that defines the glb types (`super::GlbMesh` …): `export::glb` in the core, the example's
//! root (which imports them) in the example.

use super::{GlbAttribute, GlbMaterial, GlbMesh};
use glam::{Vec2, Vec3};

/// A w×h PNG of one colour.
pub fn png(w: u32, h: u32, rgb: [u8; 3]) -> Vec<u8> {
    let img = image::RgbImage::from_pixel(w, h, image::Rgb(rgb));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// A tetrahedron, unwelded (one vertex per corner), with everything a GlbMesh can hold.
pub fn sample_mesh() -> GlbMesh {
    let p = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.0, 3.0, 0.0),
        Vec3::new(0.0, 0.0, -4.5),
    ];
    let faces = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
    let mut m = GlbMesh {
        name: "tetra".into(),
        ..Default::default()
    };
    let mut uv0 = vec![];
    let mut uv1 = vec![];
    let mut col = vec![];
    let mut disp = vec![];
    for f in faces {
        let n = (p[f[1]] - p[f[0]]).cross(p[f[2]] - p[f[0]]).normalize();
        for (k, &v) in f.iter().enumerate() {
            m.indices.push(m.positions.len() as u32);
            m.positions.push(p[v]);
            m.normals.push(n);
            m.tangents
                .push((p[f[1]] - p[f[0]]).normalize().extend(-1.0));
            uv0.push(Vec2::new(k as f32 * 0.5, v as f32 * 0.25));
            uv1.push(Vec2::new(0.125, k as f32 / 3.0));
            col.push([1.0, 0.5, k as f32 / 2.0, 1.0]);
            disp.push(Vec3::splat(v as f32 * 0.1));
        }
    }
    m.texcoords = vec![uv0, uv1];
    m.colors = Some(col);
    m.extra = vec![GlbAttribute {
        name: "_DISPLACEMENT".into(),
        values: disp,
    }];
    m.material = GlbMaterial {
        base_color_png: Some(png(5, 3, [200, 100, 50])),
        normal_png: Some(png(2, 2, [128, 128, 255])),
        metallic_roughness_png: Some(png(1, 1, [0, 200, 0])),
        roughness: 0.8,
        double_sided: true,
        ..Default::default()
    };
    m
}
