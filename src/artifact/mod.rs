//! Artifact files: a fixed header, bincode metadata, then raw little-endian arrays, each
//! aligned to 64 bytes so a memory-mapped file can be viewed in place with bytemuck
//! (DESIGN.md, "The cache").
//!
//! ```text
//! offset 0    magic "TXSYNART"            8 bytes
//!        8    format version (u32)
//!       12    artifact kind (u32)
//!       16    metadata length (u64)
//!       24    payload length (u64)        everything after the header
//!       32    payload blake3 hash         32 bytes: the artifact's content hash
//!       64    byte-order mark (u32)       0x01020304 in the writer's byte order
//!       68    reserved (zero)             up to HEADER_LEN = 128
//!      128    payload: bincode(Meta), zero padding to 64, arrays (each padded to 64)
//! ```
//!
//! The header's own fields are little-endian everywhere; the arrays are in the writing
//! machine's byte order (they are viewed in place), which the byte-order mark records. A
//! machine of the other order refuses the object ([`ArtifactError::ByteOrder`]) instead of
//! misreading it; the cache then recomputes it. Every machine texsyn is tested on is
//! little-endian.
//!
//! The content hash covers the whole payload, so it changes exactly when the bytes a reader
//! could see change. It is what downstream node keys are built from (early cutoff).

pub mod feature_aligned;
pub mod format;
pub mod geometry_images;
pub mod graph_matching;
pub mod jump_maps;
pub mod kinds;
pub mod solid;

pub use format::{Format, ReadOwned};
pub use kinds::{BUNDLE_FORMAT, Bundle};
use memmap2::Mmap;
use rayon::prelude::*;
use serde::{Deserialize, Serialize, de::DeserializeOwned};
use std::fmt;

pub const MAGIC: &[u8; 8] = b"TXSYNART";
/// 2: the byte-order mark at offset 64 (version 1 objects are recomputed).
pub const FORMAT_VERSION: u32 = 2;
/// Written in the writer's native order; read back as [`BYTE_ORDER_MARK`] only by a machine
/// of the same order.
pub const BYTE_ORDER_MARK: u32 = 0x0102_0304;
pub const HEADER_LEN: usize = 128;
const ALIGN: usize = 64;

/// What an artifact holds. The code is stored in the header so a reader can refuse a file
/// of the wrong kind (a stale cache entry after a format change, or a corrupted one).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[repr(u32)]
pub enum Kind {
    Mesh = 1,
    Image = 2,
    JumpMap = 3,
    OrientationField = 4,
    JumpParameterization = 5,
    TexelAddresses = 6,
    FileBundle = 7,
    AddressImage = 8,
    GeometryImage = 9,
    TexelImage = 10,
    ParamField = 11,
    TexelVariants = 12,
    SolidAnalysis = 13,
    RotationField = 14,
    VoxelRequest = 15,
    SolidBrick = 16,
    SolidSamples = 17,
    Sqrt2Hierarchy = 18,
    FieldKeys = 19,
    SweepField = 20,
    GaussianStack = 21,
    VertexColours = 22,
    ShapeFeatures = 23,
    TextureFeatures = 24,
    FeatureField = 25,
    RefinedMesh = 26,
    SurfaceColours = 27,
    AppearanceSpace = 28,
}

impl Kind {
    pub fn from_code(code: u32) -> Option<Kind> {
        use Kind::*;
        [
            Mesh,
            Image,
            JumpMap,
            OrientationField,
            JumpParameterization,
            TexelAddresses,
            FileBundle,
            AddressImage,
            GeometryImage,
            TexelImage,
            ParamField,
            TexelVariants,
            SolidAnalysis,
            RotationField,
            VoxelRequest,
            SolidBrick,
            SolidSamples,
            Sqrt2Hierarchy,
            FieldKeys,
            SweepField,
            GaussianStack,
            VertexColours,
            ShapeFeatures,
            TextureFeatures,
            FeatureField,
            RefinedMesh,
            SurfaceColours,
            AppearanceSpace,
        ]
        .into_iter()
        .find(|k| *k as u32 == code)
    }
}

/// Inputs from this size on are hashed on every core (blake3's documentation: multithreading
/// pays off from about 128 KiB; artifacts and exports reach hundreds of MB).
const PARALLEL_HASH_BYTES: usize = 1 << 20;

/// The blake3 hash of an artifact's payload, or of an input file's bytes.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct ContentHash(pub [u8; 32]);

