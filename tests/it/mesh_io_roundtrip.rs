//! The mesh readers' fast paths against the reference readers, and write → read round trips.
//!
//! `read_mesh_bytes` reads OFF, OBJ and PLY through fast paths that decline anything unusual
//! to the one-line-at-a-time reference readers. Two properties keep that honest: on any input
//! (valid files, the same with bytes changed, files big enough to be read in several parallel
//! pieces) both give the same mesh, bit for bit, or the same error message; and a mesh written
//! by texsyn's writers (OBJ, binary PLY) or as `{}` text (OFF, ascii PLY) reads back exactly.

use glam::{Vec2, Vec3};
use proptest::prelude::*;
use std::fmt::Write as _;
use std::path::Path;
use texsyn::geom::Mesh;
use texsyn::geom::io::{read_mesh_bytes, read_mesh_bytes_reference, write_ply};

/// Positions as bits (so -0.0 and 0.0 differ), triangles, colours as bits.
type Exact = (Vec<[u32; 3]>, Vec<[u32; 3]>, Option<Vec<[u32; 4]>>);

fn exact(m: &Mesh) -> Exact {
    (
        m.positions
            .iter()
            .map(|p| p.to_array().map(f32::to_bits))
            .collect(),
        m.triangles.clone(),
        m.colors
            .as_ref()
            .map(|c| c.iter().map(|c| c.map(f32::to_bits)).collect()),
    )
}

/// Both readers on `bytes`: the same mesh or the same message.
fn agree(name: &str, bytes: &[u8]) -> Result<(), TestCaseError> {
    let path = Path::new(name);
    let fast = read_mesh_bytes(path, bytes);
    let reference = read_mesh_bytes_reference(path, bytes);
    match (&fast, &reference) {
        (Ok(a), Ok(b)) => prop_assert_eq!(exact(a), exact(b), "{}", name),
        (Err(a), Err(b)) => prop_assert_eq!(a.to_string(), b.to_string()),
        _ => prop_assert!(
            false,
            "{name}: fast {:?} but reference {:?}",
            fast.as_ref().map(|m| m.triangles.len()),
            reference.as_ref().map(|m| m.triangles.len())
        ),
    }
    Ok(())
}

fn write_off(m: &Mesh) -> Vec<u8> {
    let mut s = format!("OFF\n{} {} 0\n", m.positions.len(), m.triangles.len());
    for p in &m.positions {
        let _ = writeln!(s, "{} {} {}", p.x, p.y, p.z);
    }
    for t in &m.triangles {
        let _ = writeln!(s, "3 {} {} {}", t[0], t[1], t[2]);
    }
    s.into_bytes()
}

fn write_ply_ascii(m: &Mesh) -> Vec<u8> {
    let mut s = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        m.positions.len(),
        m.triangles.len()
    );
    for p in &m.positions {
        let _ = writeln!(s, "{} {} {}", p.x, p.y, p.z);
    }
    for t in &m.triangles {
        let _ = writeln!(s, "3 {} {} {}", t[0], t[1], t[2]);
    }
    s.into_bytes()
}

/// Any finite f32, -0.0 and subnormals included.
fn finite() -> impl Strategy<Value = f32> {
    any::<u32>()
        .prop_map(f32::from_bits)
        .prop_filter("finite", |x| x.is_finite())
}

/// A mesh of 3–40 vertices and 1–60 triangles of three distinct vertices (degenerate ones
/// are dropped on reading, by design), with colours that survive a byte per channel.
fn mesh() -> impl Strategy<Value = (Mesh, Vec<[f32; 4]>)> {
    (3usize..40).prop_flat_map(|n| {
        let tri = (0..n as u32, 0..n as u32, 0..n as u32)
            .prop_filter("distinct", |(a, b, c)| a != b && b != c && a != c)
            .prop_map(|(a, b, c)| [a, b, c]);
        (
            prop::collection::vec((finite(), finite(), finite()), n),
            prop::collection::vec(tri, 1..60),
            prop::collection::vec(any::<[u8; 4]>(), n),
        )
            .prop_map(|(p, t, c)| {
                let positions = p.into_iter().map(|(x, y, z)| Vec3::new(x, y, z)).collect();
                // What the reader makes of a byte: k / 255 in f64, then f32.
                let colors = c
                    .into_iter()
                    .map(|c| c.map(|k| (f64::from(k) / 255.0) as f32))
                    .collect();
                (Mesh::new(positions, t), colors)
            })
    })
}

