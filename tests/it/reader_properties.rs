//! Property tests of every reader of user files: meshes
//! (OBJ, OFF, PLY ascii and binary, STL ascii and binary), images (PNG, JPEG, EXR), configs,
//! curve files and lock files. Arbitrary bytes, and valid files with bytes flipped, cut or inserted,
//! must give `Ok` or an error: never a panic, and never an allocation beyond the input's size
//! times a small factor (a header may claim a billion vertices; the reader must not believe
//! it). The allocation bound is checked with a counting allocator, for this test binary only.
//! It counts per thread, and a reader runs on a one-thread rayon pool made of the checking
//! thread, so the count holds the reader's allocations, parallel parts included, and none of
//! the other tests that run beside it in this binary.

use proptest::prelude::*;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::Path;

/// Counts, per thread, the bytes allocated and not yet freed by it, and their peak since the
/// last reset.
struct Counting;

thread_local! {
    static LIVE: Cell<isize> = const { Cell::new(0) };
    static PEAK: Cell<isize> = const { Cell::new(0) };
}

fn count(delta: isize) {
    // `try_with`: a thread being torn down has no counters left; its frees are not counted.
    let _ = LIVE.try_with(|live| {
        let now = live.get() + delta;
        live.set(now);
        let _ = PEAK.try_with(|peak| peak.set(peak.get().max(now)));
    });
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count(layout.size() as isize);
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        count(-(layout.size() as isize));
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Largest allocation growth allowed while reading `n` bytes: 64 per input byte plus 4 MiB
/// (decoders keep fixed-size tables and buffers).
fn bound(n: usize) -> usize {
    64 * n + (4 << 20)
}

thread_local! {
    /// This thread as a pool's only worker (a thread stays in such a pool for its life, so
    /// one per thread): whatever a reader runs in parallel runs on it and is counted.
    static ONE_THREAD: rayon::ThreadPool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .use_current_thread()
        .build()
        .expect("a one-thread pool on the test's thread");
}

/// Runs `read` on `bytes` and checks the allocation bound; panics inside `read` fail the
/// property (proptest reports the input).
fn check(bytes: &[u8], read: impl FnOnce(&[u8]) + Send) {
    ONE_THREAD.with(|_| ()); // made before the count starts
    let base = LIVE.with(Cell::get);
    PEAK.with(|p| p.set(base));
    ONE_THREAD.with(|pool| pool.install(|| read(bytes)));
    let grew = (PEAK.with(Cell::get) - base).max(0) as usize;
    assert!(
        grew <= bound(bytes.len()),
        "reading {} bytes allocated {grew} bytes at once",
        bytes.len()
    );
}

fn data(path: &str) -> Vec<u8> {
    std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join(path)).unwrap()
}

fn read_mesh(name: &str, bytes: &[u8]) {
    let _ = texsyn::geom::io::read_mesh_bytes(Path::new(name), bytes);
}

fn read_image(name: &str, bytes: &[u8]) {
    let _ = texsyn::image::decode_image(Path::new(name), bytes);
}

/// A valid file with a few bytes changed: flipped, cut off, or repeated.
fn mutated(seed: Vec<u8>) -> impl Strategy<Value = Vec<u8>> {
    let n = seed.len().max(1);
    (
        prop::collection::vec((0..n, any::<u8>()), 1..8),
        0..=n,
        any::<bool>(),
    )
        .prop_map(move |(flips, cut, dup)| {
            let mut b = seed.clone();
            for (i, v) in flips {
                if i < b.len() {
                    b[i] = v;
                }
            }
            b.truncate(cut.max(1));
            if dup {
                let tail = b[b.len() / 2..].to_vec();
                b.extend_from_slice(&tail);
            }
            b
        })
}

/// Small valid files of every mesh format (tetrahedra and cubes from tests/data).
fn mesh_seeds() -> Vec<(&'static str, Vec<u8>)> {
    vec![
        (
            "m.off",
            data("tests/data/meshes/cactus.off")[..4000].to_vec(),
        ),
        ("m.ply", data("tests/data/meshes/cube_ascii.ply")),
        ("m.ply", data("tests/data/meshes/cube_le.ply")),
        ("m.ply", data("tests/data/meshes/cube_be.ply")),
        ("m.stl", data("tests/data/meshes/tetra_ascii.stl")),
        ("m.stl", data("tests/data/meshes/pig.stl")[..2000].to_vec()),
        (
            "m.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n".to_vec(),
        ),
    ]
}

const CASES: u32 = 256;

