//! `texsyn pack` and `texsyn unpack`: a run packed into one archive comes
//! back into an empty cache whole, so `verify` passes and `run` computes nothing; a damaged,
//! foreign or crafted archive is refused and nothing is imported.
//!
//! Every test packs synth2d at 48×40 pixels (well under a second).

use crate::common;
use common::cli::{object_count, stderr, succeeded, texsyn};
use common::repo;
use std::path::{Path, PathBuf};
use std::process::Output;

const SETS: [&str; 4] = [
    "--set",
    "synthesize.width=48",
    "--set",
    "synthesize.height=40",
];

fn json(o: &Output) -> serde_json::Value {
    serde_json::from_slice(&o.stdout).expect("--json prints JSON")
}

/// A folder holding synth2d's config and exemplar, as a user's project would.
fn scratch() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("assets")).unwrap();
    std::fs::copy(
        repo().join("configs/assets/leopard.png"),
        dir.path().join("assets/leopard.png"),
    )
    .unwrap();
    std::fs::copy(
        repo().join("configs/synth2d.toml"),
        dir.path().join("synth2d.toml"),
    )
    .unwrap();
    dir
}

/// Packs the scratch run into `d/r.tar.zst` (cache `d/c`).
fn pack(d: &Path) -> PathBuf {
    succeeded(texsyn(
        &[
            &[
                "pack",
                "synth2d.toml",
                "--cache",
                "c",
                "-o",
                "r.tar.zst",
                "-q",
            ],
            &SETS[..],
        ]
        .concat(),
        d,
    ));
    d.join("r.tar.zst")
}

/// `unpack ARCHIVE --cache CACHE -o OUT` in `d`, asserted to fail naming the archive and
/// saying that nothing was imported; and nothing was: no object in the cache, no `OUT`.
fn assert_refused(d: &Path, archive: &str, cache: &str) -> String {
    let o = texsyn(&["unpack", archive, "--cache", cache, "-o", "u"], d);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{archive}: {e}");
    assert!(e.contains(archive), "the error names the archive: {e}");
    assert!(e.contains("nothing was imported"), "{e}");
    assert!(!e.contains("panicked"), "{e}");
    assert_eq!(
        object_count(&d.join(cache)),
        0,
        "{archive}: objects imported"
    );
    assert!(!d.join("u").exists(), "{archive}: files written");
    e
}

/// The entries of an archive: (path, bytes), in order.
fn read_entries(archive: &Path) -> Vec<(String, Vec<u8>)> {
    let file = std::fs::File::open(archive).unwrap();
    let mut tar = tar::Archive::new(zstd::stream::read::Decoder::new(file).unwrap());
    tar.entries()
        .unwrap()
        .map(|e| {
            let mut e = e.unwrap();
            let path = String::from_utf8(e.path_bytes().into_owned()).unwrap();
            let mut bytes = Vec::new();
            std::io::Read::read_to_end(&mut e, &mut bytes).unwrap();
            (path, bytes)
        })
        .collect()
}

/// Writes entries as texsyn does: tar in zstd, then the seal (a skippable frame holding
/// `TXSNPACK` and the blake3 hash of the bytes before it), so that what unpack refuses in a
/// crafted archive is the crafting, not the packaging.
fn write_archive(path: &Path, entries: &[(String, Vec<u8>)], sealed: bool) {
    let mut tar = tar::Builder::new(zstd::stream::write::Encoder::new(Vec::new(), 3).unwrap());
    for (name, bytes) in entries {
        let mut h = tar::Header::new_gnu();
        h.set_size(bytes.len() as u64);
        h.set_mode(0o644);
        tar.append_data(&mut h, name, &bytes[..]).unwrap();
    }
    let mut out = tar.into_inner().unwrap().finish().unwrap();
    if sealed {
        let hash = blake3::hash(&out);
        out.extend_from_slice(&[0x5E, 0x2A, 0x4D, 0x18]);
        out.extend_from_slice(&40u32.to_le_bytes());
        out.extend_from_slice(b"TXSNPACK");
        out.extend_from_slice(hash.as_bytes());
    }
    std::fs::write(path, out).unwrap();
}

