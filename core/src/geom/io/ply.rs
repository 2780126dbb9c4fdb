//! PLY reader (ascii, binary_little_endian, binary_big_endian) and binary PLY writer.
//!
//! Reads the `vertex` element's `x`, `y`, `z` (any scalar type) and optional `red`, `green`,
//! `blue`, `alpha` (integer types scaled by 1/255, float types taken as they are) into
//! `Mesh::colors`, and the `face` element's `vertex_indices` or `vertex_index` list (any count
//! and index types), fan-triangulating polygons. Every other element and property, lists
//! included, is skipped. Rejected: a header that is not PLY, names an unknown format or type,
//! or lacks `vertex`/`x`/`y`/`z` (naming the header line); in the body, an unparsable number,
//! a NaN or infinite coordinate, a vertex index out of range or not an integer, a face of fewer
//! than 3 vertices, and a file shorter than the header promises (naming the line for ascii, or
//! the element, its index and its byte offset for binary).

use super::fast_text::{self, Tokens};
use super::{Fault, Location, capacity, fan, out_of_range, parse, show, tokens};
use crate::geom::Mesh;
use glam::Vec3;
use rayon::prelude::*;
use std::fmt::Write as _;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(name: &[u8]) -> Option<Self> {
        Some(match name {
            b"char" | b"int8" => Scalar::I8,
            b"uchar" | b"uint8" => Scalar::U8,
            b"short" | b"int16" => Scalar::I16,
            b"ushort" | b"uint16" => Scalar::U16,
            b"int" | b"int32" => Scalar::I32,
            b"uint" | b"uint32" => Scalar::U32,
            b"float" | b"float32" => Scalar::F32,
            b"double" | b"float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }
}

#[derive(Debug, Clone, Copy)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

/// What the reader does with a property's value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Skip,
    /// Slot in [x, y, z, red, green, blue, alpha].
    Vertex(usize),
    FaceIndices,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<(Kind, Role)>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Ascii,
    Binary { big_endian: bool },
}

struct Header {
    format: Format,
    elements: Vec<Element>,
    /// Byte offset of the body, and the number of header lines before it.
    body: usize,
    lines: usize,
    vertex_count: usize,
    has_colors: bool,
}

/// The fast paths ([`read_ascii_fast`], [`read_binary_fast`]), and the reference reader for what
/// they decline.
pub(super) fn read(bytes: &[u8]) -> Result<Mesh, Fault> {
    let header = read_header(bytes)?;
    let fast = match header.format {
        Format::Ascii => read_ascii_fast(&header, &bytes[header.body..]),
        Format::Binary { big_endian } => read_binary_fast(&header, bytes, big_endian),
    };
    match fast {
        Some(mesh) => Ok(mesh),
        None => read_body_reference(&header, bytes),
    }
}

/// The reference reader: one value at a time, naming the place of any problem.
pub(super) fn read_reference(bytes: &[u8]) -> Result<Mesh, Fault> {
    read_body_reference(&read_header(bytes)?, bytes)
}

fn read_body_reference(header: &Header, bytes: &[u8]) -> Result<Mesh, Fault> {
    match header.format {
        Format::Ascii => read_body(
            header,
            Ascii {
                bytes,
                pos: header.body,
                line: header.lines + 1,
                token_line: header.lines,
            },
        ),
        Format::Binary { big_endian } => read_body(
            header,
            Binary {
                bytes,
                pos: header.body,
                big_endian,
            },
        ),
    }
}

fn read_header(bytes: &[u8]) -> Result<Header, Fault> {
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut pos = 0;
    let mut no = 0;
    loop {
        let Some(len) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            let message = if no == 0 {
                "not a PLY file: expected 'ply' on the first line"
            } else {
                "truncated header: no 'end_header' line"
            };
            return Err(Fault::line(no.max(1), message));
        };
        let raw = &bytes[pos..pos + len];
        let line = raw.strip_suffix(b"\r").unwrap_or(raw);
        pos += len + 1;
        no += 1;
        let mut t = tokens(line);
        let keyword = t.next().unwrap_or_default();
        if no == 1 {
            if keyword != b"ply" || t.next().is_some() {
                return Err(Fault::line(
                    1,
                    "not a PLY file: expected 'ply' on the first line",
                ));
            }
            continue;
        }
        match keyword {
            b"format" => {
                let name = t.next().unwrap_or_default();
                format = Some(match name {
                    b"ascii" => Format::Ascii,
                    b"binary_little_endian" => Format::Binary { big_endian: false },
                    b"binary_big_endian" => Format::Binary { big_endian: true },
                    _ => {
                        return Err(Fault::line(
                            no,
                            format!("unknown PLY format {}", show(name)),
                        ));
                    }
                });
            }
            b"comment" | b"obj_info" | b"" => {}
            b"element" => {
                let (Some(name), Some(count)) = (t.next(), t.next()) else {
                    return Err(Fault::line(no, "expected 'element NAME COUNT'"));
                };
                let count = parse::<usize>(count).ok_or_else(|| {
                    Fault::line(no, format!("cannot parse {} as a count", show(count)))
                })?;
                let name = String::from_utf8_lossy(name).into_owned();
                if elements.iter().any(|e| e.name == name) {
                    return Err(Fault::line(no, format!("element '{name}' declared twice")));
                }
                elements.push(Element {
                    name,
                    count,
                    properties: Vec::new(),
                });
            }
            b"property" => {
                let Some(element) = elements.last_mut() else {
                    return Err(Fault::line(no, "property before any element"));
                };
                let ty = |name: Option<&[u8]>| {
                    let name = name.unwrap_or_default();
                    Scalar::from_name(name).ok_or_else(|| {
                        Fault::line(no, format!("unknown property type {}", show(name)))
                    })
                };
                let first = t.next();
                let kind = if first == Some(b"list") {
                    Kind::List {
                        count: ty(t.next())?,
                        item: ty(t.next())?,
                    }
                } else {
                    Kind::Scalar(ty(first)?)
                };
                let name = t.next().unwrap_or_default();
                let role = match (element.name.as_str(), name, kind) {
                    ("vertex", b"x" | b"y" | b"z", Kind::List { .. }) => {
                        return Err(Fault::line(
                            no,
                            format!("vertex property {} is a list", show(name)),
                        ));
                    }
                    ("vertex", _, Kind::Scalar(_)) => match name {
                        b"x" => Role::Vertex(0),
                        b"y" => Role::Vertex(1),
                        b"z" => Role::Vertex(2),
                        b"red" => Role::Vertex(3),
                        b"green" => Role::Vertex(4),
                        b"blue" => Role::Vertex(5),
                        b"alpha" => Role::Vertex(6),
                        _ => Role::Skip,
                    },
                    ("face", b"vertex_indices" | b"vertex_index", Kind::List { .. }) => {
                        Role::FaceIndices
                    }
                    _ => Role::Skip,
                };
                if role != Role::Skip && element.properties.iter().any(|&(_, r)| r == role) {
                    return Err(Fault::line(
                        no,
                        format!("property {} declared twice", show(name)),
                    ));
                }
                element.properties.push((kind, role));
            }
            b"end_header" => break,
            _ => {
                return Err(Fault::line(
                    no,
                    format!("unexpected header line starting with {}", show(keyword)),
                ));
            }
        }
    }

    let format = format.ok_or_else(|| Fault::line(no, "the header has no 'format' line"))?;
    let has = |element: &str, role: Role| {
        elements
            .iter()
            .any(|e| e.name == element && e.properties.iter().any(|&(_, r)| r == role))
    };
    for (slot, axis) in ["x", "y", "z"].into_iter().enumerate() {
        if !has("vertex", Role::Vertex(slot)) {
            return Err(Fault::line(
                no,
                format!("the header declares no 'vertex' element with property '{axis}'"),
            ));
        }
    }
    if elements.iter().any(|e| e.name == "face") && !has("face", Role::FaceIndices) {
        return Err(Fault::line(
            no,
            "the 'face' element has no 'vertex_indices' list",
        ));
    }
    let vertex_count = elements
        .iter()
        .find(|e| e.name == "vertex")
        .map_or(0, |e| e.count);
    if vertex_count > u32::MAX as usize {
        return Err(Fault::line(
            no,
            format!("too many vertices ({vertex_count})"),
        ));
    }
    let has_colors = (3..6).all(|slot| has("vertex", Role::Vertex(slot)));
    Ok(Header {
        format,
        elements,
        body: pos,
        lines: no,
        vertex_count,
        has_colors,
    })
}

