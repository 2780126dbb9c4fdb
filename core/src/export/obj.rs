//! Wavefront OBJ and MTL writers.
//!
//! Numbers are written as Rust's `{}` prints them (for `f32`, the shortest text that reads back
//! to the same value; see [`super::decimal`]), so files are deterministic and round-trip
//! exactly. The lines are formatted in parallel blocks and joined in order: the text does not
//! depend on the thread count.

use super::decimal::{push_f32, push_u64};
use crate::geom::Mesh;
use glam::Vec2;
use rayon::prelude::*;
use std::collections::HashMap;
use std::fmt::Write;
use std::hash::{BuildHasherDefault, Hasher};

/// Items per parallel block, and blocks formatted at once (what is held besides the output).
const BLOCK: usize = 1 << 14;
const WINDOW: usize = 16;

/// Generous lengths of a `v`, `vt` and `f v/vt` line (shortest `f32`s of up to 15
/// characters, indices of up to 10 digits): the output's capacity is reserved from them.
const V_LINE: usize = 2 + 3 * 16;
const VT_LINE: usize = 3 + 2 * 16;
const F_LINE: usize = 1 + 3 * 22 + 1;

/// Appends one line per item of `items`, formatted by `line(global index, item, out)` in
/// parallel blocks, in order.
fn par_lines<T: Sync>(
    items: &[T],
    out: &mut Vec<u8>,
    line: impl Fn(usize, &T, &mut Vec<u8>) + Sync,
) {
    for (w, window) in items.chunks(BLOCK * WINDOW).enumerate() {
        let blocks: Vec<Vec<u8>> = window
            .par_chunks(BLOCK)
            .enumerate()
            .map(|(b, block)| {
                let first = w * BLOCK * WINDOW + b * BLOCK;
                let mut text = Vec::with_capacity(block.len() * 48);
                for (k, item) in block.iter().enumerate() {
                    line(first + k, item, &mut text);
                }
                text
            })
            .collect();
        for b in blocks {
            out.extend_from_slice(&b);
        }
    }
}

/// A multiplicative hash for the texture-coordinate index (Fx-style: the keys are two bit
/// patterns, not attacker-chosen, and lookups are most of the writer's serial work).
#[derive(Default)]
struct PairHasher(u64);

