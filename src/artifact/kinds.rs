//! The formats every method uses: meshes, images and file bundles (what reconstruct nodes
//! export).

use super::{
    AlignedBytes, Artifact, ArtifactError, ArtifactWriter, ContentHash, Format, Kind, ReadOwned,
};
use crate::geom::Mesh;
use crate::image::{Image, ImageView};
use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

#[derive(Serialize, Deserialize)]
struct MeshMeta {
    vertices: u64,
    faces: u64,
    has_colors: bool,
}

impl Format for Mesh {
    const KIND: Kind = Kind::Mesh;
    /// An owned copy: algorithms want meshes that cache their adjacency.
    type View<'a> = Mesh;
    fn write(&self) -> AlignedBytes {
        write_mesh(self)
    }
    fn decode(a: &Artifact) -> Result<Mesh, ArtifactError> {
        read_mesh(a)
    }
}

impl ReadOwned for Mesh {
    fn read(a: &Artifact) -> Result<Mesh, ArtifactError> {
        read_mesh(a)
    }
}

fn write_mesh(mesh: &Mesh) -> AlignedBytes {
    let mut w = ArtifactWriter::new(
        Kind::Mesh,
        &MeshMeta {
            vertices: mesh.positions.len() as u64,
            faces: mesh.triangles.len() as u64,
            has_colors: mesh.colors.is_some(),
        },
    )
    .array("positions", &mesh.positions)
    .array("triangles", &mesh.triangles);
    if let Some(c) = &mesh.colors {
        w = w.array("colors", c);
    }
    w.finish()
}

/// A mesh artifact as a [`Mesh`] (one copy: algorithms want owned, adjacency-caching meshes).
fn read_mesh(a: &Artifact) -> Result<Mesh, ArtifactError> {
    a.expect_kind(Kind::Mesh)?;
    let meta: MeshMeta = a.meta()?;
    let positions: &[Vec3] = a.array("positions")?;
    let triangles: &[[u32; 3]] = a.array("triangles")?;
    if positions.len() as u64 != meta.vertices || triangles.len() as u64 != meta.faces {
        return Err(ArtifactError::Meta(
            "mesh array lengths disagree with metadata".into(),
        ));
    }
    if triangles
        .iter()
        .any(|t| t.iter().any(|&v| v as usize >= positions.len()))
    {
        return Err(ArtifactError::Meta("mesh index out of range".into()));
    }
    let colors = if meta.has_colors {
        Some(a.array::<[f32; 4]>("colors")?.to_vec())
    } else {
        None
    };
    Ok(Mesh::with_colors(
        positions.to_vec(),
        triangles.to_vec(),
        colors,
    ))
}

#[derive(Serialize, Deserialize)]
struct ImageMeta {
    width: u32,
    height: u32,
}

impl Format for Image {
    const KIND: Kind = Kind::Image;
    type View<'a> = ImageView<'a>;
    fn write(&self) -> AlignedBytes {
        write_image(self)
    }
    fn decode(a: &Artifact) -> Result<ImageView<'_>, ArtifactError> {
        view_image(a)
    }
}

fn write_image(img: &Image) -> AlignedBytes {
    ArtifactWriter::new(
        Kind::Image,
        &ImageMeta {
            width: img.width,
            height: img.height,
        },
    )
    .array("pixels", &img.pixels)
    .finish()
}

/// An image artifact viewed in place.
fn view_image(a: &Artifact) -> Result<ImageView<'_>, ArtifactError> {
    a.expect_kind(Kind::Image)?;
    let meta: ImageMeta = a.meta()?;
    let pixels: &[[f32; 4]] = a.array("pixels")?;
    if pixels.len() != meta.width as usize * meta.height as usize {
        return Err(ArtifactError::Meta(
            "image size disagrees with metadata".into(),
        ));
    }
    Ok(ImageView {
        width: meta.width,
        height: meta.height,
        pixels,
    })
}

/// One file of a bundle.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct BundleEntry {
    pub name: String,
    pub len: u64,
    /// blake3 of the uncompressed bytes: compared with files already on disk, so a rerun
    /// rewrites only what differs.
    pub hash: ContentHash,
}

/// The files a reconstruct node exports: names and bytes. A node whose output is a bundle is
/// exported into the run's output directory.
#[derive(Clone, Debug, Default)]
pub struct Bundle {
    pub files: Vec<(String, Vec<u8>)>,
}

impl Bundle {
    pub fn add(&mut self, name: impl Into<String>, bytes: Vec<u8>) {
        self.files.push((name.into(), bytes));
    }
}