/// Why a value could not be read.
enum Miss {
    EndOfFile,
    Bad(String),
}

/// The body of a PLY file, read one value at a time.
trait Body {
    fn value(&mut self, ty: Scalar) -> Result<f64, Miss>;
    fn skip(&mut self, ty: Scalar, n: usize) -> Result<(), Miss>;
    /// The position in the file, taken at the start of each element instance.
    fn mark(&self) -> usize;
    fn locate(&self, element: &str, index: usize, mark: usize) -> Location;
    fn available(&self) -> usize;
}

struct Ascii<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
    /// The line of the last token read, which is where any problem is.
    token_line: usize,
}

impl<'a> Ascii<'a> {
    fn token(&mut self) -> Option<&'a [u8]> {
        while let Some(&b) = self.bytes.get(self.pos) {
            if !b.is_ascii_whitespace() {
                break;
            }
            self.line += usize::from(b == b'\n');
            self.pos += 1;
        }
        let start = self.pos;
        if start < self.bytes.len() {
            self.token_line = self.line;
        }
        while self
            .bytes
            .get(self.pos)
            .is_some_and(|b| !b.is_ascii_whitespace())
        {
            self.pos += 1;
        }
        (self.pos > start).then(|| &self.bytes[start..self.pos])
    }
}

impl Body for Ascii<'_> {
    fn value(&mut self, ty: Scalar) -> Result<f64, Miss> {
        let token = self.token().ok_or(Miss::EndOfFile)?;
        // f32 properties are parsed as f32 so that they round once, like the other readers.
        let value = match ty {
            Scalar::F32 => fast_text::parse_f32(token).map(f64::from),
            Scalar::F64 => parse::<f64>(token),
            _ => fast_text::parse_i64(token).map(|i| i as f64),
        };
        value.ok_or_else(|| Miss::Bad(format!("cannot parse {} as {ty:?}", show(token))))
    }

    fn skip(&mut self, _: Scalar, n: usize) -> Result<(), Miss> {
        for _ in 0..n {
            self.token().ok_or(Miss::EndOfFile)?;
        }
        Ok(())
    }

    fn mark(&self) -> usize {
        self.pos
    }

    fn locate(&self, _: &str, _: usize, _: usize) -> Location {
        Location::Line(self.token_line)
    }

    fn available(&self) -> usize {
        self.bytes.len() - self.pos
    }
}