/// The key the packed lock gives `node`.
fn locked_key(entries: &[(String, Vec<u8>)], node: &str) -> String {
    let lock = &entries
        .iter()
        .find(|(p, _)| p == "texsyn-pack/run.lock")
        .unwrap()
        .1;
    let lock = String::from_utf8(lock.clone()).unwrap();
    let line = lock
        .lines()
        .find(|l| l.split_whitespace().next() == Some(node))
        .unwrap();
    line.split_whitespace().nth(1).unwrap().to_owned()
}

/// The manifest, edited by `edit`, written back as the first entry.
fn edit_manifest(
    entries: &mut [(String, Vec<u8>)],
    edit: impl FnOnce(&mut Vec<serde_json::Value>),
) {
    assert_eq!(entries[0].0, "texsyn-pack/MANIFEST.json");
    let mut m: serde_json::Value = serde_json::from_slice(&entries[0].1).unwrap();
    edit(m["entries"].as_array_mut().unwrap());
    entries[0].1 = serde_json::to_vec(&m).unwrap();
}

fn manifest_entry(path: &str, bytes: &[u8]) -> serde_json::Value {
    serde_json::json!({
        "path": path,
        "role": "object",
        "size": bytes.len(),
        "blake3": blake3::hash(bytes).to_hex().to_string(),
    })
}

