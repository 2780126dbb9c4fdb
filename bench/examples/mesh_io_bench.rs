//! Mesh import and export speed: what the import node does (parse and
//! validate, `<Mesh as Import>::read` on the file's bytes) for ASCII OFF, OBJ, ASCII PLY,
//! binary PLY and binary STL, and the OBJ and binary PLY writers, on refined_elephant.off
//! subdivided twice (711,420 vertices, 1,422,848 triangles).
//!
//! ```text
//! cargo run --release -p texsyn-bench --example mesh_io_bench
//! ```
//!
//! The big mesh comes from `../shared/data/meshes/refined_elephant.off` (or
//! `$TEXSYN_SHARED_DATA/meshes`); when that is absent, the demo's cow subdivided three times
//! stands in and the output says so. The input files are written once into
//! `$TMPDIR/texsyn-mesh-io-bench/` (about 250 MB; delete it afterwards). Each read runs in a
//! child process of its own so that its peak memory (getrusage's maximum resident set) is its
//! own: the file's bytes, the mesh and the reader's working memory, plus the process's ~10 MB.
//! Every figure is the median of `RUNS` runs (default 5). The blake3 hash of each parsed mesh
//! (positions' bits, triangles, colours) is printed so that two versions of the readers can be
//! compared for bit-identical results, and the hash of each written file likewise.

use std::path::{Path, PathBuf};
use std::time::Instant;
use texsyn::geom::Mesh;
use texsyn::methods::Import;

/// A mesh writer: what the bench times, or what makes its input files.
type Writer = fn(&Mesh) -> Vec<u8>;
type DynWriter<'a> = &'a dyn Fn(&Mesh) -> Vec<u8>;