struct Binary<'a> {
    bytes: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl Binary<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], Miss> {
        let chunk = self
            .bytes
            .get(self.pos..self.pos + N)
            .ok_or(Miss::EndOfFile)?;
        self.pos += N;
        let mut a: [u8; N] = chunk.try_into().unwrap();
        if self.big_endian {
            a.reverse();
        }
        Ok(a)
    }
}

impl Body for Binary<'_> {
    fn value(&mut self, ty: Scalar) -> Result<f64, Miss> {
        // `take` has put the bytes in little-endian order.
        Ok(match ty {
            Scalar::I8 => i8::from_le_bytes(self.take()?) as f64,
            Scalar::U8 => u8::from_le_bytes(self.take()?) as f64,
            Scalar::I16 => i16::from_le_bytes(self.take()?) as f64,
            Scalar::U16 => u16::from_le_bytes(self.take()?) as f64,
            Scalar::I32 => i32::from_le_bytes(self.take()?) as f64,
            Scalar::U32 => u32::from_le_bytes(self.take()?) as f64,
            Scalar::F32 => f32::from_le_bytes(self.take()?) as f64,
            Scalar::F64 => f64::from_le_bytes(self.take()?),
        })
    }

    fn skip(&mut self, ty: Scalar, n: usize) -> Result<(), Miss> {
        let end = n
            .checked_mul(ty.size())
            .and_then(|len| self.pos.checked_add(len))
            .filter(|&end| end <= self.bytes.len())
            .ok_or(Miss::EndOfFile)?;
        self.pos = end;
        Ok(())
    }

    fn mark(&self) -> usize {
        self.pos
    }

    fn locate(&self, element: &str, index: usize, mark: usize) -> Location {
        Location::Element {
            element: element.to_string(),
            index,
            byte: mark,
        }
    }

    fn available(&self) -> usize {
        self.bytes.len() - self.pos
    }
}