impl ContentHash {
    pub fn of(bytes: &[u8]) -> Self {
        // blake3's tree hash is the same however its chunks are spread over threads.
        if bytes.len() >= PARALLEL_HASH_BYTES {
            let mut h = blake3::Hasher::new();
            h.update_rayon(bytes);
            return ContentHash(*h.finalize().as_bytes());
        }
        ContentHash(*blake3::hash(bytes).as_bytes())
    }
    pub fn to_hex(&self) -> String {
        blake3::Hash::from_bytes(self.0).to_hex().to_string()
    }

    /// Reads back what [`ContentHash::to_hex`] wrote; `None` for anything else.
    pub fn from_hex(hex: &str) -> Option<Self> {
        blake3::Hash::from_hex(hex)
            .ok()
            .map(|h| ContentHash(*h.as_bytes()))
    }
}

impl fmt::Debug for ContentHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", &self.to_hex()[..16])
    }
}

impl fmt::Display for ContentHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.to_hex())
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ArtifactError {
    #[error("artifact is shorter than its header ({0} bytes)")]
    Truncated(usize),
    #[error("not a texsyn artifact (bad magic)")]
    BadMagic,
    #[error("artifact format version {found}, this texsyn reads version {FORMAT_VERSION}")]
    Version { found: u32 },
    #[error("artifact holds kind code {found}, expected {expected:?}")]
    WrongKind { found: u32, expected: Kind },
    #[error("artifact holds kind code {0}, which is no known kind")]
    UnknownKind(u32),
    #[error("artifact header's reserved bytes are not zero (corrupted)")]
    Reserved,
    #[error(
        "artifact was written on a {written} machine; this {here} machine cannot read its arrays"
    )]
    ByteOrder {
        written: &'static str,
        here: &'static str,
    },
    #[error("cache object is not a regular file")]
    NotAFile,
    #[error("artifact length {actual} does not match its header ({expected})")]
    Length { actual: usize, expected: usize },
    #[error("artifact payload hash does not match its header (corrupted)")]
    HashMismatch,
    #[error("artifact metadata is unreadable: {0}")]
    Meta(String),
    #[error("artifact has no array named {0:?}")]
    MissingArray(String),
    #[error(
        "artifact array {name:?} holds {bytes} bytes, not a whole number of {elem}-byte elements"
    )]
    ArrayShape {
        name: String,
        bytes: usize,
        elem: usize,
    },
    #[error("artifact array {name:?} lies outside the file")]
    ArrayBounds { name: String },
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
struct ArrayDesc {
    name: String,
    offset: u64,
    len: u64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct Envelope {
    meta: Vec<u8>,
    arrays: Vec<ArrayDesc>,
}

/// The parsed fixed-size header.
#[derive(Debug, Clone, Copy)]
pub struct Header {
    pub kind: u32,
    pub meta_len: u64,
    pub payload_len: u64,
    pub content_hash: ContentHash,
}

impl Header {
    /// Checks magic, version, that the kind code is a known [`Kind`], that the reserved bytes
    /// are zero, and (when known) the file length. Cheap: reads 128 bytes. The payload hash
    /// does not cover the header, so these checks are what catch a damaged header byte (the
    /// metadata length is checked against the metadata by [`Artifact::open`]).
    pub fn parse(bytes: &[u8], file_len: Option<usize>) -> Result<Header, ArtifactError> {
        if bytes.len() < HEADER_LEN {
            return Err(ArtifactError::Truncated(bytes.len()));
        }
        if &bytes[0..8] != MAGIC {
            return Err(ArtifactError::BadMagic);
        }
        let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
        let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().unwrap());
        let version = u32_at(8);
        if version != FORMAT_VERSION {
            return Err(ArtifactError::Version { found: version });
        }
        let header = Header {
            kind: u32_at(12),
            meta_len: u64_at(16),
            payload_len: u64_at(24),
            content_hash: ContentHash(bytes[32..64].try_into().unwrap()),
        };
        if Kind::from_code(header.kind).is_none() {
            return Err(ArtifactError::UnknownKind(header.kind));
        }
        let mark = u32::from_ne_bytes(bytes[64..68].try_into().unwrap());
        if mark != BYTE_ORDER_MARK {
            let order = |big: bool| if big { "big-endian" } else { "little-endian" };
            let here_big = cfg!(target_endian = "big");
            return Err(if mark == BYTE_ORDER_MARK.swap_bytes() {
                ArtifactError::ByteOrder {
                    written: order(!here_big),
                    here: order(here_big),
                }
            } else {
                ArtifactError::Reserved
            });
        }
        if bytes[68..HEADER_LEN].iter().any(|&b| b != 0) {
            return Err(ArtifactError::Reserved);
        }
        if let Some(len) = file_len {
            let expected = HEADER_LEN as u64 + header.payload_len;
            if len as u64 != expected {
                return Err(ArtifactError::Length {
                    actual: len,
                    expected: expected as usize,
                });
            }
        }
        if header.meta_len > header.payload_len {
            return Err(ArtifactError::Meta("metadata longer than payload".into()));
        }
        Ok(header)
    }
}

