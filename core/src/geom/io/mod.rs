//! Mesh readers (OBJ, OFF and its colour/normal variants, PLY, STL) and a PLY writer.
//!
//! Every reader works on the file's bytes (the pipeline reads and hashes them itself), keeps the
//! file's vertex numbering (unreferenced vertices stay), fan-triangulates polygons, drops
//! degenerate triangles with a warning, and reports anything else it cannot use as a
//! [`MeshError`] that names the file, the place in it and the problem. No input makes it panic.

mod fast_text;
mod obj;
mod off;
mod ply;
mod stl;

pub use ply::write_ply;

use super::Mesh;
use std::fmt;
use std::path::{Path, PathBuf};

/// A mesh file that could not be read. Every message names the file, where in it the problem
/// is (line for text formats, element index and byte offset for binary ones), and what was wrong.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {location}: {message}")]
    Parse {
        path: PathBuf,
        location: Location,
        message: String,
    },
    /// A problem with the file as a whole (empty file, no faces).
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("{path}: unsupported mesh format (expected .obj, .off, .ply or .stl)")]
    UnsupportedFormat { path: PathBuf },
}

/// Where in a mesh file a problem is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Location {
    /// 1-based line of a text file (or of a PLY header).
    Line(usize),
    /// 0-based element of a binary file ("face 12"), with the byte offset where it starts.
    Element {
        element: String,
        index: usize,
        byte: usize,
    },
    /// A byte offset, where no element applies.
    Byte(usize),
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(n) => write!(f, "line {n}"),
            Location::Element {
                element,
                index,
                byte,
            } => write!(f, "{element} {index} (byte {byte})"),
            Location::Byte(b) => write!(f, "byte {b}"),
        }
    }
}

/// Reads an input file whole, refusing what is not a regular file (a FIFO would block
/// forever, a device such as `/dev/zero` never ends) before reading from it. The error's
/// message says what the path is instead.
pub fn read_regular_file(path: &Path) -> std::io::Result<Vec<u8>> {
    read_regular_file_capped(path, u64::MAX)
}

/// As [`read_regular_file`], and a file longer than `cap` bytes is an error saying so, found
/// before its bytes are read (a file that grows while it is read stops at `cap + 1` bytes).
pub fn read_regular_file_capped(path: &Path, cap: u64) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let too_big = |len: u64| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{len} bytes or more, over the limit of {cap} bytes for this file"),
        )
    };
    let not_regular = |ty: std::fs::FileType| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("not a regular file (it is {})", file_type_name(ty)),
        )
    };
    // stat first, so a FIFO is never opened (opening one for reading blocks until a writer
    // comes); then check the opened file again, in case the path changed in between.
    let ty = std::fs::metadata(path)?.file_type();
    if !ty.is_file() {
        return Err(not_regular(ty));
    }
    let file = std::fs::File::open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(not_regular(meta.file_type()));
    }
    if meta.len() > cap {
        return Err(too_big(meta.len()));
    }
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0));
    file.take(cap.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(too_big(bytes.len() as u64));
    }
    Ok(bytes)
}

/// What a file type is, for messages ("a directory").
fn file_type_name(ty: std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ty.is_fifo() {
            return "a FIFO";
        }
        if ty.is_char_device() {
            return "a character device";
        }
        if ty.is_block_device() {
            return "a block device";
        }
        if ty.is_socket() {
            return "a socket";
        }
    }
    if ty.is_dir() {
        "a directory"
    } else if ty.is_file() {
        "a regular file"
    } else {
        "a special file"
    }
}