/// The vertex being read: x, y, z, red, green, blue, alpha; colours already scaled to [0, 1].
type VertexSlots = [f64; 7];
const NO_VERTEX: VertexSlots = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];

/// Reads instance `i` of `element` from `body`: its vertex slots into `vertex`, its face (fan-
/// triangulated) onto `triangles`. `nv` is the vertex count, for the index range.
fn read_instance(
    element: &Element,
    i: usize,
    body: &mut impl Body,
    nv: usize,
    vertex: &mut VertexSlots,
    triangles: &mut Vec<[u32; 3]>,
    corners: &mut Vec<u32>,
) -> Result<(), Fault> {
    let mark = body.mark();
    let fail =
        |body: &dyn Body, message: String| Fault::new(body.locate(&element.name, i, mark), message);
    let miss = |body: &dyn Body, miss: Miss| {
        let message = match miss {
            Miss::EndOfFile => format!(
                "truncated: the file ends inside {} {i} (the header declares {})",
                element.name, element.count
            ),
            Miss::Bad(m) => m,
        };
        fail(body, message)
    };
    for &(kind, role) in &element.properties {
        match kind {
            Kind::Scalar(ty) => {
                let v = body.value(ty).map_err(|m| miss(body, m))?;
                if let Role::Vertex(slot) = role {
                    vertex[slot] = if slot >= 3 && !ty.is_float() {
                        v / 255.0
                    } else {
                        v
                    };
                }
            }
            Kind::List { count, item } => {
                let n = body.value(count).map_err(|m| miss(body, m))?;
                if n < 0.0 || n.fract() != 0.0 {
                    return Err(fail(body, format!("invalid list length {n}")));
                }
                let n = n as usize;
                if role != Role::FaceIndices {
                    body.skip(item, n).map_err(|m| miss(body, m))?;
                    continue;
                }
                if n < 3 {
                    return Err(fail(body, super::unsupported_face_size(n)));
                }
                corners.clear();
                for _ in 0..n {
                    let v = body.value(item).map_err(|m| miss(body, m))?;
                    if v.fract() != 0.0 {
                        let message = format!("vertex index {v} is not an integer");
                        return Err(fail(body, message));
                    }
                    if !(0.0..nv as f64).contains(&v) {
                        return Err(fail(body, out_of_range(v, nv)));
                    }
                    corners.push(v as u32);
                }
                fan(corners, triangles);
            }
        }
    }
    Ok(())
}

/// A vertex's position and colour as the mesh stores them, or the coordinates if one is NaN or
/// infinite.
fn finish_vertex(vertex: VertexSlots) -> Result<(Vec3, [f32; 4]), [f32; 3]> {
    let [x, y, z, r, g, b, a] = vertex.map(|v| v as f32);
    if ![x, y, z].iter().all(|c| c.is_finite()) {
        return Err([x, y, z]);
    }
    Ok((Vec3::new(x, y, z), [r, g, b, a].map(|c| c.clamp(0.0, 1.0))))
}