fn read(name: &str, bytes: &[u8]) -> Mesh {
    read_mesh_bytes(Path::new(name), bytes).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn every_format_round_trips_exactly((m, colors) in mesh(), with_uv in any::<bool>()) {
        let want = exact(&m);
        let uv: Vec<[Vec2; 3]> = m
            .triangles
            .iter()
            .map(|t| t.map(|v| Vec2::new(m.positions[v as usize].x, 0.5)))
            .collect();
        let obj = texsyn::export::write_obj(&m, with_uv.then_some(&uv[..]), Some("m.mtl"), "m");
        let files = [
            ("m.obj", obj.into_bytes()),
            ("m.ply", write_ply(&m, None)),
            ("m.off", write_off(&m)),
            ("m.ply", write_ply_ascii(&m)),
        ];
        for (name, bytes) in &files {
            prop_assert_eq!(&exact(&read(name, bytes)), &want, "{}", name);
            agree(name, bytes)?;
        }
        // Colours through binary PLY (a byte per channel).
        let back = read("m.ply", &write_ply(&m, Some(&colors)));
        prop_assert_eq!(&back.colors, &Some(colors));
        prop_assert_eq!(exact(&back).0, want.0);
    }

    /// Valid files of every fast-path format with bytes changed, cut or repeated: the fast
    /// and reference readers agree on the mesh or the message.
    #[test]
    fn fast_and_reference_readers_agree_on_damaged_files(
        (m, colors) in mesh(),
        format in 0usize..5,
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..4),
        cut in any::<prop::sample::Index>(),
        do_cut in any::<bool>(),
    ) {
        let (name, mut bytes) = match format {
            0 => ("m.off", write_off(&m)),
            1 => ("m.obj", texsyn::export::write_obj(&m, None, None, "m").into_bytes()),
            2 => ("m.ply", write_ply_ascii(&m)),
            3 => ("m.ply", write_ply(&m, Some(&colors))),
            _ => ("m.ply", write_ply(&m, None)),
        };
        for (i, v) in flips {
            let i = i.index(bytes.len());
            // Mostly bytes the text formats are made of, so the damage stays plausible.
            bytes[i] = b"0123456789 -.e\n#/f3v"[v as usize % 20];
        }
        if do_cut {
            bytes.truncate(cut.index(bytes.len()).max(1));
        }
        agree(name, &bytes)?;
    }
}

/// A mesh big enough that its text is read in several parallel pieces (pieces are 1 MiB).
fn big_mesh() -> Mesh {
    use texsyn::geom::subdivide::subdivide;
    let cow = texsyn::geom::io::read_mesh(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/assets/cow.obj"),
    )
    .unwrap();
    subdivide(&subdivide(&cow))
}

#[test]
fn big_files_read_in_pieces_agree_with_the_reference_readers() {
    let m = big_mesh();
    let want = exact(&m);
    let obj = texsyn::export::write_obj(&m, None, None, "m").into_bytes();
    let files = [
        ("m.off", write_off(&m)),
        ("m.obj", obj),
        ("m.ply", write_ply_ascii(&m)),
        ("m.ply", write_ply(&m, None)),
    ];
    for (name, bytes) in &files {
        assert!(bytes.len() > 1 << 20, "{name} is {} bytes", bytes.len());
        assert_eq!(exact(&read(name, bytes)), want, "{name}");
        agree(name, bytes).unwrap();
        // One byte changed at a few places across the pieces: the same error (or mesh) as
        // the reference reader, naming the same line.
        for k in 1..6 {
            let i = bytes.len() * k / 6;
            for b in [b'x', b'\n', b'#'] {
                let mut damaged = bytes.clone();
                damaged[i] = b;
                agree(name, &damaged).unwrap();
            }
        }
    }
    // Relative OBJ indices in a late piece count the vertices of the pieces before it.
    let mut text = String::from_utf8(files[1].1.clone()).unwrap();
    let n = m.positions.len();
    let [a, b, c] = m.triangles[m.triangles.len() - 1];
    let _ = writeln!(
        text,
        "f {} {} {}",
        a as i64 - n as i64,
        b as i64 - n as i64,
        c as i64 - n as i64
    );
    let back = read("m.obj", text.as_bytes());
    assert_eq!(back.triangles.last(), Some(&[a, b, c]));
    agree("m.obj", text.as_bytes()).unwrap();
}
