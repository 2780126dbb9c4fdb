//! STL reader, binary and ASCII, welding corners into shared vertices.
//!
//! A file is binary when its size is exactly 84 + 50·n for the triangle count n in its header
//! (some binary files begin with "solid", so that word alone decides nothing); otherwise it is
//! ASCII if it looks like text beginning with "solid", and a binary file of the wrong size if
//! not. Corners are welded by exact position (-0.0 counts as 0.0) and numbered in order of
//! first appearance, so the result is deterministic. Normals and attribute bytes are ignored.
//! Rejected: a truncated binary file (naming the first incomplete triangle and its byte offset),
//! a NaN or infinite coordinate, an unparsable number or unknown keyword (ASCII, naming the
//! line), `outer` not followed by `loop`, a facet of other than 3 vertices and a facet left
//! open at the end of the file.

use super::{Fault, Location, capacity, coord, fan, lines, show, tokens};
use crate::geom::Mesh;
use glam::Vec3;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

const HEADER: usize = 84;
const RECORD: usize = 50;

pub(super) fn read(bytes: &[u8]) -> Result<Mesh, Fault> {
    let declared = bytes
        .get(80..HEADER)
        .map(|c| u32::from_le_bytes(c.try_into().unwrap()) as usize);
    match declared {
        Some(n) if HEADER + RECORD * n == bytes.len() => read_binary(bytes, n),
        _ if looks_ascii(bytes) => read_ascii(bytes),
        Some(n) => read_binary(bytes, n),
        None => Err(Fault::new(
            Location::Byte(bytes.len()),
            format!(
                "truncated: a binary STL needs an {HEADER}-byte header, the file has {} bytes",
                bytes.len()
            ),
        )),
    }
}

/// Text starting with "solid": binary headers may start with it too, but their triangle count
/// (bytes 80..84) almost always holds a zero or other control byte.
fn looks_ascii(bytes: &[u8]) -> bool {
    let start = bytes.iter().position(|b| !b.is_ascii_whitespace());
    let is_text = |&b: &u8| b.is_ascii_graphic() || b.is_ascii_whitespace();
    start.is_some_and(|s| bytes[s..].starts_with(b"solid"))
        && bytes[..bytes.len().min(512)].iter().all(is_text)
}

/// A multiplicative (Fx-style) hash of a position's bits: welding is one lookup per corner, and
/// the standard SipHash was most of a binary STL's reading time. The numbering does not depend
/// on the hash (vertices are numbered in order of first appearance).
#[derive(Default)]
struct PositionHasher(u64);

impl Hasher for PositionHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(word));
        }
    }
    fn write_u64(&mut self, n: u64) {
        self.0 = (self.0.rotate_left(5) ^ n).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// Gives each distinct position one vertex, in order of first appearance.
struct Welder {
    index: HashMap<[u32; 3], u32, BuildHasherDefault<PositionHasher>>,
    positions: Vec<Vec3>,
}

impl Welder {
    fn with_capacity(corners: usize) -> Self {
        Welder {
            index: HashMap::with_capacity_and_hasher(corners / 4, Default::default()),
            positions: Vec::with_capacity(corners / 4),
        }
    }

    fn vertex(&mut self, p: [f32; 3]) -> u32 {
        // Adding 0.0 turns -0.0 into 0.0 and leaves every other value alone.
        let key = p.map(|x| (x + 0.0).to_bits());
        *self.index.entry(key).or_insert_with(|| {
            self.positions.push(Vec3::from(p));
            (self.positions.len() - 1) as u32
        })
    }
}

fn read_binary(bytes: &[u8], n: usize) -> Result<Mesh, Fault> {
    let available = (bytes.len() - HEADER) / RECORD;
    if available < n {
        let byte = HEADER + RECORD * available;
        return Err(Fault::element(
            "triangle",
            available,
            byte,
            format!(
                "truncated: the header declares {n} triangles ({} bytes) but the file has {} bytes",
                HEADER as u64 + RECORD as u64 * n as u64,
                bytes.len()
            ),
        ));
    }
    if HEADER + RECORD * n < bytes.len() {
        tracing::warn!(
            extra = bytes.len() - HEADER - RECORD * n,
            "binary STL: ignoring bytes after the last triangle"
        );
    }
    let mut weld = Welder::with_capacity(3 * n);
    let mut triangles = Vec::with_capacity(n);
    for (i, record) in bytes[HEADER..].chunks_exact(RECORD).take(n).enumerate() {
        let f = |k: usize| f32::from_le_bytes(record[4 * k..4 * k + 4].try_into().unwrap());
        let mut t = [0u32; 3];
        for (c, v) in t.iter_mut().enumerate() {
            // Floats 0..3 are the facet normal.
            let p = [f(3 + 3 * c), f(4 + 3 * c), f(5 + 3 * c)];
            if !p.iter().all(|x| x.is_finite()) {
                let byte = HEADER + RECORD * i;
                let message = format!("NaN or infinite coordinate in corner {c}: {p:?}");
                return Err(Fault::element("triangle", i, byte, message));
            }
            *v = weld.vertex(p);
        }
        triangles.push(t);
    }
    Ok(Mesh::new(weld.positions, triangles))
}

fn read_ascii(bytes: &[u8]) -> Result<Mesh, Fault> {
    // "vertex 0 0 0\n" is 13 bytes.
    let mut weld = Welder::with_capacity(capacity(bytes.len(), bytes.len(), 13));
    let mut triangles = Vec::new();
    let mut corners: Vec<u32> = Vec::with_capacity(4);
    // The line of the open facet, if one is open.
    let mut open: Option<usize> = None;
    for (no, line) in lines(bytes) {
        let mut t = tokens(line);
        let Some(keyword) = t.next() else { continue };
        match keyword {
            b"solid" | b"endsolid" | b"endloop" => {}
            b"outer" => {
                if t.next() != Some(b"loop".as_slice()) {
                    return Err(Fault::line(no, "expected 'outer loop'"));
                }
            }
            b"facet" => {
                if open.is_some() {
                    return Err(Fault::line(no, "'facet' before the previous 'endfacet'"));
                }
                open = Some(no);
                corners.clear();
            }
            b"vertex" => {
                if open.is_none() {
                    return Err(Fault::line(no, "'vertex' outside a facet"));
                }
                let mut p = [0.0f32; 3];
                for x in &mut p {
                    let tok = t
                        .next()
                        .ok_or_else(|| Fault::line(no, "expected 3 coordinates after 'vertex'"))?;
                    *x = coord(tok).map_err(|m| Fault::line(no, m))?;
                }
                corners.push(weld.vertex(p));
            }
            b"endfacet" => {
                if open.take().is_none() {
                    return Err(Fault::line(no, "'endfacet' without 'facet'"));
                }
                // An STL facet is a triangle; more corners mean a damaged or foreign file,
                // whose polygon would otherwise be guessed at.
                if corners.len() != 3 {
                    let n = corners.len();
                    let m = format!("this facet has {n} vertices: an STL facet has exactly 3");
                    return Err(Fault::line(no, m));
                }
                fan(&corners, &mut triangles);
            }
            other => {
                return Err(Fault::line(
                    no,
                    format!("unexpected {} in an ASCII STL", show(other)),
                ));
            }
        }
    }
    if let Some(no) = open {
        return Err(Fault::line(
            no,
            "unexpected end of file: this facet has no 'endfacet'",
        ));
    }
    Ok(Mesh::new(weld.positions, triangles))
}