/// The reference reader of a body: one value at a time, naming the place of any problem.
fn read_body(header: &Header, mut body: impl Body) -> Result<Mesh, Fault> {
    let nv = header.vertex_count;
    let available = body.available();
    let mut positions = Vec::with_capacity(capacity(nv, available, 3));
    let mut colors = header
        .has_colors
        .then(|| Vec::with_capacity(capacity(nv, available, 3)));
    let mut triangles = Vec::new();
    let mut corners: Vec<u32> = Vec::with_capacity(8);

    for element in &header.elements {
        // An element without properties occupies no bytes; its count may be anything.
        if element.properties.is_empty() {
            continue;
        }
        let is_vertex = element.name == "vertex";
        for i in 0..element.count {
            let mark = body.mark();
            let mut vertex = NO_VERTEX;
            read_instance(
                element,
                i,
                &mut body,
                nv,
                &mut vertex,
                &mut triangles,
                &mut corners,
            )?;
            if is_vertex {
                let (p, c) = finish_vertex(vertex).map_err(|[x, y, z]| {
                    let message = format!("NaN or infinite coordinate ({x}, {y}, {z})");
                    Fault::new(body.locate(&element.name, i, mark), message)
                })?;
                positions.push(p);
                if let Some(colors) = &mut colors {
                    colors.push(c);
                }
            }
        }
    }
    Ok(Mesh::with_colors(positions, triangles, colors))
}

/// A well-formed ascii body read in parallel pieces of whole lines (see [`fast_text`]), on the
/// bet that each element instance is one line, as every writer makes it: each line must hold
/// exactly one instance's values. `None` where the bet or the file fails, for
/// [`read_body`] to read or to name the problem.
fn read_ascii_fast(header: &Header, body: &[u8]) -> Option<Mesh> {
    let nv = header.vertex_count;
    // The instances in file order: (first record, element), elements with properties only.
    let mut starts = Vec::new();
    let mut records = 0usize;
    for element in header.elements.iter().filter(|e| !e.properties.is_empty()) {
        starts.push((records, element));
        records = records.checked_add(element.count)?;
    }
    let pieces = fast_text::pieces(body);
    let blank = |l: &[u8]| Tokens::<false>::new(l).is_done();
    let counts = fast_text::map_pieces(&pieces, |_, piece| {
        fast_text::lines(piece).filter(|l| !blank(l)).count()
    });
    if counts.iter().sum::<usize>() < records {
        return None;
    }
    let firsts = fast_text::firsts(&counts);
    struct Part {
        positions: Vec<Vec3>,
        colors: Vec<[f32; 4]>,
        triangles: Vec<[u32; 3]>,
    }
    // How many of records `from..to` are instances of the element named `name`.
    let overlap = |name: &str, from: usize, to: usize| {
        starts
            .iter()
            .filter(|(_, e)| e.name == name)
            .map(|&(s, e)| to.min(s + e.count).saturating_sub(from.max(s)))
            .sum::<usize>()
    };
    let parts = fast_text::map_pieces(&pieces, |i, piece| {
        let mut record = firsts[i];
        let end = (record + counts[i]).min(records);
        let vertices = overlap("vertex", record, end);
        let mut part = Part {
            positions: Vec::with_capacity(vertices),
            colors: Vec::with_capacity(if header.has_colors { vertices } else { 0 }),
            triangles: Vec::with_capacity(overlap("face", record, end)),
        };
        let mut corners: Vec<u32> = Vec::with_capacity(8);
        let is_vertex: Vec<bool> = starts.iter().map(|(_, e)| e.name == "vertex").collect();
        // The element of `record`: the last that starts at or before it.
        let mut e = starts.iter().rposition(|&(s, _)| s <= record)?;
        for line in fast_text::lines(piece) {
            if blank(line) {
                continue;
            }
            if record >= records {
                break;
            }
            while e + 1 < starts.len() && starts[e + 1].0 <= record {
                e += 1;
            }
            let (first, element) = starts[e];
            let mut ascii = Ascii {
                bytes: line,
                pos: 0,
                line: 0,
                token_line: 0,
            };
            let mut vertex = NO_VERTEX;
            read_instance(
                element,
                record - first,
                &mut ascii,
                nv,
                &mut vertex,
                &mut part.triangles,
                &mut corners,
            )
            .ok()?;
            if ascii.token().is_some() {
                return None;
            }
            if is_vertex[e] {
                let (p, c) = finish_vertex(vertex).ok()?;
                part.positions.push(p);
                if header.has_colors {
                    part.colors.push(c);
                }
            }
            record += 1;
        }
        Some(part)
    });
    let parts: Vec<Part> = parts.into_iter().collect::<Option<_>>()?;
    let mut positions = Vec::with_capacity(nv);
    let mut colors = Vec::with_capacity(if header.has_colors { nv } else { 0 });
    let mut triangles = Vec::with_capacity(parts.iter().map(|p| p.triangles.len()).sum());
    for part in parts {
        positions.extend_from_slice(&part.positions);
        colors.extend_from_slice(&part.colors);
        triangles.extend_from_slice(&part.triangles);
    }
    Some(Mesh::with_colors(
        positions,
        triangles,
        header.has_colors.then_some(colors),
    ))
}

