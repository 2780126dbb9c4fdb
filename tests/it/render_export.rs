//! End-to-end checks of the preview renderer, the atlas baker and the exporters working
//! together through files, as the `render` command and the reconstruct stage use them.

use glam::{Vec2, Vec3};
use std::path::Path;
use texsyn::export::{GlbMesh, MtlMaps, write_glb, write_mtl, write_obj};
use texsyn::geom::Mesh;
use texsyn::geom::primitives::{cuboid, uv_quad};
use texsyn::image::{Image, decode_image};
use texsyn::render::{
    ConstantShader, RenderError, SurfaceShader, ViewOptions, bake, build_atlas, render_mesh_file,
    render_views,
};

const BG: [u8; 3] = [235, 236, 240];

/// Quadrant colours of the test texture (8-bit): top left, top right, bottom left, bottom right.
const QUADRANTS: [[u8; 3]; 4] = [[200, 30, 30], [30, 180, 50], [40, 50, 230], [230, 220, 30]];

fn quadrant_png() -> Vec<u8> {
    let img = image::RgbImage::from_fn(16, 16, |x, y| {
        image::Rgb(QUADRANTS[(x >= 8) as usize + 2 * (y >= 8) as usize])
    });
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// Bounding box of the non-background pixels of view `v`.
fn foreground_box(img: &image::RgbaImage, v: u32) -> Option<(u32, u32, u32, u32)> {
    let s = img.height();
    let mut b: Option<(u32, u32, u32, u32)> = None;
    for y in 0..s {
        for x in 0..s {
            if img.get_pixel(v * s + x, y).0[..3] != BG {
                let (x0, y0, x1, y1) = b.unwrap_or((x, y, x, y));
                b = Some((x0.min(x), y0.min(y), x1.max(x), y1.max(y)));
            }
        }
    }
    b
}

fn close(a: [u8; 4], b: [u8; 3], tol: i32) -> bool {
    (0..3).all(|k| (a[k] as i32 - b[k] as i32).abs() <= tol)
}

/// Views `size` pixels high that show the surface's colours as they are (no lighting).
fn unlit(size: u32) -> ViewOptions {
    ViewOptions {
        size,
        lit: false,
        ..ViewOptions::default()
    }
}

/// The colour at the centre of the first view of an unlit 64-pixel render of the mesh file
/// `path` (no texture).
fn centre_colour(path: &Path) -> [u8; 4] {
    let img = render_mesh_file(path, None, &unlit(64)).unwrap();
    let (x0, y0, x1, y1) = foreground_box(&img, 0).unwrap();
    img.get_pixel((x0 + x1) / 2, (y0 + y1) / 2).0
}

#[test]
fn render_command_shows_an_obj_texture_upright_through_its_uvs() {
    let dir = tempfile::tempdir().unwrap();
    let (mesh, corner_uv) = uv_quad();
    let obj = dir.path().join("quad.obj");
    let png = dir.path().join("quad.png");
    std::fs::write(&obj, write_obj(&mesh, Some(&corner_uv), None, "m")).unwrap();
    std::fs::write(&png, quadrant_png()).unwrap();
    let img = render_mesh_file(&obj, Some(&png), &unlit(128)).unwrap();
    assert_eq!(img.dimensions(), (384, 128));
    let (x0, y0, x1, y1) = foreground_box(&img, 0).unwrap();
    let (w, h) = (x1 - x0 + 1, y1 - y0 + 1);
    assert!(w > 80 && w.abs_diff(h) <= 1);
    for (q, (fx, fy)) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)]
        .into_iter()
        .enumerate()
    {
        let p = img
            .get_pixel(x0 + (fx * w as f32) as u32, y0 + (fy * h as f32) as u32)
            .0;
        assert!(
            close(p, QUADRANTS[q], 1),
            "quadrant {q}: {p:?} vs {:?}",
            QUADRANTS[q]
        );
    }
}

