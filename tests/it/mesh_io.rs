//! Mesh readers and the PLY writer on real files (tests/data/meshes, configs/assets) and on
//! hand-made good and bad inputs. Expected values come from the files themselves (read here by
//! deliberately naive code), from tobj, or are written out by hand.

use glam::Vec3;
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use texsyn::geom::Mesh;
use texsyn::geom::io::{Location, MeshError, read_mesh, read_mesh_bytes, write_ply};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/meshes")
        .join(name)
}

fn read(name: &str) -> Mesh {
    read_mesh(&data(name)).unwrap_or_else(|e| panic!("{e}"))
}

fn bytes(name: &str) -> Vec<u8> {
    std::fs::read(data(name)).unwrap()
}

fn parse(name: &str, bytes: &[u8]) -> Result<Mesh, MeshError> {
    read_mesh_bytes(Path::new(name), bytes)
}

/// The error message for a file that must be rejected, checked to name the file.
fn error(name: &str, bytes: &[u8]) -> String {
    match parse(name, bytes) {
        Ok(m) => panic!(
            "{name} was accepted ({} vertices, {} faces)",
            m.vertex_count(),
            m.face_count()
        ),
        Err(e) => {
            let message = e.to_string();
            assert!(
                message.starts_with(name),
                "message does not name the file: {message}"
            );
            message
        }
    }
}

fn assert_mentions(message: &str, parts: &[&str]) {
    for part in parts {
        assert!(
            message.to_lowercase().contains(&part.to_lowercase()),
            "message {message:?} does not mention {part:?}"
        );
    }
}

/// cow.off read with `split_whitespace`, independently of the crate.
fn naive_off(text: &str) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut t = text.split_whitespace();
    assert_eq!(t.next(), Some("OFF"));
    let mut num = || t.next().unwrap();
    let nv: usize = num().parse().unwrap();
    let nf: usize = num().parse().unwrap();
    num();
    let positions = (0..nv)
        .map(|_| [(); 3].map(|_| num().parse::<f32>().unwrap()))
        .collect();
    let faces = (0..nf)
        .map(|_| {
            assert_eq!(num(), "3");
            [(); 3].map(|_| num().parse::<u32>().unwrap())
        })
        .collect();
    (positions, faces)
}

fn arrays(positions: &[Vec3]) -> Vec<[f32; 3]> {
    positions.iter().map(|p| p.to_array()).collect()
}

// ---------------------------------------------------------------------------------------------
// Real files

#[test]
fn cactus_coff_reads_counts_positions_and_integer_colours() {
    let m = read("cactus.off");
    assert_eq!((m.vertex_count(), m.face_count()), (620, 1236));
    // First vertex line: "0.0687881 0.0462836 -0.0243483 192 192 192 255".
    assert_eq!(m.positions[0], Vec3::new(0.0687881, 0.0462836, -0.0243483));
    let colors = m.colors.as_ref().expect("COFF colours");
    assert_eq!(colors.len(), 620);
    let grey = 192.0 / 255.0;
    assert_eq!(colors[0], [grey, grey, grey, 1.0]);
}

#[test]
fn mushroom_open_off_reads_counts_and_file_numbering() {
    let m = read("mushroom.off");
    assert_eq!((m.vertex_count(), m.face_count()), (2337, 4608));
    assert!(m.colors.is_none());
    let (positions, faces) = naive_off(&String::from_utf8(bytes("mushroom.off")).unwrap());
    assert_eq!(arrays(&m.positions), positions);
    assert_eq!(m.triangles, faces);
    // Open: some edge is used by one face only.
    let mut edges = std::collections::HashMap::new();
    for t in &m.triangles {
        for k in 0..3 {
            let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
            *edges.entry((a, b)).or_insert(0) += 1;
        }
    }
    assert!(edges.values().any(|&n| n == 1));
}