fn runs() -> usize {
    std::env::var("RUNS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(5)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// Peak resident memory of this process so far, in bytes.
fn peak_rss() -> u64 {
    // SAFETY: getrusage fills the struct it is given.
    unsafe {
        let mut u: libc::rusage = std::mem::zeroed();
        libc::getrusage(libc::RUSAGE_SELF, &mut u);
        u.ru_maxrss as u64 * 1024
    }
}

/// CPU seconds (user + system, all threads) this process has used.
fn cpu_seconds() -> f64 {
    // SAFETY: getrusage fills the struct it is given.
    let u = unsafe {
        let mut u: libc::rusage = std::mem::zeroed();
        libc::getrusage(libc::RUSAGE_SELF, &mut u);
        u
    };
    let t = |v: libc::timeval| v.tv_sec as f64 + v.tv_usec as f64 * 1e-6;
    t(u.ru_utime) + t(u.ru_stime)
}

/// The mesh's own size: positions, triangles and colours as stored.
fn mesh_bytes(m: &Mesh) -> usize {
    12 * m.positions.len() + 12 * m.triangles.len() + m.colors.as_ref().map_or(0, |c| 16 * c.len())
}

fn mesh_hash(m: &Mesh) -> String {
    let mut h = blake3::Hasher::new();
    h.update(bytemuck::cast_slice(&m.positions));
    h.update(bytemuck::cast_slice(&m.triangles));
    if let Some(c) = &m.colors {
        h.update(bytemuck::cast_slice(c));
    }
    h.finalize().to_hex()[..16].to_string()
}

/// Child: parse `path` `RUNS` times, print "seconds cpu_seconds peak_bytes mesh_bytes hash".
/// `reference`: with the one-line-at-a-time reference readers (what the fast paths replaced)
/// and the import node's coordinate check, for a before/after comparison on the same machine
/// at the same time.
fn child(path: &Path, reference: bool) {
    let bytes = std::fs::read(path).unwrap();
    let mut times = Vec::new();
    let mut cpu = Vec::new();
    let mut last = None;
    for _ in 0..runs() {
        drop(last.take());
        let (t, c) = (Instant::now(), cpu_seconds());
        let m = if reference {
            let m = texsyn::geom::io::read_mesh_bytes_reference(path, &bytes).unwrap();
            assert!(m.positions.iter().all(|p| p.abs().max_element() <= 1e15));
            m
        } else {
            <Mesh as Import>::read(path, &bytes).unwrap()
        };
        times.push(t.elapsed().as_secs_f64());
        cpu.push(cpu_seconds() - c);
        last = Some(m);
    }
    let m = last.unwrap();
    println!(
        "{} {} {} {} {}",
        median(times),
        median(cpu),
        peak_rss(),
        mesh_bytes(&m),
        mesh_hash(&m)
    );
}

fn fmt_f32(x: f32) -> String {
    format!("{x}")
}

/// ASCII OFF, as a modelling tool writes it.
fn write_off(m: &Mesh) -> Vec<u8> {
    use std::fmt::Write;
    let mut s = format!("OFF\n{} {} 0\n", m.positions.len(), m.triangles.len());
    for p in &m.positions {
        let _ = writeln!(s, "{} {} {}", fmt_f32(p.x), fmt_f32(p.y), fmt_f32(p.z));
    }
    for t in &m.triangles {
        let _ = writeln!(s, "3 {} {} {}", t[0], t[1], t[2]);
    }
    s.into_bytes()
}

fn write_ply_ascii(m: &Mesh) -> Vec<u8> {
    use std::fmt::Write;
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

fn write_stl(m: &Mesh) -> Vec<u8> {
    let mut out = vec![0u8; 80];
    out.extend_from_slice(&(m.triangles.len() as u32).to_le_bytes());
    for t in &m.triangles {
        out.extend_from_slice(&[0u8; 12]);
        for &v in t {
            for x in m.positions[v as usize].to_array() {
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
        out.extend_from_slice(&[0, 0]);
    }
    out
}

fn big_mesh() -> (Mesh, String) {
    let repo = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let data = [
        std::env::var_os("TEXSYN_SHARED_DATA").map(PathBuf::from),
        Some(repo.join("../shared/data")),
    ]
    .into_iter()
    .flatten()
    .map(|d| d.join("meshes/refined_elephant.off"))
    .find(|p| p.is_file());
    use texsyn::geom::subdivide::subdivide;
    match data {
        Some(p) => {
            let m = texsyn::geom::io::read_mesh(&p).unwrap();
            (
                subdivide(&subdivide(&m)),
                "refined_elephant.off subdivided twice".into(),
            )
        }
        None => {
            println!(
                "note: ../shared/data/meshes/refined_elephant.off is absent; using configs/assets/cow.obj subdivided 3 times"
            );
            let m = texsyn::geom::io::read_mesh(&repo.join("configs/assets/cow.obj")).unwrap();
            (
                subdivide(&subdivide(&subdivide(&m))),
                "cow.obj subdivided 3 times".into(),
            )
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() == 3 && args[1].starts_with("--child") {
        child(Path::new(&args[2]), args[1] == "--child-reference");
        return;
    }
    let runs = runs();
    let dir = std::env::temp_dir().join("texsyn-mesh-io-bench");
    std::fs::create_dir_all(&dir).unwrap();
    let (mesh, name) = big_mesh();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "{name}: {} vertices, {} triangles ({:.1} MB as arrays); {cores} cores, {} rayon threads; median of {runs} runs",
        mesh.positions.len(),
        mesh.triangles.len(),
        mesh_bytes(&mesh) as f64 / 1e6,
        rayon::current_num_threads()
    );
    let files: [(&str, Writer); 5] = [
        ("big.off", write_off),
        ("big.obj", |m| {
            texsyn::export::obj::write_obj(m, None, None, "m").into_bytes()
        }),
        ("big_ascii.ply", write_ply_ascii),
        ("big_binary.ply", |m| texsyn::geom::io::write_ply(m, None)),
        ("big.stl", write_stl),
    ];
    println!(
        "| read (parse + validate) | file MB | MB/s (wall) | s (wall) | CPU s (all threads) | MB per CPU s | peak RSS MB | peak / mesh | mesh hash |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let readers = files
        .iter()
        .map(|&(file, write)| (file, write, "--child"))
        .chain(
            files[..4]
                .iter()
                .map(|&(file, write)| (file, write, "--child-reference")),
        );
    for (file, write, how) in readers {
        let p = dir.join(file);
        if !p.is_file() {
            std::fs::write(&p, write(&mesh)).unwrap();
        }
        let file = if how == "--child" {
            file.to_string()
        } else {
            format!("{file} (reference reader)")
        };
        let size = std::fs::metadata(&p).unwrap().len() as f64;
        let out = std::process::Command::new(std::env::current_exe().unwrap())
            .arg(how)
            .arg(&p)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8(out.stdout).unwrap();
        let f: Vec<&str> = text.split_whitespace().collect();
        let num = |i: usize| f[i].parse::<f64>().unwrap();
        let (secs, cpu, peak, mbytes) = (num(0), num(1), num(2), num(3));
        println!(
            "| {file} | {:.1} | {:.0} | {secs:.3} | {cpu:.3} | {:.0} | {:.0} | {:.1}× | {} |",
            size / 1e6,
            size / 1e6 / secs,
            size / 1e6 / cpu,
            peak / 1e6,
            peak / mbytes,
            f[4]
        );
    }
    println!();
    println!("| write | file MB | MB/s (wall) | s (wall) | CPU s | MB per CPU s | output hash |");
    println!("|---|---|---|---|---|---|---|");
    let writers: [(&str, Writer); 2] = [
        ("OBJ (write_obj, no uv)", |m| {
            texsyn::export::obj::write_obj(m, None, None, "m").into_bytes()
        }),
        ("binary PLY (write_ply)", |m| {
            texsyn::geom::io::write_ply(m, None)
        }),
    ];
    // Per-corner texture coordinates as reconstruct writes them: continuous over the mesh (a
    // vertex's corners share one `vt`) except where a coordinate wraps.
    let uv: Vec<[glam::Vec2; 3]> = mesh
        .triangles
        .iter()
        .map(|t| {
            t.map(|v| {
                let p = mesh.positions[v as usize];
                glam::Vec2::new((p.x * 3.7).fract(), (p.y * 2.3 + p.z).fract())
            })
        })
        .collect();
    let with_uv =
        |m: &Mesh| texsyn::export::obj::write_obj(m, Some(&uv), Some("m.mtl"), "m").into_bytes();
    let writers: Vec<(&str, DynWriter)> = writers
        .iter()
        .map(|(w, f)| (*w, f as DynWriter))
        .chain([("OBJ (write_obj, per-corner uv)", &with_uv as DynWriter)])
        .collect();
    for (what, write) in writers {
        let mut times = Vec::new();
        let mut cpu = Vec::new();
        let mut last = Vec::new();
        for _ in 0..runs {
            drop(std::mem::take(&mut last));
            let (t, c) = (Instant::now(), cpu_seconds());
            last = write(&mesh);
            times.push(t.elapsed().as_secs_f64());
            cpu.push(cpu_seconds() - c);
        }
        let (secs, cpu) = (median(times), median(cpu));
        let size = last.len() as f64;
        println!(
            "| {what} | {:.1} | {:.0} | {secs:.3} | {cpu:.3} | {:.0} | {} |",
            size / 1e6,
            size / 1e6 / secs,
            size / 1e6 / cpu,
            &blake3::hash(&last).to_hex()[..16]
        );
    }
}