/// A 4×4 PNG of one colour.
fn solid_png(c: [u8; 3]) -> Vec<u8> {
    let img = image::RgbImage::from_pixel(4, 4, image::Rgb(c));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// Pixels of the first view within 1 of colour `c`.
fn count_close(img: &image::RgbaImage, c: [u8; 3]) -> usize {
    let s = img.height();
    (0..s)
        .flat_map(|y| (0..s).map(move |x| (x, y)))
        .filter(|&(x, y)| close(img.get_pixel(x, y).0, c, 1))
        .count()
}

#[test]
fn render_command_shows_each_obj_material_page_without_a_texture_option() {
    // The quad's two triangles on two pages, as a baked atlas of two pages is written, but
    // with the OBJ naming the second material first (so its models are not in material order)
    // and the MTL and its pages in a subfolder (images are relative to the MTL).
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("paged.obj");
    std::fs::write(
        &obj,
        "mtllib mats/paged.mtl\n\
         v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n\
         vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
         usemtl page1\nf 1/1 2/2 3/3\n\
         usemtl page0\nf 1/1 3/3 4/4\n",
    )
    .unwrap();
    let mats = dir.path().join("mats");
    std::fs::create_dir(&mats).unwrap();
    let page = |name: &str, file: &str| {
        let maps = MtlMaps {
            diffuse: Some(file.into()),
            ..MtlMaps::default()
        };
        write_mtl(name, &maps)
    };
    let mtl = page("page0", "page0.png") + &page("page1", "page1.png");
    std::fs::write(mats.join("paged.mtl"), mtl).unwrap();
    let (red, blue) = ([200, 30, 30], [40, 50, 230]);
    std::fs::write(mats.join("page0.png"), solid_png(red)).unwrap();
    std::fs::write(mats.join("page1.png"), solid_png(blue)).unwrap();

    // The view shows x right and y up: the first triangle (page1, blue) is the lower right
    // half, the second (page0, red) the upper left.
    let img = render_mesh_file(&obj, None, &unlit(96)).unwrap();
    let (x0, y0, x1, y1) = foreground_box(&img, 0).unwrap();
    let at = |fx: f32, fy: f32| {
        img.get_pixel(
            x0 + (fx * (x1 - x0) as f32) as u32,
            y0 + (fy * (y1 - y0) as f32) as u32,
        )
        .0
    };
    assert!(
        close(at(0.8, 0.8), blue, 1),
        "lower right {:?}",
        at(0.8, 0.8)
    );
    assert!(close(at(0.2, 0.2), red, 1), "upper left {:?}", at(0.2, 0.2));
    let area = ((x1 - x0 + 1) * (y1 - y0 + 1)) as usize;
    let (r, b) = (count_close(&img, red), count_close(&img, blue));
    assert!(r + b > area * 9 / 10, "red {r} + blue {b} of {area}");

    // An explicit texture still wins over the materials.
    let green = [30, 180, 50];
    let png = dir.path().join("green.png");
    std::fs::write(&png, solid_png(green)).unwrap();
    let img = render_mesh_file(&obj, Some(&png), &unlit(96)).unwrap();
    assert_eq!(count_close(&img, red) + count_close(&img, blue), 0);
    assert!(count_close(&img, green) > area * 9 / 10);

    // A missing page is a warning: that triangle takes its material's Kd (white), the other
    // keeps its page; with no page left both are white. A missing MTL renders grey.
    let white = [255, 255, 255];
    std::fs::remove_file(mats.join("page1.png")).unwrap();
    let img = render_mesh_file(&obj, None, &unlit(96)).unwrap();
    assert!(count_close(&img, red) > area * 4 / 10);
    assert_eq!(count_close(&img, blue), 0);
    assert!(count_close(&img, white) > area * 4 / 10);
    std::fs::remove_file(mats.join("page0.png")).unwrap();
    let img = render_mesh_file(&obj, None, &unlit(96)).unwrap();
    assert!(count_close(&img, white) > area * 9 / 10);
    std::fs::remove_file(mats.join("paged.mtl")).unwrap();
    let img = render_mesh_file(&obj, None, &unlit(96)).unwrap();
    assert_eq!(count_close(&img, white), 0);
    assert_eq!(count_close(&img, red), 0);
}

#[test]
fn render_command_uses_obj_vertex_colours_and_names_missing_files() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("coloured.obj");
    std::fs::write(
        &obj,
        "v -1 -1 0 0.2 0.4 0.8\nv 1 -1 0 0.2 0.4 0.8\nv 1 1 0 0.2 0.4 0.8\nv -1 1 0 0.2 0.4 0.8\n\
         f 1 2 3 4\n",
    )
    .unwrap();
    let p = centre_colour(&obj);
    assert!(close(p, [51, 102, 204], 1), "{p:?}");

    let opts = unlit(64);
    let missing = dir.path().join("nope.obj");
    let e = render_mesh_file(&missing, None, &opts).unwrap_err();
    assert!(matches!(e, RenderError::Io { .. }));
    assert!(e.to_string().contains("nope.obj"), "{e}");
    let e = render_mesh_file(&obj, Some(&dir.path().join("tex.png")), &opts).unwrap_err();
    assert!(e.to_string().contains("tex.png"), "{e}");
    let bad = ViewOptions {
        size: 0,
        ..ViewOptions::default()
    };
    assert!(render_mesh_file(&obj, None, &bad).is_err());
}