fn bincode_config() -> impl bincode::config::Config {
    bincode::config::standard()
        .with_little_endian()
        .with_fixed_int_encoding()
}

/// Canonical bytes of a serializable value (node parameters, artifact metadata).
pub fn canonical_bytes<T: Serialize>(value: &T) -> Vec<u8> {
    bincode::serde::encode_to_vec(value, bincode_config())
        .expect("serializing plain data to a Vec cannot fail")
}

fn align_up(n: usize) -> usize {
    n.div_ceil(ALIGN) * ALIGN
}

/// Builds an artifact's bytes: metadata plus named arrays. Arrays are borrowed where the
/// caller has them (a million-triangle mesh's arrays and exports are hundreds of megabytes:
/// each copy costs a pass over fresh memory) and copied once, into the file's bytes.
pub struct ArtifactWriter<'a> {
    kind: Kind,
    meta: Vec<u8>,
    arrays: Vec<(String, std::borrow::Cow<'a, [u8]>)>,
}

impl<'a> ArtifactWriter<'a> {
    pub fn new<M: Serialize>(kind: Kind, meta: &M) -> Self {
        ArtifactWriter {
            kind,
            meta: canonical_bytes(meta),
            arrays: Vec::new(),
        }
    }

    pub fn array<T: bytemuck::Pod>(mut self, name: &str, data: &'a [T]) -> Self {
        // x86-64 and every platform we build for are little-endian, so the in-memory
        // bytes of a Pod slice are its little-endian representation.
        self.arrays
            .push((name.to_owned(), bytemuck::cast_slice(data).into()));
        self
    }

    pub fn array_bytes(mut self, name: &str, data: Vec<u8>) -> Self {
        self.arrays.push((name.to_owned(), data.into()));
        self
    }

    /// [`ArtifactWriter::array_bytes`] of borrowed bytes.
    pub fn array_slice(mut self, name: &str, data: &'a [u8]) -> Self {
        self.arrays.push((name.to_owned(), data.into()));
        self
    }