/// An integer of type `ty` at the start of `bytes`, or `None` for a float type or too few bytes.
#[inline]
fn binary_int(ty: Scalar, bytes: &[u8], big_endian: bool) -> Option<i64> {
    fn get<const N: usize>(bytes: &[u8], big_endian: bool) -> Option<[u8; N]> {
        let mut a: [u8; N] = bytes.get(..N)?.try_into().ok()?;
        if big_endian {
            a.reverse();
        }
        Some(a)
    }
    Some(match ty {
        Scalar::I8 => i8::from_le_bytes(get(bytes, big_endian)?).into(),
        Scalar::U8 => u8::from_le_bytes(get(bytes, big_endian)?).into(),
        Scalar::I16 => i16::from_le_bytes(get(bytes, big_endian)?).into(),
        Scalar::U16 => u16::from_le_bytes(get(bytes, big_endian)?).into(),
        Scalar::I32 => i32::from_le_bytes(get(bytes, big_endian)?).into(),
        Scalar::U32 => u32::from_le_bytes(get(bytes, big_endian)?).into(),
        Scalar::F32 | Scalar::F64 => return None,
    })
}

/// A vertex's position and colour, decoded from a binary record.
type Decoded = (Vec3, [f32; 4]);

/// A value of type `ty` at the start of `bytes` (which holds it), as [`Binary`] reads it.
#[inline]
fn binary_value(ty: Scalar, bytes: &[u8], big_endian: bool) -> f64 {
    let mut body = Binary {
        bytes,
        pos: 0,
        big_endian,
    };
    body.value(ty).unwrap_or(f64::NAN)
}