#[test]
fn render_refuses_the_obj_files_run_refuses_with_the_same_words() {
    // tobj alone accepts a two-vertex face and a coordinate of five million digits; `render`
    // reads through the pipeline's reader first, so both commands say the same.
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("two.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n".to_string()),
        (
            "huge.obj",
            format!(
                "v 0 0 0\nv 1 0 0\nv 0 1 {}\nf 1 2 3\n",
                "1".repeat(5_000_000)
            ),
        ),
    ];
    for (name, text) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let e = render_mesh_file(&path, None, &unlit(32)).unwrap_err();
        let want = texsyn::geom::io::read_mesh(&path).unwrap_err();
        assert_eq!(e.to_string(), want.to_string(), "{name}");
        assert!(e.to_string().contains(name), "{e}");
    }
}

#[test]
fn render_command_reads_other_formats_with_their_vertex_colours() {
    // COFF goes through geom::io::read_mesh; integer colours mean 0-255.
    let dir = tempfile::tempdir().unwrap();
    let off = dir.path().join("quad.off");
    std::fs::write(
        &off,
        "COFF\n4 2 0\n-1 -1 0 200 100 50 255\n1 -1 0 200 100 50 255\n1 1 0 200 100 50 255\n\
         -1 1 0 200 100 50 255\n3 0 1 2\n3 0 2 3\n",
    )
    .unwrap();
    let p = centre_colour(&off);
    assert!(close(p, [200, 100, 50], 1), "{p:?}");
}

#[test]
fn cow_renders_in_all_three_views() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/assets/cow.obj");
    let img = render_mesh_file(
        &path,
        None,
        &ViewOptions {
            size: 128,
            ..ViewOptions::default()
        },
    )
    .unwrap();
    for v in 0..3 {
        let (x0, y0, x1, y1) = foreground_box(&img, v).unwrap();
        // Fitted: the cow fills a good part of each view, with a margin.
        assert!(x1 - x0 > 60 || y1 - y0 > 60, "view {v}");
        assert!(
            x0 > 0 && y0 > 0 && x1 < 127 && y1 < 127,
            "view {v} touches the border"
        );
    }
}