    /// [`ArtifactWriter::array_slice`] for each of `arrays`, in order (a value's own list of
    /// named arrays, as the stages give it).
    pub fn arrays_bytes<N: AsRef<str>>(
        self,
        arrays: impl IntoIterator<Item = (N, &'a [u8])>,
    ) -> Self {
        arrays
            .into_iter()
            .fold(self, |w, (name, data)| w.array_slice(name.as_ref(), data))
    }

    /// The complete file bytes.
    pub fn finish(self) -> AlignedBytes {
        // The envelope's array offsets depend on its own length, so lay out with a first
        // guess, then fix up once (the offsets are fixed-width, so the length is stable).
        let mut descs: Vec<ArrayDesc> = self
            .arrays
            .iter()
            .map(|(n, d)| ArrayDesc {
                name: n.clone(),
                offset: 0,
                len: d.len() as u64,
            })
            .collect();
        let env_len = canonical_bytes(&Envelope {
            meta: self.meta.clone(),
            arrays: descs.clone(),
        })
        .len();
        let mut offset = align_up(env_len);
        for d in &mut descs {
            d.offset = offset as u64;
            offset = align_up(offset + d.len as usize);
        }
        let env = canonical_bytes(&Envelope {
            meta: self.meta,
            arrays: descs.clone(),
        });
        debug_assert_eq!(env.len(), env_len);
        let payload_len = offset;
        // Zeroed by the allocator (fresh pages are zero), filled in parallel: on the machines
        // texsyn is measured on, first touching a page costs more than copying into it, so a
        // 300 MB export bundle's one copy is split over the cores.
        let mut out = AlignedBytes::zeroed(HEADER_LEN + payload_len);
        {
            let payload = &mut out[HEADER_LEN..];
            payload[..env.len()].copy_from_slice(&env);
            let mut places: Vec<(&mut [u8], &[u8])> = Vec::new();
            let mut rest = &mut payload[env.len()..];
            let mut at = env.len();
            for (d, (_, data)) in descs.iter().zip(&self.arrays) {
                let (_, tail) = std::mem::take(&mut rest).split_at_mut(d.offset as usize - at);
                let (place, tail) = tail.split_at_mut(data.len());
                rest = tail;
                at = d.offset as usize + data.len();
                places.extend(place.chunks_mut(COPY_PIECE).zip(data.chunks(COPY_PIECE)));
            }
            places
                .into_par_iter()
                .for_each(|(place, data)| place.copy_from_slice(data));
        }
        let hash = ContentHash::of(&out[HEADER_LEN..]);
        out[0..8].copy_from_slice(MAGIC);
        out[8..12].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
        out[12..16].copy_from_slice(&(self.kind as u32).to_le_bytes());
        out[16..24].copy_from_slice(&(env.len() as u64).to_le_bytes());
        out[24..32].copy_from_slice(&(payload_len as u64).to_le_bytes());
        out[32..64].copy_from_slice(&hash.0);
        out[64..68].copy_from_slice(&BYTE_ORDER_MARK.to_ne_bytes());
        out
    }
}

/// Where an artifact's bytes live: a read-only memory map of a cache file, or memory
/// (freshly computed, not yet re-read).
pub enum Backing {
    Mapped(Mmap),
    Owned(AlignedBytes),
}

impl Backing {
    fn bytes(&self) -> &[u8] {
        match self {
            Backing::Mapped(m) => m,
            Backing::Owned(v) => v.as_slice(),
        }
    }
}

#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(64))]
struct Block([u8; 64]);

/// Pieces of an artifact's arrays copied side by side in [`ArtifactWriter::finish`].
const COPY_PIECE: usize = 4 << 20;

/// Bytes in a 64-byte-aligned buffer, so typed views of in-memory artifacts are as aligned
/// as those of mapped files (a plain `Vec<u8>` only promises 1). What
/// [`ArtifactWriter::finish`] makes and [`Artifact::from_bytes`] takes without a copy.
#[derive(Clone)]
pub struct AlignedBytes {
    blocks: Vec<Block>,
    len: usize,
}

impl std::ops::Deref for AlignedBytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        self.as_slice()
    }
}

impl std::ops::DerefMut for AlignedBytes {
    fn deref_mut(&mut self) -> &mut [u8] {
        &mut bytemuck::cast_slice_mut::<Block, u8>(&mut self.blocks)[..self.len]
    }
}

impl PartialEq for AlignedBytes {
    fn eq(&self, other: &Self) -> bool {
        self.as_slice() == other.as_slice()
    }
}

impl fmt::Debug for AlignedBytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "AlignedBytes({} bytes)", self.len)
    }
}

impl From<Vec<u8>> for AlignedBytes {
    fn from(bytes: Vec<u8>) -> Self {
        AlignedBytes::from_slice(&bytes)
    }
}

impl From<&[u8]> for AlignedBytes {
    fn from(bytes: &[u8]) -> Self {
        AlignedBytes::from_slice(bytes)
    }
}

impl AlignedBytes {
    /// `len` zero bytes, from the allocator's zeroed memory (no pass over it).
    pub fn zeroed(len: usize) -> Self {
        AlignedBytes {
            blocks: bytemuck::zeroed_vec(len.div_ceil(64)),
            len,
        }
    }

    pub fn from_slice(bytes: &[u8]) -> Self {
        let mut blocks = vec![Block([0; 64]); bytes.len().div_ceil(64)];
        bytemuck::cast_slice_mut::<Block, u8>(&mut blocks)[..bytes.len()].copy_from_slice(bytes);
        AlignedBytes {
            blocks,
            len: bytes.len(),
        }
    }
    pub fn as_slice(&self) -> &[u8] {
        &bytemuck::cast_slice::<Block, u8>(&self.blocks)[..self.len]
    }
}

/// A readable artifact: its header and arrays, viewed in place.
pub struct Artifact {
    backing: Backing,
    header: Header,
    meta: Vec<u8>,
    arrays: Vec<ArrayDesc>,
}

