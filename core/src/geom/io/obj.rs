//! Wavefront OBJ reader: `v` positions (with optional `r g b` vertex colours) and `f` faces.
//!
//! All objects and groups become one mesh; polygons are fan-triangulated; texture coordinates,
//! normals, materials, points and lines are ignored (the `.mtl` need not exist). Face corners
//! may be `v`, `v/vt`, `v//vn` or `v/vt/vn`, with negative (relative) indices. Rejected, naming
//! the line: an unparsable or non-finite coordinate, a vertex index that is zero or out of
//! range, and a face of fewer than 3 vertices.
//!
//! Written by hand rather than with `tobj`: tobj renumbers vertices per object in order of
//! first use and drops unreferenced ones, and texsyn must keep the file's vertex numbering
//! (configs name vertices by index). The tests compare this reader with tobj.

use super::fast_text::{self, Tokens};
use super::{Fault, coord, fan, lines, out_of_range, parse, show, tokens};
use crate::geom::Mesh;
use glam::Vec3;

/// The fast path ([`read_fast`]), and the reference reader for what it declines.
pub(super) fn read(bytes: &[u8]) -> Result<Mesh, Fault> {
    match read_fast(bytes) {
        Some(mesh) => Ok(mesh),
        None => read_reference(bytes),
    }
}

/// Whether a line is a vertex (`v`) line: what pass 1 counts, so that relative indices in
/// any piece know how many vertices precede them.
fn is_vertex_line(line: &[u8]) -> bool {
    Tokens::<true>::new(line).next() == Some(b"v")
}

/// A well-formed OBJ read in parallel pieces of whole lines (see [`fast_text`]); `None` at
/// anything [`read_reference`] would reject, for it to name.
pub(super) fn read_fast(bytes: &[u8]) -> Option<Mesh> {
    let pieces = fast_text::pieces(bytes);
    // Pass 1: the vertices in each piece.
    let counts = fast_text::map_pieces(&pieces, |_, piece| {
        fast_text::lines(piece)
            .filter(|l| is_vertex_line(l))
            .count()
    });
    let mut before = Vec::with_capacity(counts.len());
    let mut total = 0usize;
    for c in &counts {
        before.push(total);
        total += c;
    }

    struct Part {
        positions: Vec<Vec3>,
        /// Colours of this piece's vertices up to its last coloured one (white before that).
        colors: Vec<[f32; 4]>,
        triangles: Vec<[u32; 3]>,
        largest: Option<u32>,
    }
    // Pass 2: each piece's vertices and faces.
    let parts = fast_text::map_pieces(&pieces, |i, piece| {
        let mut part = Part {
            positions: Vec::with_capacity(counts[i]),
            colors: Vec::new(),
            triangles: Vec::with_capacity(2 * counts[i]),
            largest: None,
        };
        let mut corners: Vec<u32> = Vec::with_capacity(8);
        for line in fast_text::lines(piece) {
            let mut t = Tokens::<true>::new(line);
            match t.next() {
                Some(b"v") => {
                    let mut values = [0.0f32; 6];
                    let mut n = 0;
                    for tok in t.take(6) {
                        values[n] = fast_text::coord(tok)?;
                        n += 1;
                    }
                    if n < 3 {
                        return None;
                    }
                    part.positions
                        .push(Vec3::new(values[0], values[1], values[2]));
                    if n == 6 {
                        part.colors.resize(part.positions.len() - 1, [1.0; 4]);
                        part.colors.push(
                            [values[3], values[4], values[5], 1.0].map(|c| c.clamp(0.0, 1.0)),
                        );
                    }
                }
                Some(b"f") => {
                    corners.clear();
                    let so_far = (before[i] + part.positions.len()) as i64;
                    for tok in t {
                        let v = tok.split(|&b| b == b'/').next().unwrap_or_default();
                        let index = match fast_text::parse_i64(v)? {
                            0 => return None,
                            i if i < 0 => so_far + i,
                            i => i - 1,
                        };
                        let index = u32::try_from(index).ok()?;
                        part.largest = part.largest.max(Some(index));
                        corners.push(index);
                    }
                    if corners.len() < 3 {
                        return None;
                    }
                    fast_text::fan(&corners, &mut part.triangles);
                }
                _ => {}
            }
        }
        Some(part)
    });
    let parts: Vec<Part> = parts.into_iter().collect::<Option<_>>()?;
    if parts
        .iter()
        .filter_map(|p| p.largest)
        .any(|l| l as usize >= total)
    {
        return None;
    }
    let any_colors = parts.iter().any(|p| !p.colors.is_empty());
    let mut positions = Vec::with_capacity(total);
    let mut colors = Vec::with_capacity(if any_colors { total } else { 0 });
    let mut triangles = Vec::with_capacity(parts.iter().map(|p| p.triangles.len()).sum());
    for part in parts {
        positions.extend_from_slice(&part.positions);
        if any_colors {
            colors.extend_from_slice(&part.colors);
            colors.resize(positions.len(), [1.0; 4]);
        }
        triangles.extend_from_slice(&part.triangles);
    }
    Some(Mesh::with_colors(
        positions,
        triangles,
        any_colors.then_some(colors),
    ))
}