impl Hasher for PairHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }
    fn write_u32(&mut self, n: u32) {
        self.write_u64(u64::from(n));
    }
    fn write_u64(&mut self, n: u64) {
        self.0 = (self.0.rotate_left(5) ^ n).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// Writes `mesh` as OBJ text: every vertex (`v`, in order, so vertex numbers are kept), the
/// distinct texture coordinates (`vt`, deduplicated by exact bit equality, in order of first
/// use) and one `f v/vt` line per triangle (`f v` without uvs). `corner_uv` holds each face's
/// three corner coordinates in OBJ convention (v up); when its length differs from the face
/// count it is ignored. With `mtl_file`, the file starts with `mtllib` and the faces use
/// `material`.
pub fn write_obj(
    mesh: &Mesh,
    corner_uv: Option<&[[Vec2; 3]]>,
    mtl_file: Option<&str>,
    material: &str,
) -> String {
    write_obj_materials(mesh, corner_uv, mtl_file, &[material.to_string()], None)
}

/// [`write_obj`] with several materials: face `f` uses `materials[face_material[f]]` (all use
/// the first without `face_material`). Faces are written grouped by material, one `usemtl`
/// per group, in face order within a group; materials no face uses are skipped.
pub fn write_obj_materials(
    mesh: &Mesh,
    corner_uv: Option<&[[Vec2; 3]]>,
    mtl_file: Option<&str>,
    materials: &[String],
    face_material: Option<&[u32]>,
) -> String {
    let corner_uv = corner_uv.filter(|c| c.len() == mesh.triangles.len());
    let face_material = face_material.filter(|m| m.len() == mesh.triangles.len());
    let mut head = String::from("# texsyn\n");
    if let Some(m) = mtl_file {
        let _ = writeln!(head, "mtllib {m}");
    }
    let mut out = head.into_bytes();
    // Index (1-based) of each face corner's vt, and the distinct coordinates in order of
    // first use.
    let mut corner_vt: Vec<[u32; 3]> = Vec::new();
    let mut distinct: Vec<Vec2> = Vec::new();
    if let Some(uvs) = corner_uv {
        // About half of a jump map's corners are distinct (seams are few): one growth at
        // most, instead of a rehash per doubling.
        let mut index: HashMap<(u32, u32), u32, BuildHasherDefault<PairHasher>> =
            HashMap::with_capacity_and_hasher(uvs.len() * 3 / 2, Default::default());
        corner_vt.reserve(uvs.len());
        for c in uvs {
            let mut vt = [0u32; 3];
            for k in 0..3 {
                let key = (c[k].x.to_bits(), c[k].y.to_bits());
                let next = index.len() as u32 + 1;
                vt[k] = *index.entry(key).or_insert_with(|| {
                    distinct.push(c[k]);
                    next
                });
            }
            corner_vt.push(vt);
        }
    }
    // Room for the longest lines the numbers usually make, so that the text is never moved
    // to a bigger buffer (a million-triangle OBJ is over 100 MB, and each move copies it into
    // fresh pages); capacity that is not written costs no memory.
    out.reserve(
        mesh.positions.len() * V_LINE
            + distinct.len() * VT_LINE
            + mesh.triangles.len() * F_LINE
            + materials.iter().map(|m| m.len() + 8).sum::<usize>(),
    );
    par_lines(&mesh.positions, &mut out, |_, p, out| {
        out.extend_from_slice(b"v ");
        push_f32(out, p.x);
        out.push(b' ');
        push_f32(out, p.y);
        out.push(b' ');
        push_f32(out, p.z);
        out.push(b'\n');
    });
    par_lines(&distinct, &mut out, |_, uv, out| {
        out.extend_from_slice(b"vt ");
        push_f32(out, uv.x);
        out.push(b' ');
        push_f32(out, uv.y);
        out.push(b'\n');
    });
    let face_line = |f: usize, out: &mut Vec<u8>| {
        let t = mesh.triangles[f];
        out.push(b'f');
        for k in 0..3 {
            out.push(b' ');
            push_u64(out, t[k] as u64 + 1);
            if let Some(vt) = corner_vt.get(f) {
                out.push(b'/');
                push_u64(out, vt[k].into());
            }
        }
        out.push(b'\n');
    };
    match face_material {
        None => {
            if mtl_file.is_some() {
                let name = materials.first().map_or("default", |m| m.as_str());
                out.extend_from_slice(format!("usemtl {name}\n").as_bytes());
            }
            par_lines(&mesh.triangles, &mut out, |f, _, out| face_line(f, out));
        }
        Some(fm) => {
            for (m, name) in materials.iter().enumerate() {
                let faces: Vec<usize> = (0..fm.len()).filter(|&f| fm[f] == m as u32).collect();
                if faces.is_empty() {
                    continue;
                }
                if mtl_file.is_some() {
                    out.extend_from_slice(format!("usemtl {name}\n").as_bytes());
                }
                par_lines(&faces, &mut out, |_, &f, out| face_line(f, out));
            }
        }
    }
    String::from_utf8(out).expect("OBJ text is the given names and ASCII numbers")
}

/// Texture files of a material, by name relative to the MTL file. Default: none.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MtlMaps {
    /// Base colour (`map_Kd`).
    pub diffuse: Option<String>,
    /// Tangent-space normal map (`norm`, and `map_Bump` for readers that take bump maps as
    /// normal maps, like Blender's and tobj). Written without the `-bm 1` option: 1 is the
    /// default, and simple readers (tobj) would take the option as part of the file name.
    pub normal: Option<String>,
    /// Roughness (`map_Pr`, the PBR extension of MTL).
    pub roughness: Option<String>,
    /// Height / displacement (`disp`).
    pub height: Option<String>,
}