impl fmt::Debug for Artifact {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Artifact")
            .field("kind", &self.header.kind)
            .field("hash", &self.header.content_hash)
            .field("bytes", &self.len())
            .finish()
    }
}

impl Artifact {
    /// Opens artifact bytes, checking header and lengths (not the payload hash: see
    /// [`Artifact::verify`]): the metadata must decode to exactly the header's metadata
    /// length, and every array must lie after it, aligned, inside the payload.
    pub fn open(backing: Backing) -> Result<Artifact, ArtifactError> {
        let bytes = backing.bytes();
        let header = Header::parse(bytes, Some(bytes.len()))?;
        let meta_end = HEADER_LEN + header.meta_len as usize;
        let (env, used): (Envelope, usize) =
            bincode::serde::decode_from_slice(&bytes[HEADER_LEN..meta_end], bincode_config())
                .map_err(|e| ArtifactError::Meta(e.to_string()))?;
        if used as u64 != header.meta_len {
            return Err(ArtifactError::Meta(format!(
                "metadata is {used} bytes, its header says {}",
                header.meta_len
            )));
        }
        for a in &env.arrays {
            let end = a.offset.checked_add(a.len);
            if a.offset % ALIGN as u64 != 0
                || a.offset < header.meta_len
                || end.is_none_or(|e| e > header.payload_len)
            {
                return Err(ArtifactError::ArrayBounds {
                    name: a.name.clone(),
                });
            }
        }
        Ok(Artifact {
            header,
            meta: env.meta,
            arrays: env.arrays,
            backing,
        })
    }

    pub fn from_bytes(bytes: impl Into<AlignedBytes>) -> Result<Artifact, ArtifactError> {
        Self::open(Backing::Owned(bytes.into()))
    }

    pub fn header(&self) -> &Header {
        &self.header
    }

    pub fn content_hash(&self) -> ContentHash {
        self.header.content_hash
    }