impl From<Vec<(String, Vec<u8>)>> for Bundle {
    fn from(files: Vec<(String, Vec<u8>)>) -> Bundle {
        Bundle { files }
    }
}

/// A bundle as stored: the entries, each file readable with [`BundleRef::file`].
pub struct BundleRef<'a> {
    pub artifact: &'a Artifact,
    pub entries: Vec<BundleEntry>,
}

impl<'a> BundleRef<'a> {
    /// One file's bytes, decompressed (or in place, if stored uncompressed) and checked against
    /// its hash.
    pub fn file(&self, entry: &BundleEntry) -> Result<std::borrow::Cow<'a, [u8]>, ArtifactError> {
        bundle_file(self.artifact, entry)
    }
}

impl Format for Bundle {
    const KIND: Kind = Kind::FileBundle;
    type View<'a> = BundleRef<'a>;
    fn write(&self) -> AlignedBytes {
        write_bundle(&self.files)
    }
    fn decode(a: &Artifact) -> Result<BundleRef<'_>, ArtifactError> {
        Ok(BundleRef {
            artifact: a,
            entries: a.meta()?,
        })
    }
}

/// The files a reconstruct node exports: each one zstd-compressed (DESIGN.md: zstd for what is
/// not read by random access), except files above [`BUNDLE_PIECE`], which are stored as they
/// are, under the array name [`RAW`]`NAME`.
///
/// Why big files are not compressed: a million-triangle mesh's exports are over 300 MB of OBJ
/// and glTF, and zstd level 1 runs at about 150 MB/s per core on the machines texsyn is measured
/// on, so compressing them (and decompressing them again to write the outputs) took longer than
/// writing them uncompressed: on the 1.4M-triangle run the cache holds 413 MB instead of 223 MB,
/// and the process spends about 1.5 s less CPU (user + system, medians of 3: 19.97 → 18.45 s;
/// BENCHMARKS.md, "Jump maps end to end"). Bundles written before (big files in 16 MiB level-1
/// frames under their plain name) are still read.
fn write_bundle(files: &[(String, Vec<u8>)]) -> AlignedBytes {
    let mut w = ArtifactWriter::new(Kind::FileBundle, &bundle_entries(files));
    let packed: Vec<Option<Vec<u8>>> = files
        .par_iter()
        .map(|(_, b)| (b.len() <= BUNDLE_PIECE).then(|| compress_file(b)))
        .collect();
    for ((name, bytes), packed) in files.iter().zip(packed) {
        // Output names are plain file names (the output writer refuses others): no small
        // file's array can be named like a raw one.
        debug_assert!(
            !name.contains('/'),
            "bundle file name {name:?} is not a plain name"
        );
        w = match packed {
            Some(packed) => w.array_bytes(name, packed),
            None => w.array_slice(&format!("{RAW}{name}"), bytes),
        };
    }
    w.finish()
}

/// The layout of a bundle's files, mixed into the key of every node that exports one (so a
/// lock made before a change says "key changed", not "content changed under the same key").
/// 1: every file zstd-compressed, big ones in 16 MiB level-1 frames. 2: files above
/// [`BUNDLE_PIECE`] stored uncompressed under [`RAW`]`NAME`.
pub const BUNDLE_FORMAT: u32 = 2;

/// A bundle's metadata: each file's name, length and hash.
fn bundle_entries(files: &[(String, Vec<u8>)]) -> Vec<BundleEntry> {
    files
        .par_iter()
        .map(|(name, bytes)| BundleEntry {
            name: name.clone(),
            len: bytes.len() as u64,
            hash: ContentHash::of(bytes),
        })
        .collect()
}

/// Files above this size are stored uncompressed (see [`write_bundle`]); bundles of earlier
/// versions compressed them in pieces of this size.
const BUNDLE_PIECE: usize = 16 << 20;

/// The array name prefix of a file stored uncompressed. Output names are plain file names
/// (no `/`), so no compressed file's array can carry it.
const RAW: &str = "raw/";

/// One file, zstd level 3 in one frame.
fn compress_file(bytes: &[u8]) -> Vec<u8> {
    zstd::bulk::compress(bytes, 3).expect("zstd compression of memory")
}