proptest! {
    #![proptest_config(ProptestConfig { cases: CASES, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn mesh_readers_survive_arbitrary_bytes(
        bytes in prop::collection::vec(any::<u8>(), 0..2048),
        ext in prop::sample::select(vec!["m.obj", "m.off", "m.ply", "m.stl"]),
    ) {
        check(&bytes, |b| read_mesh(ext, b));
    }

    #[test]
    fn mesh_readers_survive_mutated_files(
        (name, bytes) in prop::sample::select(mesh_seeds())
            .prop_flat_map(|(name, seed)| (Just(name), mutated(seed)))
    ) {
        check(&bytes, |b| read_mesh(name, b));
    }

    #[test]
    fn image_readers_survive_mutated_files(
        (name, bytes) in prop::sample::select(vec![
            ("e.png", data("tests/data/exemplars/leopard.png")),
            ("e.png", data("tests/data/exemplars/wood2.png")),
        ])
        .prop_flat_map(|(name, seed)| (Just(name), mutated(seed)))
    ) {
        check(&bytes, |b| read_image(name, b));
    }

    #[test]
    fn image_readers_survive_arbitrary_bytes(
        bytes in prop::collection::vec(any::<u8>(), 0..2048),
        ext in prop::sample::select(vec!["e.png", "e.jpg", "e.exr"]),
    ) {
        check(&bytes, |b| read_image(ext, b));
    }

    #[test]
    fn configs_and_curve_files_survive_mutations(
        bytes in mutated(data("configs/solid_elephant.toml")),
        curves in mutated(data("configs/solid_elephant_curves.toml")),
    ) {
        check(&bytes, |b| {
            let text = String::from_utf8_lossy(b);
            if let Ok(cfg) = texsyn::config::Config::from_str(Path::new("configs/x.toml"), &text, &[]) {
                let _ = texsyn::methods::plan(&cfg);
            }
        });
        check(&curves, |b| {
            let _ = texsyn::stages::field::quaternion_field::CurvesFile::read(b, 0);
        });
    }

    #[test]
    fn feature_curve_files_survive_mutations(
        toml in mutated(data("configs/feature_aligned_cow_curves.toml")),
        obj in mutated(OBJ_LINES.to_vec()),
        config in mutated(data("configs/feature_aligned_curves.toml")),
    ) {
        use texsyn::stages::extract::shape_features::read_curves_file;
        check(&toml, |b| {
            let _ = read_curves_file("curves.toml", b);
        });
        check(&obj, |b| {
            let _ = read_curves_file("lines.obj", b);
        });
        check(&config, |b| {
            let text = String::from_utf8_lossy(b);
            if let Ok(cfg) = texsyn::config::Config::from_str(Path::new("configs/x.toml"), &text, &[]) {
                let _ = texsyn::methods::plan(&cfg);
            }
        });
    }

    #[test]
    fn lock_files_survive_mutations_and_round_trip(
        mutated_lock in mutated(data("configs/demo.lock")),
        arbitrary in prop::collection::vec(any::<u8>(), 0..1024),
    ) {
        use texsyn::ops::lockfile::LockFile;
        let reference = LockFile::parse(
            &String::from_utf8(data("configs/demo.lock")).unwrap(),
            Path::new("demo.lock"),
        )
        .unwrap();
        for bytes in [&mutated_lock, &arbitrary] {
            check(bytes, |b| {
                let text = String::from_utf8_lossy(b);
                if let Ok(lock) = LockFile::parse(&text, Path::new("x.lock")) {
                    // What parses is what `hashes` would write back, and compares cleanly.
                    let again = LockFile::parse(&lock.to_text(), Path::new("y.lock")).unwrap();
                    assert_eq!(again, lock);
                    let _ = reference.compare(&lock);
                }
            });
        }
    }
}

/// A `lines.obj` as a feature-aligned run writes it.
const OBJ_LINES: &[u8] = b"# feature curves\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\ng crease\nl 1 2 3\nl 3 4 1 3\ng user\nl -1 -2\n";

/// Headers that lie about their sizes, kept as a corpus: each must be a clear error, quickly.
#[test]
fn headers_that_claim_more_than_the_file_holds_are_errors() {
    let cases: [(&str, &[u8]); 4] = [
        ("m.off", b"OFF\n2000000000 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
        (
            "m.ply",
            b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n",
        ),
        ("m.stl", &[0u8; 84]),
        ("m.stl", &{
            let mut b = vec![0u8; 84];
            b[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
            b
        }),
    ];
    for (name, bytes) in cases {
        check(bytes, |b| {
            assert!(
                texsyn::geom::io::read_mesh_bytes(Path::new(name), b).is_err(),
                "{name}: {:?}",
                String::from_utf8_lossy(&b[..b.len().min(40)])
            )
        });
    }
}

/// The allocation bound can fail: a reader that believed a header claiming 64 MiB would.
#[test]
#[should_panic(expected = "allocated")]
fn the_bound_catches_a_reader_that_believes_its_header() {
    check(b"OFF\n", |_| {
        std::hint::black_box(vec![1u8; 64 << 20]);
    });
}
