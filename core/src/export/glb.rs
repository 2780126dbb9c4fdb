//! Binary glTF 2.0 (`.glb`) writer: one mesh, one or more primitives sharing its vertex arrays
//! (one material each, e.g. one per atlas page), textures embedded.
//!
//! Layout: a 12-byte header, a JSON chunk (padded with spaces) and a BIN chunk (padded with
//! zeros). Every array and image is its own bufferView, starting on a 4-byte boundary. The JSON
//! has sorted keys (serde_json's map) and shortest round-trip numbers, so the bytes depend only
//! on the input.

use glam::{Vec2, Vec3, Vec4};
use serde_json::{Map, Value, json};

/// A custom per-vertex attribute (glTF application-specific semantic).
#[derive(Debug, Clone, PartialEq)]
pub struct GlbAttribute {
    /// Attribute name, starting with `_` (e.g. `_DISPLACEMENT`).
    pub name: String,
    /// One value per vertex.
    pub values: Vec<Vec3>,
}

/// The material of a [`GlbMesh`] (glTF metallic-roughness).
#[derive(Debug, Clone, PartialEq)]
pub struct GlbMaterial {
    /// Default: "texsyn".
    pub name: String,
    /// Base colour texture, PNG bytes (sRGB). Default: none.
    pub base_color_png: Option<Vec<u8>>,
    /// Multiplies the base colour (linear RGBA). Default: [1, 1, 1, 1].
    pub base_color_factor: [f32; 4],
    /// Tangent-space normal map, PNG bytes. Default: none.
    pub normal_png: Option<Vec<u8>>,
    /// Metallic (blue) and roughness (green) texture, PNG bytes. Default: none.
    pub metallic_roughness_png: Option<Vec<u8>>,
    /// Roughness factor in [0, 1] (clamped). Default: 1.
    pub roughness: f32,
    /// Metallic factor in [0, 1] (clamped). Default: 0.
    pub metallic: f32,
    /// Render both sides of every triangle. Default: false.
    pub double_sided: bool,
    /// Which TEXCOORD_n set the textures use. Default: 0.
    pub texcoord: u32,
}

impl Default for GlbMaterial {
    fn default() -> Self {
        GlbMaterial {
            name: "texsyn".into(),
            base_color_png: None,
            base_color_factor: [1.0; 4],
            normal_png: None,
            metallic_roughness_png: None,
            roughness: 1.0,
            metallic: 0.0,
            double_sided: false,
            texcoord: 0,
        }
    }
}

/// A triangle mesh ready for glTF: per-vertex arrays of equal length (vertices may be unwelded,
/// one per corner), triangle list indices.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GlbMesh {
    /// Node and mesh name. Default: empty (no name written).
    pub name: String,
    pub positions: Vec<Vec3>,
    /// Unit normals, one per vertex, or empty for none. Written normalized; zero or non-finite
    /// ones are written as +Z (glTF requires unit length).
    pub normals: Vec<Vec3>,
    /// Tangents (xyz unit, w = ±1 handedness), one per vertex, or empty for none; written
    /// normalized (w snapped to ±1). Give them with a normal map for portable results.
    pub tangents: Vec<Vec4>,
    /// Up to 4 texture coordinate sets (TEXCOORD_0..3), glTF convention (v down).
    pub texcoords: Vec<Vec<Vec2>>,
    /// Optional vertex colours (COLOR_0, linear RGBA, clamped to [0, 1]).
    pub colors: Option<Vec<[f32; 4]>>,
    /// Custom attributes (VEC3 float).
    pub extra: Vec<GlbAttribute>,
    /// Triangle list, three indices per triangle.
    pub indices: Vec<u32>,
    pub material: GlbMaterial,
    /// Further primitives over the same vertex arrays, each with its own material (one per
    /// page of a multi-page atlas). Default: none.
    pub more_primitives: Vec<GlbPrimitive>,
}