#[test]
fn obj_and_mtl_files_read_back_with_tobj() {
    let dir = tempfile::tempdir().unwrap();
    let (mesh, corner_uv) = uv_quad();
    let maps = MtlMaps {
        diffuse: Some("albedo.png".into()),
        normal: Some("normal.png".into()),
        ..MtlMaps::default()
    };
    std::fs::write(dir.path().join("q.mtl"), write_mtl("synth", &maps)).unwrap();
    std::fs::write(
        dir.path().join("q.obj"),
        write_obj(&mesh, Some(&corner_uv), Some("q.mtl"), "synth"),
    )
    .unwrap();
    let (models, materials) = tobj::load_obj(
        dir.path().join("q.obj"),
        &tobj::LoadOptions {
            triangulate: true,
            ..Default::default()
        },
    )
    .unwrap();
    let materials = materials.unwrap();
    assert_eq!(materials.len(), 1);
    assert_eq!(materials[0].name, "synth");
    assert_eq!(materials[0].diffuse_texture.as_deref(), Some("albedo.png"));
    assert_eq!(materials[0].normal_texture.as_deref(), Some("normal.png"));
    let m = &models[0].mesh;
    assert_eq!(m.material_id, Some(0));
    assert_eq!(m.indices.len(), 6);
    for (f, (tri, fuv)) in mesh.triangles.iter().zip(&corner_uv).enumerate() {
        for k in 0..3 {
            let vi = m.indices[3 * f + k] as usize;
            let p = Vec3::from_slice(&m.positions[3 * vi..3 * vi + 3]);
            assert_eq!(p, mesh.positions[tri[k] as usize]);
            let ti = m.texcoord_indices[3 * f + k] as usize;
            assert_eq!(Vec2::from_slice(&m.texcoords[2 * ti..2 * ti + 2]), fuv[k]);
        }
    }
}

/// Colour by position: a 3D checker, so a correct bake + uv mapping must bring each surface
/// point its own colour back.
struct Checker<'a>(&'a Mesh);
impl SurfaceShader for Checker<'_> {
    fn albedo(&self, f: usize, b: Vec3) -> Vec3 {
        let t = self.0.triangles[f];
        let p = self.0.positions[t[0] as usize] * b.x
            + self.0.positions[t[1] as usize] * b.y
            + self.0.positions[t[2] as usize] * b.z;
        let k = (p * 3.0 + 0.5).floor();
        if (k.x + k.y + k.z) as i64 % 2 == 0 {
            Vec3::new(0.8, 0.2, 0.1)
        } else {
            Vec3::new(0.9, 0.9, 0.8)
        }
    }
}

/// The closed box [-1, 1]³: the core's cuboid, centred on the origin.
fn cube() -> Mesh {
    let c = cuboid(Vec3::splat(2.0));
    Mesh::new(c.positions.iter().map(|&p| p - 1.0).collect(), c.triangles)
}

#[test]
fn a_baked_atlas_renders_like_the_shader_it_was_baked_from() {
    let mesh = cube();
    let atlas = build_atlas(&mesh, 512).unwrap();
    let baked = bake(&atlas, &mesh, &Checker(&mesh));
    let tex = Image {
        width: 512,
        height: 512,
        pixels: baked
            .pixels()
            .map(|p| p.0.map(|c| c as f32 / 255.0))
            .collect(),
    };
    let obj_uv: Vec<[Vec2; 3]> = atlas
        .corner_uv
        .iter()
        .map(|c| c.map(texsyn::image::uv_for_gltf))
        .collect();
    let opts = ViewOptions {
        size: 128,
        ..ViewOptions::default()
    };
    let direct = render_views(&mesh, &Checker(&mesh), &opts);
    let via_atlas = render_views(
        &mesh,
        &texsyn::render::CornerUvShader::new(&obj_uv, tex.view()),
        &opts,
    );
    // Identical except next to checker boundaries (resampled through texels there): every
    // pixel whose 3x3 neighbourhood is uniform in the direct render must match.
    let (w, h) = direct.dimensions();
    let mut checked = 0;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let c = direct.get_pixel(x, y).0;
            let uniform = (0..9).all(|k| {
                let q = direct.get_pixel(x + k % 3 - 1, y + k / 3 - 1).0;
                (0..3).all(|i| (q[i] as i32 - c[i] as i32).abs() <= 2)
            });
            if uniform && c[..3] != BG {
                let a = via_atlas.get_pixel(x, y).0;
                assert!(
                    close(a, [c[0], c[1], c[2]], 3),
                    "pixel ({x}, {y}): {a:?} vs {c:?}"
                );
                checked += 1;
            }
        }
    }
    assert!(
        checked > (w * h / 4) as usize,
        "only {checked} pixels compared"
    );
    // And the grey cube is not what we compare against by accident.
    let grey = render_views(&mesh, &ConstantShader(Vec3::splat(0.5)), &opts);
    assert_ne!(grey.as_raw(), via_atlas.as_raw());
}