#[test]
fn an_unpacked_run_verifies_and_reruns_without_computing() {
    let dir = scratch();
    let d = dir.path();
    let ran = succeeded(texsyn(
        &[
            &[
                "run",
                "synth2d.toml",
                "--cache",
                "c",
                "--out",
                "o1",
                "--json",
            ],
            &SETS[..],
        ]
        .concat(),
        d,
    ));
    assert!(json(&ran)["nodes"].as_array().unwrap().len() == 4);
    let packed = json(&succeeded(texsyn(
        &[
            &[
                "pack",
                "synth2d.toml",
                "--cache",
                "c",
                "-o",
                "r.tar.zst",
                "--json",
            ],
            &SETS[..],
        ]
        .concat(),
        d,
    )));
    assert_eq!(packed["objects"], 4);
    assert_eq!(packed["computed"], 0, "everything was cached: {packed}");
    assert_eq!(packed["outputs"], 2);
    // The same run packs to the same bytes.
    succeeded(texsyn(
        &[
            &[
                "pack",
                "synth2d.toml",
                "--cache",
                "c",
                "-o",
                "r2.tar.zst",
                "-q",
            ],
            &SETS[..],
        ]
        .concat(),
        d,
    ));
    assert_eq!(
        std::fs::read(d.join("r.tar.zst")).unwrap(),
        std::fs::read(d.join("r2.tar.zst")).unwrap()
    );

    // Into an empty cache (which does not exist yet) and an empty folder.
    let unpacked = json(&succeeded(texsyn(
        &["unpack", "r.tar.zst", "--cache", "c2", "-o", "u", "--json"],
        d,
    )));
    assert_eq!(unpacked["imported"], 4, "{unpacked}");
    assert_eq!(unpacked["present"], 0);
    assert_eq!(object_count(&d.join("c2")), 4);
    let same = |a: &str, b: &str| {
        assert_eq!(
            std::fs::read(d.join(a)).unwrap(),
            std::fs::read(d.join(b)).unwrap(),
            "{a} differs from {b}"
        )
    };
    same("u/synth2d.toml", "synth2d.toml");
    same("u/assets/leopard.png", "assets/leopard.png");
    same("u/out/synth2d/synthesized.png", "o1/synthesized.png");
    same("u/out/synth2d/coordinates.png", "o1/coordinates.png");
    let lock = std::fs::read_to_string(d.join("u/synth2d.lock")).unwrap();
    assert!(lock.contains("# set: synthesize.width=48"), "{lock}");

    // The reader's checks: verify passes re-reading the imported objects, …
    let verified = json(&succeeded(texsyn(
        &[
            "verify",
            "u/synth2d.toml",
            "u/synth2d.lock",
            "--cache",
            "c2",
            "--json",
        ],
        d,
    )));
    assert_eq!(verified["artifacts"], 4);
    assert!(verified["mismatches"].as_array().unwrap().is_empty());
    assert!(verified["damaged"].as_array().unwrap().is_empty());
    // … `run` finds every node cached and rewrites no output, …
    let rerun = json(&succeeded(texsyn(
        &[
            &[
                "run",
                "u/synth2d.toml",
                "--cache",
                "c2",
                "--out",
                "u/out/synth2d",
                "--json",
            ],
            &SETS[..],
        ]
        .concat(),
        d,
    )));
    let nodes = rerun["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), 4);
    for n in nodes {
        assert_eq!(n["status"], "cached", "{n}");
    }
    for f in rerun["outputs"].as_array().unwrap() {
        assert_eq!(f["written"], false, "{f}");
    }
    // … and a recomputation from nothing gives the packed hashes.
    succeeded(texsyn(
        &[
            "verify",
            "u/synth2d.toml",
            "u/synth2d.lock",
            "--fresh",
            "-q",
        ],
        d,
    ));
    // Unpacking again is harmless: everything is there already.
    let again = json(&succeeded(texsyn(
        &["unpack", "r.tar.zst", "--cache", "c2", "-o", "u", "--json"],
        d,
    )));
    assert_eq!(
        (again["imported"].clone(), again["present"].clone()),
        (0.into(), 4.into())
    );
}

#[test]
fn a_flipped_or_missing_byte_is_refused_and_nothing_is_imported() {
    let dir = scratch();
    let d = dir.path();
    let good = std::fs::read(pack(d)).unwrap();
    let n = good.len();
    // The middle (an object's compressed bytes), the zstd frame header (a window-size bit
    // that would still decode the same content), early data, and the seal's hash.
    for (i, at) in [n / 2, 5, 40, n / 3, n - 1].into_iter().enumerate() {
        let mut bad = good.clone();
        bad[at] ^= 0x01;
        let name = format!("flipped{i}.tar.zst");
        std::fs::write(d.join(&name), &bad).unwrap();
        let e = assert_refused(d, &name, &format!("c{i}"));
        assert!(e.contains("is damaged or truncated"), "byte {at}: {e}");
    }
    std::fs::write(d.join("cut.tar.zst"), &good[..n / 2]).unwrap();
    let e = assert_refused(d, "cut.tar.zst", "cut");
    assert!(e.contains("is damaged or truncated"), "{e}");
    // A cache that already has objects keeps them as they were.
    succeeded(texsyn(&["unpack", "r.tar.zst", "--cache", "kept"], d));
    let before = object_count(&d.join("kept"));
    let mut bad = good.clone();
    bad[n / 2] ^= 0x80;
    std::fs::write(d.join("bad.tar.zst"), &bad).unwrap();
    assert_eq!(
        texsyn(&["unpack", "bad.tar.zst", "--cache", "kept"], d)
            .status
            .code(),
        Some(1)
    );
    assert_eq!(object_count(&d.join("kept")), before);
}

#[test]
fn a_foreign_archive_is_refused_by_name() {
    let dir = scratch();
    let d = dir.path();
    // Someone else's tar.zst.
    write_archive(
        &d.join("photos.tar.zst"),
        &[("holiday/readme.txt".into(), b"not texsyn".to_vec())],
        false,
    );
    let e = assert_refused(d, "photos.tar.zst", "c1");
    assert!(e.contains("is not a texsyn pack archive"), "{e}");
    assert!(e.contains("holiday/readme.txt"), "names what it found: {e}");
    // Not zstd at all.
    let e = assert_refused(d, "synth2d.toml", "c2");
    assert!(
        e.contains("is not a texsyn pack archive (not zstd-compressed)"),
        "{e}"
    );
    // The manifest's place, but another format's magic.
    write_archive(
        &d.join("other.tar.zst"),
        &[(
            "texsyn-pack/MANIFEST.json".into(),
            br#"{"magic": "other-pack", "format": 1}"#.to_vec(),
        )],
        false,
    );
    let e = assert_refused(d, "other.tar.zst", "c3");
    assert!(e.contains("is not a texsyn pack archive"), "{e}");
    // A later format is named as such.
    let real = pack(d);
    let mut entries = read_entries(&real);
    let mut m: serde_json::Value = serde_json::from_slice(&entries[0].1).unwrap();
    m["format"] = 2.into();
    entries[0].1 = serde_json::to_vec(&m).unwrap();
    write_archive(&d.join("future.tar.zst"), &entries, true);
    let e = assert_refused(d, "future.tar.zst", "c4");
    assert!(e.contains("pack format 2"), "{e}");
}

#[test]
fn a_crafted_archive_cannot_plant_an_object_under_a_key_it_does_not_earn() {
    let dir = scratch();
    let d = dir.path();
    let real = pack(d);
    let entries = read_entries(&real);
    let synth_key = locked_key(&entries, "synthesize");
    let synth_entry = format!("texsyn-pack/objects/{synth_key}");
    let synth_bytes = entries
        .iter()
        .find(|(p, _)| *p == synth_entry)
        .unwrap()
        .1
        .clone();

    // Control: the test's writer makes archives unpack accepts, so each refusal below is the
    // crafting's doing.
    write_archive(&d.join("control.tar.zst"), &entries, true);
    succeeded(texsyn(
        &["unpack", "control.tar.zst", "--cache", "control"],
        d,
    ));
    assert_eq!(object_count(&d.join("control")), 4);

    // 1. A valid artifact (synthesize's own bytes) planted under a key of the attacker's
    //    choosing, listed in the manifest with its true hash.
    let planted = blake3::hash(b"a key nobody earned").to_hex().to_string();
    let mut crafted = entries.clone();
    crafted.push((
        format!("texsyn-pack/objects/{planted}"),
        synth_bytes.clone(),
    ));
    edit_manifest(&mut crafted, |list| {
        list.push(manifest_entry(&format!("objects/{planted}"), &synth_bytes))
    });
    write_archive(&d.join("planted.tar.zst"), &crafted, true);
    let e = assert_refused(d, "planted.tar.zst", "c1");
    assert!(
        e.contains(&format!("objects/{planted}")),
        "names the entry: {e}"
    );
    assert!(e.contains("does not produce"), "{e}");

    // 2. The synthesize object moved to another key: that key is not earned, and the key the
    //    graph derives has no object.
    let mut moved = entries.clone();
    for (p, _) in moved.iter_mut() {
        if *p == synth_entry {
            *p = format!("texsyn-pack/objects/{planted}");
        }
    }
    edit_manifest(&mut moved, |list| {
        for e in list.iter_mut() {
            if e["path"] == format!("objects/{synth_key}") {
                e["path"] = format!("objects/{planted}").into();
            }
        }
    });
    write_archive(&d.join("moved.tar.zst"), &moved, true);
    let e = assert_refused(d, "moved.tar.zst", "c2");
    assert!(
        e.contains(&format!("objects/{synth_key}")) || e.contains(&format!("objects/{planted}")),
        "names the entry: {e}"
    );

    // 3. Another artifact's bytes under synthesize's key (the manifest's hash made to fit):
    //    the wrong kind for the node that earns the key.
    let import_key = locked_key(&entries, "import.exemplar");
    let import_bytes = entries
        .iter()
        .find(|(p, _)| *p == format!("texsyn-pack/objects/{import_key}"))
        .unwrap()
        .1
        .clone();
    let mut swapped = entries.clone();
    for (p, b) in swapped.iter_mut() {
        if *p == synth_entry {
            *b = import_bytes.clone();
        }
    }
    edit_manifest(&mut swapped, |list| {
        for e in list.iter_mut() {
            if e["path"] == format!("objects/{synth_key}") {
                let nodes = e["nodes"].clone();
                *e = manifest_entry(&format!("objects/{synth_key}"), &import_bytes);
                e["nodes"] = nodes;
            }
        }
    });
    write_archive(&d.join("swapped.tar.zst"), &swapped, true);
    let e = assert_refused(d, "swapped.tar.zst", "c3");
    assert!(e.contains(&format!("objects/{synth_key}")), "{e}");

    // 4. An unlisted entry slipped in after the manifest.
    let mut slipped = entries.clone();
    slipped.push((
        format!("texsyn-pack/objects/{planted}"),
        synth_bytes.clone(),
    ));
    write_archive(&d.join("slipped.tar.zst"), &slipped, true);
    let e = assert_refused(d, "slipped.tar.zst", "c4");
    assert!(e.contains("not listed in the manifest"), "{e}");
}

#[test]
fn an_input_by_absolute_path_is_not_packed() {
    let dir = scratch();
    let d = dir.path();
    let exemplar = d.join("assets/leopard.png");
    let o = texsyn(
        &[
            &[
                "pack",
                "synth2d.toml",
                "--cache",
                "c",
                "-o",
                "r.tar.zst",
                "-q",
            ],
            &SETS[..],
            &[
                "--set",
                &format!("inputs.exemplar={:?}", exemplar.to_str().unwrap()),
            ],
        ]
        .concat(),
        d,
    );
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("cannot pack synth2d.toml"), "{e}");
    assert!(
        e.contains(exemplar.to_str().unwrap()),
        "names the file: {e}"
    );
    assert!(e.contains("relative to the config"), "{e}");
    assert!(!d.join("r.tar.zst").exists());
    let left: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().contains("tar.zst"))
        .collect();
    assert!(left.is_empty(), "temporary archive left: {left:?}");
}