/// Reads a mesh, choosing the reader by the file's extension.
pub fn read_mesh(path: &Path) -> Result<Mesh, MeshError> {
    let bytes = read_regular_file(path).map_err(|source| MeshError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    read_mesh_bytes(path, &bytes)
}

/// Parses a mesh file already in memory. `path` only chooses the reader (by its extension, in
/// any case: .obj, .off, .ply, .stl) and names the file in errors.
///
/// OFF, OBJ and PLY files are read by fast paths (parallel pieces of whole lines for text,
/// fixed-size records for binary) that decline anything unusual; the reference readers then
/// read those and give every error, so the result is always [`read_mesh_bytes_reference`]'s.
pub fn read_mesh_bytes(path: &Path, bytes: &[u8]) -> Result<Mesh, MeshError> {
    read_with(path, bytes, false)
}

/// [`read_mesh_bytes`] with the reference readers only (one line or value at a time): what the
/// fast paths must agree with, for tests and comparisons.
#[doc(hidden)]
pub fn read_mesh_bytes_reference(path: &Path, bytes: &[u8]) -> Result<Mesh, MeshError> {
    read_with(path, bytes, true)
}

fn read_with(path: &Path, bytes: &[u8], reference: bool) -> Result<Mesh, MeshError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let reader: fn(&[u8]) -> Result<Mesh, Fault> = match (ext.as_deref(), reference) {
        (Some("obj"), false) => obj::read,
        (Some("obj"), true) => obj::read_reference,
        (Some("off"), false) => off::read,
        (Some("off"), true) => off::read_reference,
        (Some("ply"), false) => ply::read,
        (Some("ply"), true) => ply::read_reference,
        (Some("stl"), _) => stl::read,
        _ => {
            return Err(MeshError::UnsupportedFormat {
                path: path.to_path_buf(),
            });
        }
    };
    let invalid = |message: String| MeshError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    // A text file saved with a UTF-8 byte-order mark (some Windows editors do) reads as
    // without it: the mark would otherwise spoil its first line. Binary STL headers are
    // arbitrary bytes, so STL keeps them.
    const BOM: &[u8] = b"\xEF\xBB\xBF";
    let bytes = match ext.as_deref() {
        Some("obj" | "off" | "ply") => bytes.strip_prefix(BOM).unwrap_or(bytes),
        _ => bytes,
    };
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Err(invalid("file is empty".into()));
    }
    // Warnings from inside the readers get the file name from this span.
    let _span = tracing::warn_span!("read_mesh", path = %path.display()).entered();
    let mut mesh = reader(bytes).map_err(|fault| match fault.at {
        Some(location) => MeshError::Parse {
            path: path.to_path_buf(),
            location,
            message: fault.message,
        },
        None => invalid(fault.message),
    })?;

    let before = mesh.triangles.len();
    mesh.triangles
        .retain(|&[a, b, c]| a != b && b != c && c != a);
    let dropped = before - mesh.triangles.len();
    if dropped > 0 {
        tracing::warn!(dropped, "dropped degenerate faces (a vertex repeated)");
    }
    if mesh.triangles.is_empty() {
        return Err(invalid(if dropped > 0 {
            format!("empty mesh: all {dropped} faces are degenerate")
        } else {
            "empty mesh: no faces".into()
        }));
    }
    Ok(mesh)
}

/// A reader's complaint, before the path is attached. `at: None` is about the whole file.
#[derive(Debug)]
struct Fault {
    at: Option<Location>,
    message: String,
}

impl Fault {
    fn new(at: Location, message: impl Into<String>) -> Self {
        Fault {
            at: Some(at),
            message: message.into(),
        }
    }

    fn line(line: usize, message: impl Into<String>) -> Self {
        Self::new(Location::Line(line), message)
    }

    fn element(element: &str, index: usize, byte: usize, message: impl Into<String>) -> Self {
        Self::new(
            Location::Element {
                element: element.to_string(),
                index,
                byte,
            },
            message,
        )
    }
}

/// Lines of a text file with their 1-based numbers, `\r` and `#` comments removed.
fn lines(bytes: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    bytes.split(|&b| b == b'\n').enumerate().map(|(i, line)| {
        let line = match line.iter().position(|&b| b == b'#') {
            Some(p) => &line[..p],
            None => line,
        };
        (i + 1, line.strip_suffix(b"\r").unwrap_or(line))
    })
}

