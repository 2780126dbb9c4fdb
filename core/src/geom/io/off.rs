//! OFF reader: `OFF`, `COFF`, `NOFF` and `CNOFF` (Geomview's object file format).
//!
//! The counts may follow the keyword on the header line; `#` starts a comment. COFF vertex
//! colours (RGB or RGBA, integers 0–255 or floats 0–1) become `Mesh::colors`; normals are
//! skipped; faces of more than 3 vertices are fan-triangulated and a per-face colour after the
//! indices is ignored. Rejected, naming the line: other variants (`4OFF`, `nOFF`, `STOFF`), an
//! unparsable or non-finite number, a face of fewer than 3 vertices, a vertex index out of
//! range, and a file that ends before the declared vertex or face counts.

use super::fast_text::{self, Tokens};
use super::{Fault, capacity, coord, fan, lines, out_of_range, parse, show, tokens};
use crate::geom::Mesh;
use glam::Vec3;

/// The fast path ([`read_fast`]), and the reference reader for what it declines.
pub(super) fn read(bytes: &[u8]) -> Result<Mesh, Fault> {
    match read_fast(bytes) {
        Some(mesh) => Ok(mesh),
        None => read_reference(bytes),
    }
}

/// A well-formed OFF read in parallel pieces of whole lines (see [`fast_text`]); `None` at
/// anything [`read_reference`] would reject, for it to name.
pub(super) fn read_fast(bytes: &[u8]) -> Option<Mesh> {
    // The header: the first non-blank line, then the counts on it or on the next one.
    let mut pos = 0;
    let mut next_line = || {
        while pos < bytes.len() {
            let end = memchr::memchr(b'\n', &bytes[pos..]).map_or(bytes.len(), |p| pos + p);
            let line = &bytes[pos..end];
            pos = (end + 1).min(bytes.len());
            if !Tokens::<true>::new(line).is_done() {
                return Some(line);
            }
        }
        None
    };
    let mut head = Tokens::<true>::new(next_line()?);
    let (has_normals, has_colors) = match head.next()? {
        b"OFF" => (false, false),
        b"COFF" => (false, true),
        b"NOFF" => (true, false),
        b"CNOFF" | b"NCOFF" => (true, true),
        _ => return None,
    };
    if head.is_done() {
        head = Tokens::<true>::new(next_line()?);
    }
    let nv = fast_text::parse_usize(head.next()?)?;
    let nf = fast_text::parse_usize(head.next()?)?;
    if nv > u32::MAX as usize {
        return None;
    }
    let body = &bytes[pos..];

    // Pass 1: the records (non-blank lines) in each piece.
    let pieces = fast_text::pieces(body);
    let counts = fast_text::map_pieces(&pieces, |_, piece| {
        fast_text::lines(piece)
            .filter(|l| !Tokens::<true>::new(l).is_done())
            .count()
    });
    let total: usize = counts.iter().sum();
    if total < nv.checked_add(nf)? {
        return None;
    }
    let firsts = fast_text::firsts(&counts);

    // Pass 2: each piece's vertices and faces, knowing which record it starts at.
    struct Part {
        positions: Vec<Vec3>,
        colors: Vec<[f32; 4]>,
        triangles: Vec<[u32; 3]>,
    }
    let parts = fast_text::map_pieces(&pieces, |i, piece| {
        let mut record = firsts[i];
        let vertices = nv.saturating_sub(record).min(counts[i]);
        let mut part = Part {
            positions: Vec::with_capacity(vertices),
            colors: Vec::with_capacity(if has_colors { vertices } else { 0 }),
            triangles: Vec::with_capacity(2 * (counts[i] - vertices)),
        };
        let mut corners: Vec<u32> = Vec::with_capacity(8);
        for line in fast_text::lines(piece) {
            let mut t = Tokens::<true>::new(line);
            if t.is_done() {
                continue;
            }
            if record < nv {
                let mut p = [0.0f32; 3];
                for x in &mut p {
                    *x = fast_text::coord(t.next()?)?;
                }
                part.positions.push(Vec3::from(p));
                if has_normals {
                    for _ in 0..3 {
                        t.next()?;
                    }
                }
                if has_colors {
                    part.colors.push(color(t).ok()?);
                }
            } else if record < nv + nf {
                let n = fast_text::parse_usize(t.next()?)?;
                if n < 3 {
                    return None;
                }
                corners.clear();
                for _ in 0..n {
                    let v = fast_text::parse_usize(t.next()?)?;
                    if v >= nv {
                        return None;
                    }
                    corners.push(v as u32);
                }
                fast_text::fan(&corners, &mut part.triangles);
            } else {
                break;
            }
            record += 1;
        }
        Some(part)
    });
    let parts: Vec<Part> = parts.into_iter().collect::<Option<_>>()?;
    let concat = |f: fn(&Part) -> usize| parts.iter().map(f).sum::<usize>();
    let mut positions = Vec::with_capacity(concat(|p| p.positions.len()));
    let mut colors = Vec::with_capacity(concat(|p| p.colors.len()));
    let mut triangles = Vec::with_capacity(concat(|p| p.triangles.len()));
    for part in parts {
        positions.extend_from_slice(&part.positions);
        colors.extend_from_slice(&part.colors);
        triangles.extend_from_slice(&part.triangles);
    }
    Some(Mesh::with_colors(
        positions,
        triangles,
        has_colors.then_some(colors),
    ))
}