fn bundle_file<'a>(
    a: &'a Artifact,
    entry: &BundleEntry,
) -> Result<std::borrow::Cow<'a, [u8]>, ArtifactError> {
    let bytes = match a.raw_array(&format!("{RAW}{}", entry.name)) {
        Ok(raw) if raw.len() as u64 == entry.len => std::borrow::Cow::Borrowed(raw),
        Ok(raw) => {
            return Err(ArtifactError::Meta(format!(
                "{}: {} bytes stored, {} listed",
                entry.name,
                raw.len(),
                entry.len
            )));
        }
        Err(_) => {
            let packed = a.raw_array(&entry.name)?;
            decompress_file(packed, entry.len as usize)
                .map_err(|e| ArtifactError::Meta(format!("{}: {e}", entry.name)))?
                .into()
        }
    };
    if ContentHash::of(&bytes) != entry.hash {
        return Err(ArtifactError::HashMismatch);
    }
    Ok(bytes)
}

/// A compressed file of a bundle. Bundles of earlier versions stored a big file as one
/// level-1 frame per [`BUNDLE_PIECE`] (each decoding to exactly that many bytes but the last):
/// those frames are decompressed in parallel into their places. Anything else (one frame, or
/// frames of other sizes) is decoded as one stream.
fn decompress_file(packed: &[u8], len: usize) -> std::io::Result<Vec<u8>> {
    let frames = (len > BUNDLE_PIECE).then(|| split_frames(packed)).flatten();
    let Some(frames) = frames.filter(|f| f.len() == len.div_ceil(BUNDLE_PIECE)) else {
        return zstd::bulk::decompress(packed, len);
    };
    let mut out = vec![0u8; len];
    let whole = out
        .par_chunks_mut(BUNDLE_PIECE)
        .zip(frames)
        .all(|(piece, frame)| {
            zstd::bulk::decompress_to_buffer(frame, piece).is_ok_and(|n| n == piece.len())
        });
    if whole {
        Ok(out)
    } else {
        // Damaged, or split otherwise: decoded again as one stream, whose error (if any) does
        // not depend on which frame a thread met first.
        zstd::bulk::decompress(packed, len)
    }
}