/// The reference reader: one line at a time, naming the line of any problem.
pub(super) fn read_reference(bytes: &[u8]) -> Result<Mesh, Fault> {
    let mut positions = Vec::new();
    let mut colors: Vec<[f32; 4]> = Vec::new();
    let mut triangles = Vec::new();
    let mut corners: Vec<u32> = Vec::with_capacity(8);
    // Positive indices may point forward (vertices listed after the face), so their range is
    // checked at the end; the largest one and its line are enough for that.
    let mut largest: Option<(u32, usize)> = None;

    for (no, line) in lines(bytes) {
        let mut t = tokens(line);
        match t.next() {
            Some(b"v") => {
                let mut values = [0.0f32; 6];
                let mut n = 0;
                for tok in t.take(6) {
                    values[n] = coord(tok).map_err(|m| Fault::line(no, m))?;
                    n += 1;
                }
                if n < 3 {
                    return Err(Fault::line(no, "expected 3 coordinates after 'v'"));
                }
                positions.push(Vec3::new(values[0], values[1], values[2]));
                // `v x y z r g b`; `v x y z w` has a weight, which we ignore (it is 1 in
                // practice).
                if n == 6 {
                    colors.resize(positions.len() - 1, [1.0; 4]);
                    colors.push([values[3], values[4], values[5], 1.0].map(|c| c.clamp(0.0, 1.0)));
                }
            }
            Some(b"f") => {
                corners.clear();
                for tok in t {
                    let v = tok.split(|&b| b == b'/').next().unwrap_or_default();
                    let i = parse::<i64>(v).ok_or_else(|| {
                        Fault::line(no, format!("cannot parse {} as a vertex index", show(v)))
                    })?;
                    let index = match i {
                        0 => {
                            return Err(Fault::line(no, "vertex index 0 (OBJ indices start at 1)"));
                        }
                        i if i < 0 => positions.len() as i64 + i,
                        i => i - 1,
                    };
                    let index = u32::try_from(index)
                        .map_err(|_| Fault::line(no, out_of_range(i, positions.len())))?;
                    if largest.is_none_or(|(l, _)| index > l) {
                        largest = Some((index, no));
                    }
                    corners.push(index);
                }
                if corners.len() < 3 {
                    return Err(Fault::line(no, super::unsupported_face_size(corners.len())));
                }
                fan(&corners, &mut triangles);
            }
            _ => {}
        }
    }

    if let Some((index, no)) = largest
        && index as usize >= positions.len()
    {
        return Err(Fault::line(
            no,
            out_of_range(index as u64 + 1, positions.len()),
        ));
    }
    let colors = (!colors.is_empty()).then(|| {
        colors.resize(positions.len(), [1.0; 4]);
        colors
    });
    Ok(Mesh::with_colors(positions, triangles, colors))
}