/// The reference reader: one line at a time, naming the line of any problem.
pub(super) fn read_reference(bytes: &[u8]) -> Result<Mesh, Fault> {
    // Blank and comment-only lines carry nothing.
    let mut lines = lines(bytes).filter(|(_, l)| tokens(l).next().is_some());
    let last_line = || bytes.split(|&b| b == b'\n').count() - usize::from(bytes.ends_with(b"\n"));

    let (header_no, header) = lines
        .next()
        .ok_or_else(|| Fault::line(1, "file is empty"))?;
    let mut head = tokens(header);
    let keyword = head.next().unwrap_or_default();
    let (has_normals, has_colors) = match keyword {
        b"OFF" => (false, false),
        b"COFF" => (false, true),
        b"NOFF" => (true, false),
        b"CNOFF" | b"NCOFF" => (true, true),
        _ if keyword.ends_with(b"OFF") => {
            return Err(Fault::line(
                header_no,
                format!(
                    "unsupported OFF variant {} (expected OFF, COFF, NOFF or CNOFF)",
                    show(keyword)
                ),
            ));
        }
        _ => {
            return Err(Fault::line(
                header_no,
                format!("expected an OFF header, found {}", show(keyword)),
            ));
        }
    };

    // Counts: vertices, faces, edges (ignored); they may share the header line.
    let mut counts = Vec::with_capacity(3);
    let mut counts_no = header_no;
    let mut rest = head.peekable();
    if rest.peek().is_none() {
        let (n, line) = lines.next().ok_or_else(|| {
            Fault::line(
                header_no,
                "unexpected end of file: expected vertex and face counts",
            )
        })?;
        counts_no = n;
        rest = tokens(line).peekable();
    }
    for t in rest.take(2) {
        counts.push(parse::<usize>(t).ok_or_else(|| {
            Fault::line(counts_no, format!("cannot parse {} as a count", show(t)))
        })?);
    }
    let [nv, nf] = counts[..] else {
        return Err(Fault::line(counts_no, "expected vertex and face counts"));
    };
    if nv > u32::MAX as usize {
        return Err(Fault::line(counts_no, format!("too many vertices ({nv})")));
    }

    // The next line, the `i`-th of `n` `what` the header declared: its number and tokens.
    let mut next_record = |i: usize, n: usize, what: &str| {
        let (no, line) = lines.next().ok_or_else(|| {
            Fault::line(
                last_line(),
                format!("unexpected end of file after {i} of {n} {what}"),
            )
        })?;
        Ok::<_, Fault>((no, tokens(line)))
    };

    // A vertex line has at least 6 bytes ("0 0 0\n"), a face line at least 8.
    let mut positions = Vec::with_capacity(capacity(nv, bytes.len(), 6));
    let mut colors = has_colors.then(|| Vec::with_capacity(capacity(nv, bytes.len(), 6)));
    for i in 0..nv {
        let (no, mut t) = next_record(i, nv, "vertices")?;
        let mut p = [0.0f32; 3];
        for x in &mut p {
            let tok = t
                .next()
                .ok_or_else(|| Fault::line(no, "expected 3 coordinates"))?;
            *x = coord(tok).map_err(|m| Fault::line(no, m))?;
        }
        positions.push(Vec3::from(p));
        if has_normals {
            for _ in 0..3 {
                t.next()
                    .ok_or_else(|| Fault::line(no, "expected a normal after the coordinates"))?;
            }
        }
        if let Some(colors) = &mut colors {
            colors.push(color(t).map_err(|m| Fault::line(no, m))?);
        }
    }

    let mut triangles = Vec::with_capacity(capacity(nf, bytes.len(), 8));
    let mut corners: Vec<u32> = Vec::with_capacity(8);
    for i in 0..nf {
        let (no, mut t) = next_record(i, nf, "faces")?;
        let first = t.next().unwrap_or_default();
        let n = parse::<usize>(first).ok_or_else(|| {
            Fault::line(no, format!("cannot parse {} as a face size", show(first)))
        })?;
        if n < 3 {
            return Err(Fault::line(no, super::unsupported_face_size(n)));
        }
        corners.clear();
        for k in 0..n {
            let tok = t.next().ok_or_else(|| {
                Fault::line(no, format!("face of {n} vertices has only {k} indices"))
            })?;
            let v = parse::<usize>(tok).ok_or_else(|| {
                Fault::line(no, format!("cannot parse {} as a vertex index", show(tok)))
            })?;
            if v >= nv {
                return Err(Fault::line(no, out_of_range(v, nv)));
            }
            corners.push(v as u32);
        }
        fan(&corners, &mut triangles);
    }
    Ok(Mesh::with_colors(positions, triangles, colors))
}

/// A COFF colour: 3 or 4 components, integers meaning 0–255 or floats meaning 0–1.
fn color<'a>(mut t: impl Iterator<Item = &'a [u8]>) -> Result<[f32; 4], String> {
    let mut c = [1.0f32; 4];
    let mut n = 0;
    let mut all_integers = true;
    for (slot, tok) in c.iter_mut().zip(&mut t) {
        all_integers &= tok.iter().all(u8::is_ascii_digit);
        *slot = match parse::<f32>(tok) {
            Some(x) if x.is_finite() => x,
            _ => return Err(format!("cannot parse {} as a colour component", show(tok))),
        };
        n += 1;
    }
    if n < 3 {
        return Err("expected an RGB or RGBA colour after the coordinates".into());
    }
    let scale = if all_integers { 255.0 } else { 1.0 };
    for x in &mut c[..n] {
        *x = (*x / scale).clamp(0.0, 1.0);
    }
    Ok(c)
}