#[test]
fn unpacking_over_other_files_is_refused_before_importing() {
    let dir = scratch();
    let d = dir.path();
    pack(d);
    std::fs::create_dir_all(d.join("u")).unwrap();
    std::fs::write(d.join("u/synth2d.toml"), "method = \"synth2d\"  # mine\n").unwrap();
    let o = texsyn(&["unpack", "r.tar.zst", "--cache", "c2", "-o", "u"], d);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("u/synth2d.toml"), "names the file: {e}");
    assert!(
        e.contains("other content") && e.contains("nothing was imported"),
        "{e}"
    );
    assert_eq!(object_count(&d.join("c2")), 0);
    assert_eq!(
        std::fs::read_to_string(d.join("u/synth2d.toml")).unwrap(),
        "method = \"synth2d\"  # mine\n"
    );
    assert!(!d.join("u/assets").exists());
}

/// The path of the object file under `key` in a cache (`objects-v1/ab/cdef…`).
fn object_file(cache: &Path, key: &str) -> PathBuf {
    cache.join("objects-v1").join(&key[..2]).join(&key[2..])
}

/// A healthy object the user's cache already holds under one of the archive's keys, but with
/// other content (a code change without a version bump, or a crafted archive), is never
/// replaced: the archive is refused and nothing is imported.
#[test]
fn unpack_never_replaces_a_cached_object_with_other_content() {
    let dir = scratch();
    let d = dir.path();
    let archive = pack(d);
    let entries = read_entries(&archive);
    let (synth, analysis) = (
        locked_key(&entries, "synthesize"),
        locked_key(&entries, "analyse_exemplar"),
    );
    // A cache holding analyse_exemplar's (valid) object under synthesize's key.
    let from = object_file(&d.join("c"), &analysis);
    let mine_to = object_file(&d.join("mine"), &synth);
    assert!(from.is_file() && object_file(&d.join("c"), &synth).is_file());
    std::fs::create_dir_all(mine_to.parent().unwrap()).unwrap();
    std::fs::copy(&from, &mine_to).unwrap();
    let before = std::fs::read(&mine_to).unwrap();
    let o = texsyn(&["unpack", "r.tar.zst", "--cache", "mine"], d);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("synthesize") && e.contains("nothing was imported"),
        "{e}"
    );
    assert_eq!(
        std::fs::read(&mine_to).unwrap(),
        before,
        "the cached object was replaced"
    );
    assert_eq!(object_count(&d.join("mine")), 1, "objects were imported");
}