impl GlbMesh {
    /// `mesh` coloured per vertex, double-sided, without a texture: `srgb` holds its vertices'
    /// sRGB-encoded colours (as texsyn's images and PLYs do), written as glTF's linear
    /// `COLOR_0` (alpha 1). The fallback of the per-triangle atlas exports.
    pub fn vertex_coloured(name: &str, mesh: &crate::geom::Mesh, srgb: &[[f32; 4]]) -> GlbMesh {
        use crate::render::srgb::to_linear;
        GlbMesh {
            name: name.into(),
            positions: mesh.positions.clone(),
            normals: mesh.vertex_normals().to_vec(),
            colors: Some(
                srgb.iter()
                    .map(|c| [to_linear(c[0]), to_linear(c[1]), to_linear(c[2]), 1.0])
                    .collect(),
            ),
            indices: mesh.triangles.iter().flatten().copied().collect(),
            material: GlbMaterial {
                double_sided: true,
                ..Default::default()
            },
            ..Default::default()
        }
    }
}

/// A primitive of a [`GlbMesh`] beyond the first: its triangles and their material.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GlbPrimitive {
    /// Triangle list, three indices per triangle (into the mesh's vertex arrays).
    pub indices: Vec<u32>,
    pub material: GlbMaterial,
}

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const GLB_MAGIC: u32 = 0x4654_6C67; // "glTF"
const CHUNK_JSON: u32 = 0x4E4F_534A; // "JSON"
const CHUNK_BIN: u32 = 0x004E_4942; // "BIN\0"

/// Accumulates the BIN chunk, its bufferViews and accessors. The chunk is sized up front
/// (see [`write_glb`]) and the arrays are appended to it directly: a million-triangle .glb is
/// over 50 MB, and every intermediate copy or regrowth of it touches that much fresh memory.
#[derive(Default)]
struct Builder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Builder {
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        self.view_with(target, |bin| bin.extend_from_slice(bytes))
    }

    /// A bufferView over what `append` adds to the chunk (at a 4-byte boundary).
    fn view_with(&mut self, target: Option<u32>, append: impl FnOnce(&mut Vec<u8>)) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let start = self.bin.len();
        append(&mut self.bin);
        let mut v = Map::new();
        v.insert("buffer".into(), json!(0));
        v.insert("byteOffset".into(), json!(start));
        v.insert("byteLength".into(), json!(self.bin.len() - start));
        if let Some(t) = target {
            v.insert("target".into(), json!(t));
        }
        self.views.push(Value::Object(v));
        self.views.len() - 1
    }

    /// A float accessor over `f` of every item (`N` components per element), written into
    /// the chunk as it is computed; with `bounds`, per-component min and max are recorded.
    fn floats<T, const N: usize>(
        &mut self,
        items: &[T],
        f: impl Fn(&T) -> [f32; N],
        ty: &str,
        bounds: bool,
    ) -> usize {
        let mut lo = [f32::INFINITY; N];
        let mut hi = [f32::NEG_INFINITY; N];
        let view = self.view_with(Some(ARRAY_BUFFER), |bin| {
            for item in items {
                let e = f(item);
                for k in 0..N {
                    if bounds {
                        lo[k] = lo[k].min(e[k]);
                        hi[k] = hi[k].max(e[k]);
                    }
                    bin.extend_from_slice(&e[k].to_le_bytes());
                }
            }
        });
        let mut a = Map::new();
        a.insert("bufferView".into(), json!(view));
        a.insert("componentType".into(), json!(FLOAT));
        a.insert("count".into(), json!(items.len()));
        a.insert("type".into(), json!(ty));
        if bounds {
            a.insert("min".into(), json!(lo.as_slice()));
            a.insert("max".into(), json!(hi.as_slice()));
        }
        self.accessors.push(Value::Object(a));
        self.accessors.len() - 1
    }

    fn indices(&mut self, idx: &[u32]) -> usize {
        let view = self.view_with(Some(ELEMENT_ARRAY_BUFFER), |bin| {
            for x in idx {
                bin.extend_from_slice(&x.to_le_bytes());
            }
        });
        self.accessors.push(json!({
            "bufferView": view,
            "componentType": UNSIGNED_INT,
            "count": idx.len(),
            "type": "SCALAR",
        }));
        self.accessors.len() - 1
    }
}

fn clamp01(x: f32, default: f32) -> f32 {
    if x.is_nan() {
        default
    } else {
        x.clamp(0.0, 1.0)
    }
}

/// `v` scaled to unit length, or `fallback` if it has no direction (glTF wants unit normals
/// and tangents).
fn unit_or(v: Vec3, fallback: Vec3) -> Vec3 {
    let u = v.normalize_or_zero();
    if u == Vec3::ZERO { fallback } else { u }
}