/// Whitespace-separated tokens of a line, without allocating.
fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(u8::is_ascii_whitespace)
        .filter(|t| !t.is_empty())
}

/// A token as it should appear quoted in a message (lossy, shortened).
fn show(token: &[u8]) -> String {
    let s = String::from_utf8_lossy(&token[..token.len().min(40)]);
    if token.len() > 40 {
        format!("'{s}…'")
    } else {
        format!("'{s}'")
    }
}

fn parse<T: std::str::FromStr>(token: &[u8]) -> Option<T> {
    std::str::from_utf8(token).ok()?.parse().ok()
}

/// A coordinate: parsed straight to f32 (one rounding) and required to be finite.
fn coord(token: &[u8]) -> Result<f32, String> {
    match parse::<f32>(token) {
        Some(x) if x.is_finite() => Ok(x),
        Some(_) => Err(format!("NaN or infinite coordinate {}", show(token))),
        None => Err(format!("cannot parse {} as a number", show(token))),
    }
}

/// A reserve size that trusts a count from the file only as far as the file's size allows, so
/// a corrupt header cannot make us allocate gigabytes.
fn capacity(declared: usize, available_bytes: usize, min_bytes_each: usize) -> usize {
    declared.min(available_bytes / min_bytes_each.max(1))
}

fn fan(corners: &[u32], triangles: &mut Vec<[u32; 3]>) {
    for k in 1..corners.len().saturating_sub(1) {
        triangles.push([corners[0], corners[k], corners[k + 1]]);
    }
}

fn unsupported_face_size(n: usize) -> String {
    format!("unsupported face size {n} (a face needs at least 3 vertices)")
}

fn out_of_range(index: impl fmt::Display, vertex_count: usize) -> String {
    format!("vertex index {index} out of range (the file has {vertex_count} vertices)")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_byte_order_mark_before_an_obj_or_off_changes_nothing() {
        let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n";
        let off = "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 2 3\n";
        for (name, text) in [("m.obj", obj), ("m.off", off)] {
            let plain = read_mesh_bytes(Path::new(name), text.as_bytes()).unwrap();
            let marked = [b"\xEF\xBB\xBF".as_slice(), text.as_bytes()].concat();
            let marked = read_mesh_bytes(Path::new(name), &marked).unwrap();
            assert_eq!(marked.positions, plain.positions, "{name}");
            assert_eq!(marked.triangles, plain.triangles, "{name}");
        }
    }

    #[test]
    fn locations_read_as_a_user_would_look_them_up() {
        assert_eq!(Location::Line(7).to_string(), "line 7");
        let face = Location::Element {
            element: "face".into(),
            index: 3,
            byte: 120,
        };
        assert_eq!(face.to_string(), "face 3 (byte 120)");
        assert_eq!(Location::Byte(80).to_string(), "byte 80");
    }

    #[test]
    fn lines_are_numbered_from_one_without_cr_or_comments() {
        let got: Vec<(usize, &[u8])> = lines(b"a b\r\n# c\nd # e\n").collect();
        assert_eq!(
            got,
            vec![
                (1, &b"a b"[..]),
                (2, &b""[..]),
                (3, &b"d "[..]),
                (4, &b""[..])
            ]
        );
        assert_eq!(tokens(b"  x\t y  ").collect::<Vec<_>>(), vec![b"x", b"y"]);
    }

    #[test]
    fn fan_triangulates_around_the_first_corner() {
        let mut t = Vec::new();
        fan(&[4, 5, 6, 7, 8], &mut t);
        assert_eq!(t, vec![[4, 5, 6], [4, 6, 7], [4, 7, 8]]);
    }

    #[test]
    fn declared_counts_cannot_reserve_more_than_the_file_holds() {
        assert_eq!(capacity(usize::MAX, 1000, 10), 100);
        assert_eq!(capacity(5, 1000, 10), 5);
    }
}