#[test]
fn unpack_follows_no_symlinked_folder_inside_its_destination() {
    let dir = scratch();
    let d = dir.path();
    pack(d);
    for link in ["assets", "out", "out/synth2d"] {
        let u = d.join("u");
        let elsewhere = d.join("elsewhere");
        let _ = std::fs::remove_dir_all(&u);
        let _ = std::fs::remove_dir_all(&elsewhere);
        std::fs::create_dir_all(&elsewhere).unwrap();
        let at = u.join(link);
        std::fs::create_dir_all(at.parent().unwrap()).unwrap();
        std::os::unix::fs::symlink(&elsewhere, &at).unwrap();
        let o = texsyn(&["unpack", "r.tar.zst", "--cache", "c2", "-o", "u"], d);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{link}: {e}");
        assert!(
            e.contains(&format!("u/{link}")) && e.contains("symbolic link"),
            "{link}: names the link: {e}"
        );
        assert!(e.contains("nothing was imported"), "{link}: {e}");
        assert!(!e.contains("panicked"), "{e}");
        assert_eq!(
            std::fs::read_dir(&elsewhere).unwrap().count(),
            0,
            "{link}: wrote through the link"
        );
        assert_eq!(object_count(&d.join("c2")), 0, "{link}: imported");
    }
}