/// Serializes `scene` as a binary glTF 2.0 file. The bytes depend only on the input.
///
/// # Panics
/// On inconsistent input (a caller's bug, not a user's): per-vertex arrays of a length other
/// than `positions.len()`, more than 4 texcoord sets, a custom attribute name not starting
/// with `_`, an index count not a multiple of 3 or an index out of range, or a texture without
/// the texcoord set it uses.
pub fn write_glb(scene: &GlbMesh) -> Vec<u8> {
    let nv = scene.positions.len();
    assert!(
        scene.normals.is_empty() || scene.normals.len() == nv,
        "normals: wrong length"
    );
    assert!(
        scene.tangents.is_empty() || scene.tangents.len() == nv,
        "tangents: wrong length"
    );
    assert!(scene.texcoords.len() <= 4, "at most 4 texcoord sets");
    for (k, t) in scene.texcoords.iter().enumerate() {
        assert_eq!(t.len(), nv, "TEXCOORD_{k}: wrong length");
    }
    if let Some(c) = &scene.colors {
        assert_eq!(c.len(), nv, "colors: wrong length");
    }
    for a in &scene.extra {
        assert!(
            a.name.starts_with('_'),
            "custom attribute {:?} must start with '_'",
            a.name
        );
        assert_eq!(a.values.len(), nv, "{}: wrong length", a.name);
    }
    let primitives: Vec<(&[u32], &GlbMaterial)> =
        std::iter::once((scene.indices.as_slice(), &scene.material))
            .chain(
                scene
                    .more_primitives
                    .iter()
                    .map(|p| (p.indices.as_slice(), &p.material)),
            )
            .filter(|(idx, _)| !idx.is_empty())
            .collect();
    for (indices, mat) in &primitives {
        assert!(
            indices.len().is_multiple_of(3),
            "indices: not a triangle list"
        );
        assert!(
            indices.iter().all(|&i| (i as usize) < nv),
            "index out of range"
        );
        let textured = mat.base_color_png.is_some()
            || mat.normal_png.is_some()
            || mat.metallic_roughness_png.is_some();
        assert!(
            !textured || (mat.texcoord as usize) < scene.texcoords.len(),
            "textures use TEXCOORD_{} which is missing",
            mat.texcoord
        );
    }

    // The BIN chunk's size (with its padding), and room for the header and JSON that go in
    // front of it at the end, so that neither the chunk nor the file is ever regrown.
    let per_vertex = 12
        + 12 * usize::from(!scene.normals.is_empty())
        + 16 * usize::from(!scene.tangents.is_empty())
        + 8 * scene.texcoords.len()
        + 16 * usize::from(scene.colors.is_some())
        + 12 * scene.extra.len();
    let pngs: usize = primitives
        .iter()
        .flat_map(|(_, m)| [&m.base_color_png, &m.normal_png, &m.metallic_roughness_png])
        .map(|png| png.as_ref().map_or(0, |b| b.len() + 3))
        .sum();
    let indices: usize = primitives.iter().map(|(i, _)| 4 * i.len()).sum();
    let mut b = Builder {
        bin: Vec::with_capacity(nv * per_vertex + indices + pngs + 64 * 4 + (256 << 10)),
        ..Default::default()
    };
    let mut root = Map::new();
    root.insert(
        "asset".into(),
        json!({ "version": "2.0", "generator": "texsyn" }),
    );
    root.insert("scene".into(), json!(0));
    root.insert("scenes".into(), json!([{ "nodes": [0] }]));
    let mut node = Map::new();
    if !scene.name.is_empty() {
        node.insert("name".into(), json!(scene.name));
    }

    // glTF forbids empty accessors: an empty mesh is a scene with one empty node.
    if nv > 0 && !primitives.is_empty() {
        node.insert("mesh".into(), json!(0));
        let mut attrs = Map::new();
        let pos = b.floats(&scene.positions, |p| p.to_array(), "VEC3", true);
        attrs.insert("POSITION".into(), json!(pos));
        if !scene.normals.is_empty() {
            let unit = |&n: &Vec3| unit_or(n, Vec3::Z).to_array();
            let nrm = b.floats(&scene.normals, unit, "VEC3", false);
            attrs.insert("NORMAL".into(), json!(nrm));
        }
        if !scene.tangents.is_empty() {
            let unit = |t: &Vec4| {
                let w = if t.w < 0.0 { -1.0 } else { 1.0 };
                unit_or(t.truncate(), Vec3::X).extend(w).to_array()
            };
            let tan = b.floats(&scene.tangents, unit, "VEC4", false);
            attrs.insert("TANGENT".into(), json!(tan));
        }
        for (k, t) in scene.texcoords.iter().enumerate() {
            let uv = b.floats(t, |p| p.to_array(), "VEC2", false);
            attrs.insert(format!("TEXCOORD_{k}"), json!(uv));
        }
        if let Some(c) = &scene.colors {
            let col = b.floats(c, |c| c.map(|x| clamp01(x, 0.0)), "VEC4", false);
            attrs.insert("COLOR_0".into(), json!(col));
        }
        for a in &scene.extra {
            let v = b.floats(&a.values, |p| p.to_array(), "VEC3", false);
            attrs.insert(a.name.clone(), json!(v));
        }
        let mut mesh = Map::new();
        if !scene.name.is_empty() {
            mesh.insert("name".into(), json!(scene.name));
        }
        let mut prims = Vec::new();
        let mut materials = Vec::new();
        let mut images = vec![];
        let mut textures = vec![];
        for (m, (indices, mat)) in primitives.iter().enumerate() {
            let indices = b.indices(indices);
            prims
                .push(json!({ "attributes": attrs, "indices": indices, "material": m, "mode": 4 }));
            // The material and its embedded textures.
            let mut texture = |png: &Option<Vec<u8>>, b: &mut Builder| {
                png.as_ref().map(|bytes| {
                    let view = b.view(bytes, None);
                    images.push(json!({ "bufferView": view, "mimeType": "image/png" }));
                    textures.push(json!({ "source": images.len() - 1, "sampler": 0 }));
                    json!({ "index": textures.len() - 1, "texCoord": mat.texcoord })
                })
            };
            let base = texture(&mat.base_color_png, &mut b);
            let normal = texture(&mat.normal_png, &mut b);
            let mr = texture(&mat.metallic_roughness_png, &mut b);
            let mut pbr = Map::new();
            pbr.insert(
                "baseColorFactor".into(),
                json!(mat.base_color_factor.map(|x| clamp01(x, 1.0))),
            );
            pbr.insert("metallicFactor".into(), json!(clamp01(mat.metallic, 0.0)));
            pbr.insert("roughnessFactor".into(), json!(clamp01(mat.roughness, 1.0)));
            if let Some(t) = base {
                pbr.insert("baseColorTexture".into(), t);
            }
            if let Some(t) = mr {
                pbr.insert("metallicRoughnessTexture".into(), t);
            }
            let mut mm = Map::new();
            mm.insert("name".into(), json!(mat.name));
            mm.insert("pbrMetallicRoughness".into(), Value::Object(pbr));
            if let Some(t) = normal {
                mm.insert("normalTexture".into(), t);
            }
            mm.insert("doubleSided".into(), json!(mat.double_sided));
            materials.push(Value::Object(mm));
        }
        mesh.insert("primitives".into(), json!(prims));
        root.insert("meshes".into(), json!([mesh]));
        root.insert("materials".into(), json!(materials));
        if !images.is_empty() {
            root.insert("images".into(), json!(images));
            root.insert("textures".into(), json!(textures));
            // Trilinear, clamped: atlases are not tiling textures.
            root.insert(
                "samplers".into(),
                json!([{ "magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071 }]),
            );
        }
    }
    root.insert("nodes".into(), json!([node]));

    while !b.bin.len().is_multiple_of(4) {
        b.bin.push(0);
    }
    if !b.views.is_empty() {
        root.insert("accessors".into(), json!(b.accessors));
        root.insert("bufferViews".into(), json!(b.views));
        root.insert("buffers".into(), json!([{ "byteLength": b.bin.len() }]));
    }
    let mut json_bytes = serde_json::to_vec(&Value::Object(root)).expect("JSON values serialize");
    while !json_bytes.len().is_multiple_of(4) {
        json_bytes.push(b' ');
    }

    let has_bin = !b.bin.is_empty();
    let total = 12 + 8 + json_bytes.len() + if has_bin { 8 + b.bin.len() } else { 0 };
    let mut head = Vec::with_capacity(total - b.bin.len());
    head.extend_from_slice(&GLB_MAGIC.to_le_bytes());
    head.extend_from_slice(&2u32.to_le_bytes());
    head.extend_from_slice(&(total as u32).to_le_bytes());
    head.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
    head.extend_from_slice(&CHUNK_JSON.to_le_bytes());
    head.extend_from_slice(&json_bytes);
    if !has_bin {
        return head;
    }
    head.extend_from_slice(&(b.bin.len() as u32).to_le_bytes());
    head.extend_from_slice(&CHUNK_BIN.to_le_bytes());
    // The chunk moves up within its own buffer (reserved with room for this) rather than
    // being copied into a new one.
    let mut out = b.bin;
    out.splice(0..0, head);
    debug_assert_eq!(out.len(), total);
    out
}

/// The sample mesh of the tests and of the `sample_glb` example (which includes the file).
#[cfg(test)]
mod sample;

#[cfg(test)]
pub(crate) mod tests {
    use super::sample::sample_mesh;
    use super::*;

    #[test]
    fn vertex_coloured_meshes_carry_linear_colours_of_every_vertex() {
        let mesh = crate::geom::Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
        let srgb = [[0.5, 0.0, 1.0, 0.3], [1.0; 4], [0.0; 4]];
        let g = GlbMesh::vertex_coloured("m", &mesh, &srgb);
        let colours = g.colors.as_ref().unwrap();
        assert_eq!(colours.len(), 3);
        // sRGB 0.5 is linear 0.2140; alpha is opaque whatever it was.
        assert!((colours[0][0] - 0.2140).abs() < 1e-3, "{:?}", colours[0]);
        assert_eq!(&colours[0][1..], &[0.0, 1.0, 1.0]);
        assert_eq!((colours[1], colours[2]), ([1.0; 4], [0.0, 0.0, 0.0, 1.0]));
        assert_eq!((g.positions.len(), g.normals.len()), (3, 3));
        assert_eq!(g.indices, [0, 1, 2]);
        assert!(g.material.double_sided && g.material.base_color_png.is_none());
    }

    fn u32_at(b: &[u8], o: usize) -> u32 {
        u32::from_le_bytes(b[o..o + 4].try_into().unwrap())
    }

    /// Splits a GLB into (JSON, BIN) after checking the header and chunk framing.
    pub(crate) fn parse_glb(b: &[u8]) -> (Value, Vec<u8>) {
        assert_eq!(&b[0..4], b"glTF");
        assert_eq!(u32_at(b, 4), 2);
        assert_eq!(u32_at(b, 8) as usize, b.len());
        let jlen = u32_at(b, 12) as usize;
        assert_eq!(&b[16..20], b"JSON");
        assert_eq!(jlen % 4, 0);
        let json_bytes = &b[20..20 + jlen];
        let text = std::str::from_utf8(json_bytes).unwrap();
        // Padding: fewer than 4 spaces.
        let trimmed = text.trim_end_matches(' ');
        assert!(jlen - trimmed.len() < 4);
        let json: Value = serde_json::from_str(trimmed).unwrap();
        let rest = &b[20 + jlen..];
        if rest.is_empty() {
            return (json, vec![]);
        }
        let blen = u32_at(rest, 0) as usize;
        assert_eq!(&rest[4..8], b"BIN\0");
        assert_eq!(blen % 4, 0);
        assert_eq!(rest.len(), 8 + blen, "trailing bytes after BIN");
        (json, rest[8..].to_vec())
    }

    fn floats(bin: &[u8], off: usize, n: usize) -> Vec<f32> {
        (0..n)
            .map(|i| f32::from_le_bytes(bin[off + 4 * i..off + 4 * i + 4].try_into().unwrap()))
            .collect()
    }

    #[test]
    fn glb_chunks_accessors_and_views_are_consistent_with_the_input() {
        let m = sample_mesh();
        let bytes = write_glb(&m);
        let (json, bin) = parse_glb(&bytes);
        assert_eq!(json["asset"]["version"], "2.0");
        assert_eq!(json["asset"]["generator"], "texsyn");
        let buffer_len = json["buffers"][0]["byteLength"].as_u64().unwrap() as usize;
        assert!(buffer_len <= bin.len() && bin.len() - buffer_len < 4);
        assert!(bin[buffer_len..].iter().all(|&z| z == 0));
        let views = json["bufferViews"].as_array().unwrap();
        let accessors = json["accessors"].as_array().unwrap();
        for v in views {
            let (off, len) = (
                v["byteOffset"].as_u64().unwrap() as usize,
                v["byteLength"].as_u64().unwrap() as usize,
            );
            assert_eq!(off % 4, 0, "unaligned view {v}");
            assert!(off + len <= buffer_len);
        }
        let comps = |t: &str| match t {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            _ => panic!("{t}"),
        };
        for a in accessors {
            let v = &views[a["bufferView"].as_u64().unwrap() as usize];
            let n = a["count"].as_u64().unwrap() as usize * comps(a["type"].as_str().unwrap()) * 4;
            assert_eq!(
                v["byteLength"].as_u64().unwrap() as usize,
                n,
                "accessor {a}"
            );
        }
        let prim = &json["meshes"][0]["primitives"][0];
        let attr = |name: &str| &accessors[prim["attributes"][name].as_u64().unwrap() as usize];
        let nv = m.positions.len() as u64;
        for name in [
            "POSITION",
            "NORMAL",
            "TANGENT",
            "TEXCOORD_0",
            "TEXCOORD_1",
            "COLOR_0",
            "_DISPLACEMENT",
        ] {
            assert_eq!(attr(name)["count"].as_u64().unwrap(), nv, "{name}");
        }
        // POSITION data and bounds, read back from BIN.
        let pos = attr("POSITION");
        let view = &views[pos["bufferView"].as_u64().unwrap() as usize];
        let data = floats(
            &bin,
            view["byteOffset"].as_u64().unwrap() as usize,
            m.positions.len() * 3,
        );
        let want: Vec<f32> = m.positions.iter().flat_map(|p| p.to_array()).collect();
        assert_eq!(data, want);
        assert_eq!(pos["min"], json!([0.0, 0.0, -4.5]));
        assert_eq!(pos["max"], json!([2.0, 3.0, 0.0]));
        // Indices.
        let ia = &accessors[prim["indices"].as_u64().unwrap() as usize];
        assert_eq!(ia["componentType"], 5125);
        assert_eq!(ia["count"].as_u64().unwrap() as usize, m.indices.len());
        // Images: the exact PNG bytes, in their own views.
        let mat = &json["materials"][0];
        assert_eq!(mat["doubleSided"], true);
        let tex_png = |t: &Value| {
            let tex = &json["textures"][t["index"].as_u64().unwrap() as usize];
            let img = &json["images"][tex["source"].as_u64().unwrap() as usize];
            assert_eq!(img["mimeType"], "image/png");
            let v = &views[img["bufferView"].as_u64().unwrap() as usize];
            let off = v["byteOffset"].as_u64().unwrap() as usize;
            bin[off..off + v["byteLength"].as_u64().unwrap() as usize].to_vec()
        };
        assert_eq!(
            Some(tex_png(&mat["pbrMetallicRoughness"]["baseColorTexture"])),
            m.material.base_color_png
        );
        assert_eq!(Some(tex_png(&mat["normalTexture"])), m.material.normal_png);
        assert_eq!(
            Some(tex_png(
                &mat["pbrMetallicRoughness"]["metallicRoughnessTexture"]
            )),
            m.material.metallic_roughness_png
        );
        assert_eq!(
            mat["pbrMetallicRoughness"]["roughnessFactor"]
                .as_f64()
                .unwrap() as f32,
            0.8
        );
        // Deterministic.
        assert_eq!(bytes, write_glb(&m));
    }

    #[test]
    fn empty_mesh_is_a_valid_scene_without_buffers() {
        let bytes = write_glb(&GlbMesh::default());
        let (json, bin) = parse_glb(&bytes);
        assert!(bin.is_empty());
        assert!(json.get("accessors").is_none() && json.get("meshes").is_none());
        assert_eq!(json["nodes"].as_array().unwrap().len(), 1);
    }

    #[test]
    #[should_panic(expected = "must start with '_'")]
    fn custom_attribute_names_are_checked() {
        let mut m = sample_mesh();
        m.extra[0].name = "DISPLACEMENT".into();
        write_glb(&m);
    }
}