    pub fn len(&self) -> usize {
        self.backing.bytes().len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn kind(&self) -> Option<Kind> {
        Kind::from_code(self.header.kind)
    }

    pub fn expect_kind(&self, expected: Kind) -> Result<(), ArtifactError> {
        if self.header.kind != expected as u32 {
            return Err(ArtifactError::WrongKind {
                found: self.header.kind,
                expected,
            });
        }
        Ok(())
    }

    /// Re-hashes the payload and compares it with the header.
    pub fn verify(&self) -> Result<(), ArtifactError> {
        if ContentHash::of(&self.backing.bytes()[HEADER_LEN..]) != self.header.content_hash {
            return Err(ArtifactError::HashMismatch);
        }
        Ok(())
    }

    pub fn meta<M: DeserializeOwned>(&self) -> Result<M, ArtifactError> {
        bincode::serde::decode_from_slice(&self.meta, bincode_config())
            .map(|(m, _)| m)
            .map_err(|e| ArtifactError::Meta(e.to_string()))
    }

    pub fn raw_array(&self, name: &str) -> Result<&[u8], ArtifactError> {
        let a = self
            .arrays
            .iter()
            .find(|a| a.name == name)
            .ok_or_else(|| ArtifactError::MissingArray(name.to_owned()))?;
        let start = HEADER_LEN + a.offset as usize;
        Ok(&self.backing.bytes()[start..start + a.len as usize])
    }

    /// The names of the arrays, in stored order.
    pub fn array_names(&self) -> Vec<&str> {
        self.arrays.iter().map(|a| a.name.as_str()).collect()
    }

    /// A typed view of an array, in place (zero copy).
    pub fn array<T: bytemuck::Pod>(&self, name: &str) -> Result<&[T], ArtifactError> {
        let raw = self.raw_array(name)?;
        bytemuck::try_cast_slice(raw).map_err(|_| ArtifactError::ArrayShape {
            name: name.to_owned(),
            bytes: raw.len(),
            elem: std::mem::size_of::<T>(),
        })
    }

    /// The whole file's bytes (for writing to the cache).
    pub fn file_bytes(&self) -> &[u8] {
        self.backing.bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<u8> {
        ArtifactWriter::new(Kind::Mesh, &(7u32, "meta".to_string()))
            .array("a", &[1.0f32, 2.0, 3.0])
            .array("b", &[[1u32, 2, 3], [4, 5, 6]])
            .finish()
            .to_vec()
    }

    #[test]
    fn round_trip_views_arrays_in_place_and_aligned() {
        let art = Artifact::from_bytes(sample()).unwrap();
        art.verify().unwrap();
        art.expect_kind(Kind::Mesh).unwrap();
        assert_eq!(art.meta::<(u32, String)>().unwrap(), (7, "meta".into()));
        assert_eq!(art.array::<f32>("a").unwrap(), &[1.0, 2.0, 3.0]);
        assert_eq!(art.array::<[u32; 3]>("b").unwrap(), &[[1, 2, 3], [4, 5, 6]]);
        for name in ["a", "b"] {
            let off =
                art.raw_array(name).unwrap().as_ptr() as usize - art.file_bytes().as_ptr() as usize;
            assert_eq!(off % 64, 0, "{name} not aligned");
        }
        assert!(matches!(
            art.expect_kind(Kind::Image),
            Err(ArtifactError::WrongKind { .. })
        ));
    }

    #[test]
    fn writing_is_deterministic_and_hash_tracks_content() {
        assert_eq!(sample(), sample());
        let other = ArtifactWriter::new(Kind::Mesh, &(7u32, "meta".to_string()))
            .array("a", &[1.0f32, 2.0, 3.5])
            .array("b", &[[1u32, 2, 3], [4, 5, 6]])
            .finish();
        let h1 = Artifact::from_bytes(sample()).unwrap().content_hash();
        let h2 = Artifact::from_bytes(other).unwrap().content_hash();
        assert_ne!(h1, h2);
    }

    #[test]
    fn truncation_and_corruption_are_detected() {
        let bytes = sample();
        for cut in [0, 10, HEADER_LEN, bytes.len() - 1] {
            assert!(
                Artifact::from_bytes(bytes[..cut].to_vec()).is_err(),
                "cut {cut}"
            );
        }
        let mut flipped = bytes.clone();
        let last = flipped.len() - 70;
        flipped[last] ^= 0x40;
        let art = Artifact::from_bytes(flipped).unwrap();
        assert!(matches!(art.verify(), Err(ArtifactError::HashMismatch)));
        let mut bad_magic = bytes;
        bad_magic[0] = b'X';
        assert!(matches!(
            Artifact::from_bytes(bad_magic),
            Err(ArtifactError::BadMagic)
        ));
    }

    /// Every header field outside the payload hash is checked on open:
    /// the kind code, the reserved bytes, the metadata length, the payload length.
    #[test]
    fn damaged_header_fields_are_detected_on_open() {
        let bytes = sample();
        let damaged = |offset: usize, value: u8| {
            let mut b = bytes.clone();
            b[offset] = value;
            Artifact::from_bytes(b)
        };
        assert!(matches!(
            damaged(12, 99),
            Err(ArtifactError::UnknownKind(99))
        ));
        assert!(matches!(damaged(100, 1), Err(ArtifactError::Reserved)));
        let meta_len = bytes[16];
        assert!(damaged(16, meta_len + 8).is_err(), "longer metadata length");
        assert!(
            damaged(16, meta_len - 1).is_err(),
            "shorter metadata length"
        );
        assert!(damaged(24, bytes[24] ^ 0x40).is_err(), "payload length");
        // A known but different kind opens, and is refused by the reader expecting Mesh.
        let other = damaged(12, Kind::Image as u8).unwrap();
        assert!(other.expect_kind(Kind::Mesh).is_err());
    }

    /// An object from a machine of the other byte order is refused by name:
    /// flipping the mark plays that machine, no big-endian machine needed.
    #[test]
    fn an_object_of_the_other_byte_order_is_refused() {
        let mut b = sample();
        b[64..68].reverse();
        let e = Artifact::from_bytes(b).err().unwrap();
        assert!(matches!(e, ArtifactError::ByteOrder { .. }), "{e}");
        let here = if cfg!(target_endian = "big") {
            "big"
        } else {
            "little"
        };
        assert!(
            e.to_string()
                .contains(&format!("this {here}-endian machine")),
            "{e}"
        );
        let mut zero = sample();
        zero[64..68].fill(0);
        assert!(matches!(
            Artifact::from_bytes(zero),
            Err(ArtifactError::Reserved)
        ));
    }

    #[test]
    fn wrong_element_size_is_an_error_not_a_panic() {
        let art = Artifact::from_bytes(sample()).unwrap();
        assert!(art.array::<[f32; 2]>("a").is_err());
        assert!(art.array::<f32>("missing").is_err());
    }
}