/// Writes an MTL file with one material: white diffuse (modulated by `map_Kd` if given), no
/// specular, opaque, plus the given maps.
pub fn write_mtl(material: &str, maps: &MtlMaps) -> String {
    let mut out = String::new();
    out.push_str("# texsyn\n");
    let _ = writeln!(out, "newmtl {material}");
    out.push_str("Ka 0 0 0\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\n");
    if let Some(f) = &maps.diffuse {
        let _ = writeln!(out, "map_Kd {f}");
    }
    if let Some(f) = &maps.normal {
        let _ = writeln!(out, "norm {f}");
        let _ = writeln!(out, "map_Bump {f}");
    }
    if let Some(f) = &maps.roughness {
        let _ = writeln!(out, "map_Pr {f}");
    }
    if let Some(f) = &maps.height {
        let _ = writeln!(out, "disp {f}");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn read_back(obj: &str) -> Vec<tobj::Model> {
        let opts = tobj::LoadOptions {
            triangulate: true,
            ..Default::default()
        };
        let (models, _) = tobj::load_obj_buf(&mut obj.as_bytes(), &opts, |_| {
            Err(tobj::LoadError::OpenFileFailed)
        })
        .unwrap();
        models
    }

    #[test]
    fn obj_round_trips_through_tobj_with_shared_uvs() {
        let mesh = Mesh::new(
            vec![
                Vec3::new(0.1, -2.5, 3.0),
                Vec3::new(1e-7, 0.0, -0.0),
                Vec3::new(123456.79, 1.0 / 3.0, 0.5),
                Vec3::new(-1.0, 2.0, 7.25),
            ],
            vec![[0, 1, 2], [2, 1, 3]],
        );
        let uv = [
            [
                Vec2::new(0.0, 0.0),
                Vec2::new(0.1, 0.9),
                Vec2::new(1.0 / 3.0, 0.5),
            ],
            [
                Vec2::new(1.0 / 3.0, 0.5),
                Vec2::new(0.1, 0.9),
                Vec2::new(1.0, 1.0),
            ],
        ];
        let text = write_obj(&mesh, Some(&uv), Some("out.mtl"), "synth");
        assert_eq!(text.lines().filter(|l| l.starts_with("vt ")).count(), 4);
        assert!(text.contains("mtllib out.mtl\n") && text.contains("usemtl synth\n"));
        let models = read_back(&text);
        assert_eq!(models.len(), 1);
        let m = &models[0].mesh;
        assert_eq!(m.indices.len(), 6);
        for (f, (tri, fuv)) in mesh.triangles.iter().zip(&uv).enumerate() {
            for k in 0..3 {
                let vi = m.indices[3 * f + k] as usize;
                let p = Vec3::from_slice(&m.positions[3 * vi..3 * vi + 3]);
                assert_eq!(p, mesh.positions[tri[k] as usize]);
                let ti = m.texcoord_indices[3 * f + k] as usize;
                let t = Vec2::from_slice(&m.texcoords[2 * ti..2 * ti + 2]);
                assert_eq!(t, fuv[k]);
            }
        }
        // Deterministic text.
        assert_eq!(text, write_obj(&mesh, Some(&uv), Some("out.mtl"), "synth"));
    }

    #[test]
    fn obj_without_uvs_or_material_has_plain_faces() {
        let mesh = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
        let text = write_obj(&mesh, None, None, "unused");
        assert_eq!(text, "# texsyn\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    }

    #[test]
    fn mtl_names_every_map() {
        let maps = MtlMaps {
            diffuse: Some("albedo.png".into()),
            normal: Some("normal.png".into()),
            roughness: Some("rough.png".into()),
            height: Some("height.png".into()),
        };
        let text = write_mtl("synth", &maps);
        for line in [
            "newmtl synth",
            "map_Kd albedo.png",
            "norm normal.png",
            "map_Bump normal.png",
            "map_Pr rough.png",
            "disp height.png",
        ] {
            assert!(
                text.lines().any(|l| l == line),
                "missing {line:?} in\n{text}"
            );
        }
        let plain = write_mtl("m", &MtlMaps::default());
        assert!(!plain.contains("map_") && plain.contains("newmtl m\n"));
    }
}