/// The zstd frames of `packed`, or None if it does not parse as whole frames.
fn split_frames(mut packed: &[u8]) -> Option<Vec<&[u8]>> {
    let mut frames = Vec::new();
    while !packed.is_empty() {
        let n = zstd::zstd_safe::find_frame_compressed_size(packed).ok()?;
        if n == 0 || n > packed.len() {
            return None;
        }
        let (frame, rest) = packed.split_at(n);
        frames.push(frame);
        packed = rest;
    }
    Some(frames)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bytes that are not periodic in the old piece size.
    fn big_file() -> Vec<u8> {
        (0..2 * BUNDLE_PIECE + 12345)
            .map(|i| ((i * 2_654_435_761usize) >> 13) as u8 ^ (i / 1000) as u8)
            .collect()
    }

    #[test]
    fn big_bundle_files_are_stored_uncompressed_and_read_in_place() {
        let big = big_file();
        let files = vec![
            ("small.txt".to_string(), b"hi hi hi hi hi hi".to_vec()),
            ("big.bin".to_string(), big.clone()),
        ];
        let stored = write_bundle(&files);
        let a = Artifact::from_bytes(stored.clone()).unwrap();
        let view = Bundle::decode(&a).unwrap();
        assert_eq!(view.entries.len(), 2);
        // The big file is its own bytes, under the raw name, and is read without a copy; the
        // small one is compressed under its plain name.
        assert_eq!(a.raw_array("raw/big.bin").unwrap(), &big[..]);
        assert!(a.raw_array("big.bin").is_err());
        let read = view.file(&view.entries[1]).unwrap();
        assert!(matches!(read, std::borrow::Cow::Borrowed(_)));
        assert_eq!(&read[..], &big[..]);
        assert!(a.raw_array("raw/small.txt").is_err());
        assert_ne!(a.raw_array("small.txt").unwrap(), b"hi hi hi hi hi hi");
        assert_eq!(
            &view.file(&view.entries[0]).unwrap()[..],
            b"hi hi hi hi hi hi"
        );
        // The same bytes with one thread.
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        assert_eq!(one.install(|| write_bundle(&files)), stored);
        // A damaged byte of the stored file, or a length that disagrees with the entry, is an
        // error.
        let at = a.raw_array("raw/big.bin").unwrap().as_ptr() as usize
            - a.file_bytes().as_ptr() as usize;
        let mut damaged = stored.clone();
        damaged[at + BUNDLE_PIECE] ^= 0x5a;
        let d = Artifact::from_bytes(damaged).unwrap();
        assert!(matches!(
            bundle_file(&d, &view.entries[1]),
            Err(ArtifactError::HashMismatch)
        ));
        let mut longer = view.entries[1].clone();
        longer.len += 1;
        assert!(bundle_file(&a, &longer).is_err());
    }

    /// Bundles of the version before: a big file as 16 MiB level-1 frames under its plain name.
    fn old_bundle(files: &[(String, Vec<u8>)]) -> AlignedBytes {
        let mut w = ArtifactWriter::new(Kind::FileBundle, &bundle_entries(files));
        for (name, b) in files {
            let packed = if b.len() <= BUNDLE_PIECE {
                compress_file(b)
            } else {
                b.chunks(BUNDLE_PIECE)
                    .flat_map(|c| zstd::bulk::compress(c, 1).unwrap())
                    .collect()
            };
            w = w.array_bytes(name, packed);
        }
        w.finish()
    }

    #[test]
    fn bundles_of_the_version_before_are_still_read() {
        let big = big_file();
        let files = vec![
            ("small.txt".to_string(), b"hi".to_vec()),
            ("big.bin".to_string(), big.clone()),
        ];
        let stored = old_bundle(&files);
        let a = Artifact::from_bytes(stored.clone()).unwrap();
        let view = Bundle::view(&a).unwrap();
        assert_eq!(&view.file(&view.entries[1]).unwrap()[..], &big[..]);
        assert_eq!(&view.file(&view.entries[0]).unwrap()[..], b"hi");
        // Their frames are found and decoded in parallel; a single frame of a big file (or a
        // damaged one) still decodes, or fails, as one stream.
        let packed = a.raw_array("big.bin").unwrap();
        assert_eq!(split_frames(packed).map(|f| f.len()), Some(3));
        let single = zstd::bulk::compress(&big, 1).unwrap();
        assert_eq!(decompress_file(&single, big.len()).unwrap(), big);
        assert!(decompress_file(packed, big.len() - 1).is_err());
        // Frames of another size than the pieces still decode (as one stream).
        let halves: Vec<u8> = big
            .chunks(BUNDLE_PIECE / 2)
            .flat_map(|c| zstd::bulk::compress(c, 1).unwrap())
            .collect();
        assert_eq!(decompress_file(&halves, big.len()).unwrap(), big);
        // A bundle whose big file is damaged in any frame, or cut short, is an error, with
        // the same message for any thread count.
        let packed_at = packed.as_ptr() as usize - a.file_bytes().as_ptr() as usize;
        let frames = split_frames(packed).unwrap();
        let mut at = packed_at;
        for frame in &frames {
            let mut damaged = stored.clone();
            // A byte in the middle of the frame's compressed data.
            damaged[at + frame.len() / 2] ^= 0x5a;
            let d = Artifact::from_bytes(damaged).unwrap();
            let err = |threads: usize| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap()
                    .install(|| {
                        bundle_file(&d, &view.entries[1])
                            .map(|b| b.len())
                            .map_err(|e| e.to_string())
                    })
            };
            let (one, three) = (err(1), err(3));
            assert!(one.is_err(), "a damaged frame decoded to the right bytes");
            assert_eq!(one, three);
            at += frame.len();
        }
        let cut = &packed[..packed.len() - frames.last().unwrap().len() / 2];
        assert!(decompress_file(cut, big.len()).is_err());
    }

    #[test]
    fn mesh_round_trips_with_colors() {
        let m = Mesh::with_colors(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            vec![[0, 1, 2]],
            Some(vec![[1.0, 0.0, 0.0, 1.0]; 3]),
        );
        let a = Artifact::from_bytes(write_mesh(&m)).unwrap();
        let r = read_mesh(&a).unwrap();
        assert_eq!(r.positions, m.positions);
        assert_eq!(r.triangles, m.triangles);
        assert_eq!(r.colors, m.colors);
    }

    #[test]
    fn bundle_round_trips_and_detects_damage() {
        let files = vec![
            ("a.txt".to_string(), b"hello hello hello".to_vec()),
            ("b.bin".to_string(), vec![7u8; 1000]),
        ];
        let a = Artifact::from_bytes(write_bundle(&files)).unwrap();
        let entries = Bundle::view(&a).unwrap().entries;
        assert_eq!(entries.len(), 2);
        for (e, (name, bytes)) in entries.iter().zip(&files) {
            assert_eq!(&e.name, name);
            assert_eq!(&bundle_file(&a, e).unwrap()[..], &bytes[..]);
        }
        let mut wrong = entries[0].clone();
        wrong.hash = ContentHash::of(b"other");
        assert!(bundle_file(&a, &wrong).is_err());
    }
}