/// A well-formed binary body whose elements are either all scalars (a fixed record size: read
/// in parallel slices) or a face element holding only an integer index list. `None` for
/// anything else or any problem, for [`read_body`] to read or name.
fn read_binary_fast(header: &Header, bytes: &[u8], big_endian: bool) -> Option<Mesh> {
    let nv = header.vertex_count;
    let mut pos = header.body;
    let mut positions = Vec::new();
    let mut colors = Vec::new();
    let mut triangles = Vec::new();
    let mut corners: Vec<u32> = Vec::with_capacity(8);
    for element in header.elements.iter().filter(|e| !e.properties.is_empty()) {
        let scalars: Option<Vec<Scalar>> = element
            .properties
            .iter()
            .map(|&(k, _)| match k {
                Kind::Scalar(ty) => Some(ty),
                Kind::List { .. } => None,
            })
            .collect();
        if let Some(types) = scalars {
            let size: usize = types.iter().map(|t| t.size()).sum();
            let end = element
                .count
                .checked_mul(size)
                .and_then(|n| n.checked_add(pos))
                .filter(|&end| end <= bytes.len())?;
            if element.name == "vertex" {
                let data = &bytes[pos..end];
                // Where each used property sits in a record.
                let mut used = Vec::new();
                let mut offset = 0;
                for (&(_, role), &ty) in element.properties.iter().zip(&types) {
                    if let Role::Vertex(slot) = role {
                        used.push((offset, ty, slot));
                    }
                    offset += ty.size();
                }
                let decode = |record: &[u8]| {
                    let mut vertex = NO_VERTEX;
                    for &(offset, ty, slot) in &used {
                        let v = binary_value(ty, &record[offset..], big_endian);
                        vertex[slot] = if slot >= 3 && !ty.is_float() {
                            v / 255.0
                        } else {
                            v
                        };
                    }
                    finish_vertex(vertex).ok()
                };
                // 64k vertices per task; results concatenated in order.
                let parts: Vec<Option<Vec<Decoded>>> = data
                    .par_chunks(size.max(1) << 16)
                    .map(|chunk| chunk.chunks_exact(size).map(decode).collect())
                    .collect();
                positions.reserve(element.count);
                if header.has_colors {
                    colors.reserve(element.count);
                }
                for part in parts {
                    for (p, c) in part? {
                        positions.push(p);
                        if header.has_colors {
                            colors.push(c);
                        }
                    }
                }
            }
            pos = end;
            continue;
        }
        // Only a face element with nothing but an integer index list.
        let [(Kind::List { count, item }, Role::FaceIndices)] = element.properties[..] else {
            return None;
        };
        if count.is_float() || item.is_float() {
            return None;
        }
        triangles.reserve(capacity(
            element.count,
            bytes.len() - pos,
            1 + 3 * item.size(),
        ));
        for _ in 0..element.count {
            let n = binary_int(count, bytes.get(pos..)?, big_endian)?;
            pos += count.size();
            if n < 3 {
                return None;
            }
            corners.clear();
            for _ in 0..n {
                let v = binary_int(item, bytes.get(pos..)?, big_endian)?;
                pos += item.size();
                if !(0..nv as i64).contains(&v) {
                    return None;
                }
                corners.push(v as u32);
            }
            fast_text::fan(&corners, &mut triangles);
        }
    }
    Some(Mesh::with_colors(
        positions,
        triangles,
        header.has_colors.then_some(colors),
    ))
}

/// Binary little-endian PLY: float `x y z`, then `red green blue alpha` as uchar when `colors`
/// is given (one per vertex, components in [0, 1]), then the faces as a `uchar int` list.
///
/// # Panics
/// If `colors` does not have one entry per vertex (a caller's bug, not a user's).
pub fn write_ply(mesh: &Mesh, colors: Option<&[[f32; 4]]>) -> Vec<u8> {
    if let Some(c) = colors {
        assert_eq!(
            c.len(),
            mesh.positions.len(),
            "write_ply: one colour per vertex"
        );
    }
    let mut header = String::from("ply\nformat binary_little_endian 1.0\ncomment texsyn\n");
    let _ = writeln!(header, "element vertex {}", mesh.positions.len());
    header.push_str("property float x\nproperty float y\nproperty float z\n");
    if colors.is_some() {
        header.push_str(
            "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n",
        );
    }
    let _ = writeln!(header, "element face {}", mesh.triangles.len());
    header.push_str("property list uchar int vertex_indices\nend_header\n");

    let vertex_size = 12 + if colors.is_some() { 4 } else { 0 };
    let mut out = Vec::with_capacity(
        header.len() + vertex_size * mesh.positions.len() + 13 * mesh.triangles.len(),
    );
    out.extend_from_slice(header.as_bytes());
    for (i, p) in mesh.positions.iter().enumerate() {
        for x in p.to_array() {
            out.extend_from_slice(&x.to_le_bytes());
        }
        if let Some(c) = colors {
            out.extend(c[i].map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8));
        }
    }
    for t in &mesh.triangles {
        out.push(3);
        for &v in t {
            out.extend_from_slice(&(v as i32).to_le_bytes());
        }
    }
    out
}