#[test]
fn cow_off_and_cow_obj_give_identical_meshes() {
    let off = read("cow.off");
    let obj =
        read_mesh(&Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/assets/cow.obj")).unwrap();
    assert_eq!((off.vertex_count(), off.face_count()), (2904, 5804));
    assert_eq!(off.positions, obj.positions);
    assert_eq!(off.triangles, obj.triangles);
    let (positions, faces) = naive_off(&String::from_utf8(bytes("cow.off")).unwrap());
    assert_eq!(arrays(&off.positions), positions);
    assert_eq!(off.triangles, faces);
}

#[test]
fn cow_obj_matches_tobj_up_to_vertex_numbering() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/assets/cow.obj");
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let text = std::fs::read(&path).unwrap();
    let (models, _) = tobj::load_obj_buf(&mut &text[..], &options, |_: &Path| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .unwrap();
    // tobj renumbers vertices, so compare triangles as position triples, in file order.
    let mut expected = Vec::new();
    for model in &models {
        let p = &model.mesh.positions;
        for t in model.mesh.indices.chunks_exact(3) {
            expected.push([t[0], t[1], t[2]].map(|i| {
                let i = i as usize * 3;
                [p[i], p[i + 1], p[i + 2]]
            }));
        }
    }
    let m = read_mesh(&path).unwrap();
    let ours: Vec<[[f32; 3]; 3]> = m
        .triangles
        .iter()
        .map(|t| t.map(|v| m.positions[v as usize].to_array()))
        .collect();
    assert_eq!(ours.len(), 5804);
    assert_eq!(ours, expected);
}

#[test]
fn pig_binary_stl_welds_to_shared_vertices_in_first_seen_order() {
    let raw = bytes("pig.stl");
    let m = read("pig.stl");
    assert_eq!((m.vertex_count(), m.face_count()), (8642, 16848));
    // Every triangle's corners are the file's, in order; decode the records here.
    let f = |at: usize| f32::from_le_bytes(raw[at..at + 4].try_into().unwrap());
    for (i, t) in m.triangles.iter().enumerate() {
        for (c, &v) in t.iter().enumerate() {
            let at = 84 + 50 * i + 12 + 12 * c;
            let corner = Vec3::new(f(at), f(at + 4), f(at + 8));
            assert_eq!(m.positions[v as usize], corner, "triangle {i} corner {c}");
        }
    }
    // First-seen numbering: the first triangle's corners are vertices 0, 1, 2 and each new
    // vertex index is at most one more than the largest before it.
    assert_eq!(m.triangles[0], [0, 1, 2]);
    let mut next = 0;
    for &v in m.triangles.iter().flatten() {
        assert!(v <= next);
        next = next.max(v + 1);
    }
    // Welding by exact position: no two vertices coincide.
    let mut keys: Vec<[u32; 3]> = m
        .positions
        .iter()
        .map(|p| p.to_array().map(|x| (x + 0.0).to_bits()))
        .collect();
    keys.sort_unstable();
    keys.dedup();
    assert_eq!(keys.len(), 8642);
}

#[test]
fn binary_stl_whose_header_starts_with_solid_is_still_binary() {
    let mut raw = bytes("pig.stl");
    raw[..12].copy_from_slice(b"solid pig   ");
    let m = parse("pig.stl", &raw).unwrap();
    assert_eq!((m.vertex_count(), m.face_count()), (8642, 16848));
}

#[test]
fn ascii_stl_welds_negative_zero_with_zero() {
    let m = read("tetra_ascii.stl");
    // Facets (0 2 1), (0 1 3), (0 3 2), (1 2 3) of p0 = origin, p1 = x, p2 = y, p3 = z; the
    // origin is spelled -0.0 in facets 1 and 3.
    assert_eq!(
        m.positions,
        vec![Vec3::ZERO, Vec3::Y, Vec3::X, Vec3::Z],
        "vertices in first-seen order"
    );
    assert_eq!(
        m.triangles,
        vec![[0, 1, 2], [0, 2, 3], [0, 3, 1], [2, 1, 3]]
    );
}

// ---------------------------------------------------------------------------------------------
// PLY

/// The cube written by tests/data/meshes/make_test_meshes.py.
fn cube_positions() -> Vec<Vec3> {
    let corners = [
        [0., 0., 0.],
        [1., 0., 0.],
        [1., 1., 0.],
        [0., 1., 0.],
        [0., 0., 1.],
        [1., 0., 1.],
        [1., 1., 1.],
        [0., 1., 1.],
        [3., 3., 3.],
    ];
    corners
        .iter()
        .map(|c| Vec3::from(*c) * 0.5 - 1.25)
        .collect()
}

fn cube_triangles() -> Vec<[u32; 3]> {
    let quads = [
        [0, 3, 2, 1],
        [4, 5, 6, 7],
        [0, 1, 5, 4],
        [1, 2, 6, 5],
        [2, 3, 7, 6],
        [3, 0, 4, 7],
    ];
    quads
        .iter()
        .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
        .collect()
}

fn cube_colors() -> Vec<[f32; 4]> {
    (0..9)
        .map(|i| {
            let alpha = if i % 2 == 0 { 255 } else { 128 };
            [i * 30, 255 - i * 20, 7 * i, alpha].map(|c| c as f32 / 255.0)
        })
        .collect()
}

#[test]
fn ply_cube_reads_the_same_in_ascii_little_and_big_endian() {
    for name in ["cube_ascii.ply", "cube_le.ply", "cube_be.ply"] {
        let m = read(name);
        // Vertex 8 is not used by any face and must stay.
        assert_eq!(m.positions, cube_positions(), "{name}");
        assert_eq!(m.triangles, cube_triangles(), "{name}");
        let colors = m
            .colors
            .as_ref()
            .unwrap_or_else(|| panic!("{name}: no colours"));
        for (got, want) in colors.iter().zip(cube_colors()) {
            for k in 0..4 {
                assert!(
                    (got[k] - want[k]).abs() < 1e-6,
                    "{name}: {got:?} vs {want:?}"
                );
            }
        }
    }
}

/// Builds a binary PLY of cow.off by hand: `big_endian` uses double coordinates and
/// `uint` indices with an extra per-face property, little endian float and `int`.
fn cow_ply(big_endian: bool) -> (Vec<u8>, usize) {
    let (positions, faces) = naive_off(&String::from_utf8(bytes("cow.off")).unwrap());
    let (format, coord, index) = if big_endian {
        ("binary_big_endian", "double", "uint")
    } else {
        ("binary_little_endian", "float", "int")
    };
    let mut out = format!(
        "ply\nformat {format} 1.0\nelement vertex {}\nproperty {coord} x\nproperty {coord} y\n\
         property {coord} z\nelement face {}\nproperty list uchar {index} vertex_indices\n\
         property short flags\nend_header\n",
        positions.len(),
        faces.len()
    )
    .into_bytes();
    let header = out.len();
    for p in &positions {
        for &x in p {
            if big_endian {
                out.extend_from_slice(&(x as f64).to_be_bytes());
            } else {
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
    }
    for f in &faces {
        out.push(3);
        for &v in f {
            out.extend_from_slice(&if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        }
        out.extend_from_slice(&[0x7f, 0x01]);
    }
    (out, header)
}

#[test]
fn binary_ply_of_cow_matches_cow_off() {
    let (positions, faces) = naive_off(&String::from_utf8(bytes("cow.off")).unwrap());
    for big_endian in [false, true] {
        let (ply, _) = cow_ply(big_endian);
        let m = parse("cow.ply", &ply).unwrap();
        assert_eq!(arrays(&m.positions), positions, "big endian: {big_endian}");
        assert_eq!(m.triangles, faces, "big endian: {big_endian}");
        assert!(m.colors.is_none());
    }
}

#[test]
fn write_ply_round_trips_positions_triangles_and_colours() {
    let cactus = read("cactus.off");
    let colors: Vec<[f32; 4]> = (0..cactus.vertex_count())
        .map(|i| [i as f32 / 620.0, 1.0, 0.0, 0.5])
        .collect();
    let out = write_ply(&cactus, Some(&colors));
    let header = "ply\nformat binary_little_endian 1.0\ncomment texsyn\nelement vertex 620\n\
                  property float x\nproperty float y\nproperty float z\nproperty uchar red\n\
                  property uchar green\nproperty uchar blue\nproperty uchar alpha\n\
                  element face 1236\nproperty list uchar int vertex_indices\nend_header\n";
    assert!(out.starts_with(header.as_bytes()));
    assert_eq!(out.len(), header.len() + 620 * 16 + 1236 * 13);
    // Vertex 0: x as little-endian float, then the colour bytes.
    let v0 = &out[header.len()..header.len() + 16];
    assert_eq!(v0[..4], 0.0687881f32.to_le_bytes());
    assert_eq!(v0[12..], [0, 255, 0, 128]);

    let back = parse("back.ply", &out).unwrap();
    assert_eq!(back.positions, cactus.positions);
    assert_eq!(back.triangles, cactus.triangles);
    for (got, want) in back.colors.unwrap().iter().zip(&colors) {
        for k in 0..4 {
            assert!((got[k] - want[k]).abs() <= 0.5 / 255.0 + 1e-6);
        }
    }

    let plain = write_ply(&cactus, None);
    let header = header.replace(
        "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n",
        "",
    );
    assert!(plain.starts_with(header.as_bytes()));
    assert_eq!(plain.len(), header.len() + 620 * 12 + 1236 * 13);
    let back = parse("back.ply", &plain).unwrap();
    assert_eq!(back.positions, cactus.positions);
    assert_eq!(back.triangles, cactus.triangles);
    assert!(back.colors.is_none());
}

// ---------------------------------------------------------------------------------------------
// Small hand-made inputs

#[test]
fn off_variants_counts_on_header_comments_and_polygons() {
    // Counts on the header line, comments, a quad with a face colour after its indices.
    let m = parse(
        "a.off",
        b"OFF 4 1 0 # counts here\n# comment\n0 0 0\n1 0 0\n\n1 1 0 # c\n0 1 0\n4 0 1 2 3 255 0 0\n",
    )
    .unwrap();
    assert_eq!(m.vertex_count(), 4);
    assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    assert!(m.colors.is_none());

    // NOFF: the normals are skipped, not read as positions.
    let m = parse(
        "n.off",
        b"NOFF\n3 1 3\n1 2 3 0 0 1\n4 5 6 0 0 1\n7 8 9 0 0 1\n3 2 1 0\n",
    )
    .unwrap();
    assert_eq!(m.positions[1], Vec3::new(4.0, 5.0, 6.0));
    assert_eq!(m.triangles, vec![[2, 1, 0]]);

    // CNOFF with float RGBA and COFF with integer RGB (alpha defaults to 1).
    let m = parse(
        "cn.off",
        b"CNOFF\n3 1 0\n0 0 0 0 0 1 0.5 0.25 1 0.75\n1 0 0 0 0 1 0 0 0 1\n0 1 0 0 0 1 1 1 1 1\n3 0 1 2\n",
    )
    .unwrap();
    assert_eq!(m.positions[1], Vec3::X);
    assert_eq!(m.colors.unwrap()[0], [0.5, 0.25, 1.0, 0.75]);
    let m = parse(
        "c.off",
        b"COFF\n3 1 0\n0 0 0 255 0 51\n1 0 0 0 0 0\n0 1 0 1 1 1\n3 0 1 2\n",
    )
    .unwrap();
    let c = m.colors.unwrap();
    assert_eq!(c[0], [1.0, 0.0, 0.2, 1.0]);
    assert_eq!(c[2], [1.0 / 255.0, 1.0 / 255.0, 1.0 / 255.0, 1.0]);
}

#[test]
fn obj_groups_corner_forms_relative_indices_and_polygons() {
    let text = b"mtllib missing.mtl\no first\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 2 2\n\
                 vt 0 0\nvn 0 0 1\nusemtl nowhere\nf 1/1/1 2/1/1 3/1/1 4/1/1\ng second\n\
                 v 5 5 5\nf -6//1 -4//1 -3//1\nl 1 2\nf 1/1 2/1 5/1 3/1 4/1\n";
    let m = parse("m.OBJ", text).unwrap();
    // Vertex 5 (0-based) is used by no face but kept.
    assert_eq!(m.vertex_count(), 6);
    assert_eq!(m.positions[5], Vec3::splat(5.0));
    assert_eq!(
        m.triangles,
        vec![
            [0, 1, 2],
            [0, 2, 3],
            [0, 2, 3],
            [0, 1, 4],
            [0, 4, 2],
            [0, 2, 3]
        ]
    );
    assert!(m.colors.is_none());

    let m = parse(
        "c.obj",
        b"v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 0.5\nf 1 2 3\n",
    )
    .unwrap();
    assert_eq!(m.colors.unwrap()[2], [0.0, 0.0, 0.5, 1.0]);
}

#[test]
fn degenerate_faces_are_dropped_and_unreferenced_vertices_kept() {
    let m = parse(
        "d.off",
        b"OFF\n5 3 0\n0 0 0\n1 0 0\n0 1 0\n9 9 9\n0 0 1\n3 0 1 1\n3 0 1 2\n3 2 2 2\n",
    )
    .unwrap();
    assert_eq!(m.vertex_count(), 5);
    assert_eq!(m.triangles, vec![[0, 1, 2]]);

    let message = error(
        "d.off",
        b"OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 1\n3 2 2 0\n",
    );
    assert_mentions(&message, &["empty", "degenerate"]);
}

// ---------------------------------------------------------------------------------------------
// Bad inputs

#[test]
fn nan_and_infinite_coordinates_are_rejected_naming_the_place() {
    let m = error("bad.obj", b"# x\nv 0 0 0\nv 0 nan 0\nv 1 1 1\nf 1 2 3\n");
    assert_mentions(&m, &["line 3", "NaN", "'nan'"]);
    let m = error("bad.off", b"OFF\n3 1 0\n0 0 0\n1 inf 0\n0 1 0\n3 0 1 2\n");
    assert_mentions(&m, &["line 4", "infinite", "'inf'"]);
    let m = error(
        "bad.stl",
        b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex NaN 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid\n",
    );
    assert_mentions(&m, &["line 5", "NaN"]);
    let m = error(
        "bad.ply",
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 nan 0\n3 0 1 2\n",
    );
    assert_mentions(&m, &["line 12", "NaN"]);

    // Binary STL: triangle 5's second corner gets a NaN x.
    let mut raw = bytes("pig.stl");
    let at = 84 + 50 * 5 + 24;
    raw[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let m = error("pig.stl", &raw);
    assert_mentions(&m, &["triangle 5 (byte 334)", "NaN"]);

    // Binary PLY: vertex 7's y set to infinity.
    let (mut ply, header) = cow_ply(false);
    let at = header + 7 * 12 + 4;
    ply[at..at + 4].copy_from_slice(&f32::INFINITY.to_le_bytes());
    let m = error("cow.ply", &ply);
    assert_mentions(
        &m,
        &[&format!("vertex 7 (byte {})", header + 84), "infinite"],
    );
}

#[test]
fn vertex_indices_out_of_range_are_rejected_naming_the_place() {
    let m = error(
        "r.off",
        b"OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 3\n",
    );
    assert_mentions(&m, &["line 7", "index 3 out of range", "3 vertices"]);
    let m = error("r.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n");
    assert_mentions(&m, &["line 5", "index 4 out of range"]);
    let m = error("r.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
    assert_mentions(&m, &["line 4", "index 0"]);
    let m = error("r.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n");
    assert_mentions(&m, &["line 4", "index -4 out of range"]);

    // Binary PLY: face 100's second index set to the vertex count.
    let (mut ply, header) = cow_ply(false);
    let face = header + 2904 * 12 + 100 * 15;
    ply[face + 5..face + 9].copy_from_slice(&2904i32.to_le_bytes());
    let m = error("cow.ply", &ply);
    assert_mentions(
        &m,
        &[
            &format!("face 100 (byte {face})"),
            "index 2904 out of range",
        ],
    );
}

#[test]
fn truncated_binary_stl_names_the_triangle_and_byte() {
    let raw = bytes("pig.stl");
    let m = error("pig.stl", &raw[..84 + 50 * 100 + 20]);
    assert_mentions(
        &m,
        &["truncated", "triangle 100 (byte 5084)", "16848 triangles"],
    );
    let m = error("short.stl", &raw[..83]);
    assert_mentions(&m, &["truncated", "84-byte header"]);
}

#[test]
fn truncated_binary_ply_names_the_element_and_byte() {
    let (ply, header) = cow_ply(false);
    let face = header + 2904 * 12 + 300 * 15;
    let m = error("cow.ply", &ply[..face + 7]);
    assert_mentions(
        &m,
        &[
            "truncated",
            &format!("face 300 (byte {face})"),
            "declares 5804",
        ],
    );
    let (ply, header) = cow_ply(true);
    let m = error("cow.ply", &ply[..header + 24 * 10 + 3]);
    assert_mentions(
        &m,
        &["truncated", &format!("vertex 10 (byte {})", header + 240)],
    );
}

#[test]
fn text_files_ending_before_their_counts_are_rejected() {
    let m = error("t.off", b"OFF\n5 1 0\n0 0 0\n1 0 0\n0 1 0\n");
    assert_mentions(&m, &["line 5", "end of file", "3 of 5 vertices"]);
    let m = error("t.off", b"OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2");
    assert_mentions(&m, &["line 6", "end of file", "1 of 2 faces"]);
    let m = error(
        "t.ply",
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0\n",
    );
    assert_mentions(&m, &["truncated", "vertex 1", "line 9"]);
    let m = error(
        "t.stl",
        b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n",
    );
    assert_mentions(&m, &["line 2", "end of file"]);
}

#[test]
fn ascii_stl_facets_are_triangles_inside_an_outer_loop() {
    let facet = |corners: &str, outer: &str| {
        format!("solid s\nfacet normal 0 0 1\n{outer}\n{corners}endloop\nendfacet\nendsolid s\n")
    };
    let three = "vertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n";
    let four = "vertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\nvertex 0 1 0\n";
    assert!(parse("ok.stl", facet(three, "outer loop").as_bytes()).is_ok());
    let m = error("q.stl", facet(four, "outer loop").as_bytes());
    assert_mentions(&m, &["line 9", "4 vertices", "exactly 3"]);
    let m = error("o.stl", facet(three, "outer lop").as_bytes());
    assert_mentions(&m, &["line 3", "outer loop"]);
}

#[test]
fn empty_files_are_rejected_for_every_format() {
    for name in ["e.obj", "e.off", "e.ply", "e.stl"] {
        assert_mentions(&error(name, b""), &["empty"]);
        assert_mentions(&error(name, b"  \n\n"), &["empty"]);
    }
    // Well-formed but without faces.
    assert_mentions(
        &error("v.obj", b"v 0 0 0\nv 1 0 0\n"),
        &["empty mesh", "no faces"],
    );
    assert_mentions(&error("v.stl", b"solid x\nendsolid x\n"), &["empty mesh"]);
    assert_mentions(&error("v.off", b"OFF\n1 0 0\n0 0 0\n"), &["empty mesh"]);
}

#[test]
fn faces_of_two_vertices_are_unsupported() {
    let m = error("f.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n");
    assert_mentions(&m, &["line 6", "unsupported face size 2"]);
    let m = error("f.obj", b"v 0 0 0\nv 1 0 0\nf 1 2\n");
    assert_mentions(&m, &["line 3", "unsupported face size 2"]);
    let m = error(
        "f.ply",
        b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n2 0 1\n",
    );
    assert_mentions(&m, &["line 12", "unsupported face size 2"]);
}

#[test]
fn unknown_extensions_and_missing_files_are_rejected() {
    let e = parse("mesh.xyz", b"OFF\n").unwrap_err();
    assert!(matches!(e, MeshError::UnsupportedFormat { .. }));
    assert_mentions(&e.to_string(), &["mesh.xyz", "unsupported"]);
    let e = parse("noextension", b"OFF\n").unwrap_err();
    assert!(matches!(e, MeshError::UnsupportedFormat { .. }));

    let e = read_mesh(&data("does-not-exist.off")).unwrap_err();
    assert!(matches!(e, MeshError::Io { .. }));
    assert_mentions(&e.to_string(), &["does-not-exist.off"]);
}

#[test]
fn garbage_ply_headers_are_rejected_naming_the_line() {
    let m = error("g.ply", b"\x00\x01garbage\nmore\n");
    assert_mentions(&m, &["line 1", "not a PLY file"]);
    let m = error(
        "g.ply",
        b"ply\nformat binary_middle_endian 1.0\nend_header\n",
    );
    assert_mentions(&m, &["line 2", "unknown PLY format 'binary_middle_endian'"]);
    let m = error(
        "g.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
    );
    assert_mentions(&m, &["line 4", "unknown property type 'float128'"]);
    let m = error(
        "g.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",
    );
    assert_mentions(&m, &["end_header"]);
    let m = error(
        "g.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0 0\n",
    );
    assert_mentions(&m, &["line 6", "property 'z'"]);
    let m = error(
        "g.ply",
        b"ply\nformat ascii 1.0\nwhat is this\nend_header\n",
    );
    assert_mentions(&m, &["line 3", "'what'"]);
    // The location is structured, for callers that want it.
    let e = parse("g.ply", b"ply\nformat text 1.0\nend_header\n").unwrap_err();
    assert!(matches!(
        e,
        MeshError::Parse {
            location: Location::Line(2),
            ..
        }
    ));
}

#[test]
fn unparsable_numbers_are_rejected_quoting_the_token() {
    let m = error("u.obj", b"v 0 0 0\nv 1 0x1 0\n");
    assert_mentions(&m, &["line 2", "cannot parse '0x1'"]);
    let m = error("u.off", b"OFF\n3 one 0\n");
    assert_mentions(&m, &["line 2", "'one'"]);
    let m = error("u.off", b"4OFF\n");
    assert_mentions(&m, &["line 1", "unsupported OFF variant"]);
    let m = error("u.stl", b"solid\nfacet\nouter loop\nvertex 0 0 zero\n");
    assert_mentions(&m, &["line 4", "'zero'"]);
    let m = error(
        "u.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty uchar z\nend_header\n0 0 1.5\n",
    );
    assert_mentions(&m, &["line 8", "'1.5'"]);
}

// ---------------------------------------------------------------------------------------------
// No input makes a reader panic

const EXTENSIONS: [&str; 4] = ["x.obj", "x.off", "x.ply", "x.stl"];

fn seeds() -> Vec<(&'static str, Vec<u8>)> {
    let mut seeds = vec![
        (
            "x.off",
            b"COFF\n3 1 0\n0 0 0 1 2 3\n1 0 0 4 5 6\n0 1 0 7 8 9\n3 0 1 2\n".to_vec(),
        ),
        (
            "x.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2//3 -1\n".to_vec(),
        ),
        ("x.stl", bytes("tetra_ascii.stl")),
        ("x.ply", bytes("cube_ascii.ply")),
        ("x.ply", bytes("cube_le.ply")),
        ("x.ply", bytes("cube_be.ply")),
    ];
    let mut stl = bytes("pig.stl");
    stl.truncate(84 + 50 * 4);
    stl[80..84].copy_from_slice(&4u32.to_le_bytes());
    seeds.push(("x.stl", stl));
    seeds
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_bytes_never_panic(data in proptest::collection::vec(any::<u8>(), 0..600)) {
        for name in EXTENSIONS {
            let _ = parse(name, &data);
        }
    }

    #[test]
    fn random_bytes_after_a_valid_start_never_panic(
        start in 0usize..7,
        tail in proptest::collection::vec(any::<u8>(), 0..300),
    ) {
        let prefixes: [(&str, &[u8]); 7] = [
            ("x.off", b"OFF\n"),
            ("x.off", b"COFF 3 1 0\n"),
            ("x.obj", b"v 0 0 0\nf "),
            ("x.stl", b"solid x\nfacet normal 0 0 1\nouter loop\nvertex "),
            ("x.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"),
            ("x.ply", b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty list int double x\nproperty double x\nproperty double y\nproperty double z\nelement face 1\nproperty list uint uint vertex_index\nend_header\n"),
            ("x.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"),
        ];
        let (name, prefix) = prefixes[start];
        let mut data = prefix.to_vec();
        data.extend_from_slice(&tail);
        let _ = parse(name, &data);
    }

    #[test]
    fn mutated_valid_files_never_panic(
        seed in 0usize..7,
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
        cut in any::<prop::sample::Index>(),
    ) {
        let seeds = seeds();
        let (name, mut data) = seeds[seed].clone();
        for (at, byte) in edits {
            let i = at.index(data.len());
            data[i] = byte;
        }
        let _ = parse(name, &data);
        data.truncate(cut.index(data.len() + 1));
        let _ = parse(name, &data);
    }
}