#[test]
fn glb_of_a_baked_mesh_carries_its_texture_and_uvs() {
    let mesh = cube();
    let atlas = build_atlas(&mesh, 128).unwrap();
    let baked = bake(&atlas, &mesh, &Checker(&mesh));
    let mut png = std::io::Cursor::new(Vec::new());
    baked.write_to(&mut png, image::ImageFormat::Png).unwrap();
    let png = png.into_inner();
    let mut g = GlbMesh::default();
    let mut uv = vec![];
    for (f, t) in mesh.triangles.iter().enumerate() {
        for (&v, &c) in t.iter().zip(&atlas.corner_uv[f]) {
            g.indices.push(g.positions.len() as u32);
            g.positions.push(mesh.positions[v as usize]);
            g.normals.push(mesh.vertex_normals()[v as usize]);
            uv.push(c);
        }
    }
    g.texcoords = vec![uv.clone()];
    g.material.base_color_png = Some(png.clone());
    let bytes = write_glb(&g);

    // Header and chunks.
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()) as usize;
    assert_eq!(&bytes[..4], b"glTF");
    assert_eq!(u32_at(4), 2);
    assert_eq!(u32_at(8), bytes.len());
    let jlen = u32_at(12);
    assert_eq!(&bytes[16..20], b"JSON");
    let json: serde_json::Value =
        serde_json::from_slice(bytes[20..20 + jlen].trim_ascii_end()).unwrap();
    let blen = u32_at(20 + jlen);
    assert_eq!(&bytes[24 + jlen..28 + jlen], b"BIN\0");
    assert_eq!(28 + jlen + blen, bytes.len());
    let bin = &bytes[28 + jlen..];

    // TEXCOORD_0 read back equals the atlas uvs; the image decodes to the baked texture.
    let acc = &json["accessors"];
    let views = &json["bufferViews"];
    let prim = &json["meshes"][0]["primitives"][0];
    let a = &acc[prim["attributes"]["TEXCOORD_0"].as_u64().unwrap() as usize];
    assert_eq!(a["count"].as_u64().unwrap() as usize, uv.len());
    let v = &views[a["bufferView"].as_u64().unwrap() as usize];
    let off = v["byteOffset"].as_u64().unwrap() as usize;
    assert_eq!(v["byteLength"].as_u64().unwrap() as usize, uv.len() * 8);
    for (i, want) in uv.iter().enumerate() {
        let x = f32::from_le_bytes(bin[off + 8 * i..off + 8 * i + 4].try_into().unwrap());
        let y = f32::from_le_bytes(bin[off + 8 * i + 4..off + 8 * i + 8].try_into().unwrap());
        assert_eq!(Vec2::new(x, y), *want);
    }
    let img = &json["images"][0];
    let v = &views[img["bufferView"].as_u64().unwrap() as usize];
    let off = v["byteOffset"].as_u64().unwrap() as usize;
    let len = v["byteLength"].as_u64().unwrap() as usize;
    let decoded = decode_image(Path::new("embedded.png"), &bin[off..off + len]).unwrap();
    assert_eq!(decoded.to_rgba8().as_raw(), baked.as_raw());
}
