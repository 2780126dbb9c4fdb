//! The output folder after failures and kills: a run's outputs are
//! written as a set, a swap a killed run left half done is finished or undone by the next
//! command, dead processes' temporaries are removed (and nothing that is not texsyn's), and
//! input files that are not regular files, or whose header claims more than they hold, fail
//! fast. Everything runs the real binary on configs/synth2d.toml (fast).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use texsyn::owner::Owner;

const CONFIG: &str = "configs/synth2d.toml";
/// synth2d's exports.
const OUTPUTS: [&str; 2] = ["coordinates.png", "synthesized.png"];

struct Output {
    ok: bool,
    stderr: String,
}

/// Runs texsyn with `args` (and `env`), killing it and failing the test if it takes longer
/// than a minute (a FIFO input would otherwise hang the test forever).
fn texsyn_env(args: &[&str], env: &[(&str, &Path)]) -> Output {
    let logs = tempfile::tempdir().unwrap();
    let (out, err) = (logs.path().join("out"), logs.path().join("err"));
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_texsyn"));
    cmd.current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out).unwrap())
        .stderr(std::fs::File::create(&err).unwrap());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let mut child = cmd.spawn().unwrap();
    let deadline = Instant::now() + Duration::from_secs(60);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "texsyn {args:?} still running after 60 s (killed); stderr: {}",
                std::fs::read_to_string(&err).unwrap_or_default()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Output {
        ok: status.success(),
        stderr: std::fs::read_to_string(&err).unwrap(),
    }
}

fn texsyn(args: &[&str]) -> Output {
    texsyn_env(args, &[])
}

/// `texsyn run` of synth2d with `seed` into `out`, with the cache at `cache`.
fn run(cache: &Path, out: &Path, seed: u32) -> Output {
    run_with(cache, out, seed, &[])
}

/// [`run`] with `extra` arguments.
fn run_with(cache: &Path, out: &Path, seed: u32, extra: &[&str]) -> Output {
    let seed = format!("synthesize.seed={seed}");
    let mut args = vec![
        "run",
        CONFIG,
        "-q",
        "--cache",
        cache.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--set",
        &seed,
    ];
    args.extend(extra);
    texsyn(&args)
}

fn run_ok(cache: &Path, out: &Path, seed: u32) {
    let o = run(cache, out, seed);
    assert!(o.ok, "run failed: {}", o.stderr);
}

/// Every entry of `dir` (recursively), files with their bytes, folders as `None`.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Option<Vec<u8>>> {
    let mut all = BTreeMap::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let e = e.unwrap();
        let p = e.path();
        let rel = PathBuf::from(e.file_name());
        if e.file_type().unwrap().is_dir() {
            all.insert(rel.clone(), None);
            for (k, v) in snapshot(&p) {
                all.insert(rel.join(k), v);
            }
        } else {
            all.insert(rel, Some(std::fs::read(&p).unwrap()));
        }
    }
    all
}

/// The owner tag of a process that has exited (a finished child).
fn dead_pid() -> String {
    let mut child = Command::new("true").spawn().unwrap();
    let pid = child.id();
    child.wait().unwrap();
    Owner::with_pid(pid).tag()
}

/// The owner tag of a process in another PID namespace (or on another host): its liveness
/// cannot be checked from here.
fn foreign_owner() -> String {
    let mut parts: Vec<String> = Owner::this().tag().split('_').map(String::from).collect();
    parts[2] = "1".into();
    parts[3] = "7".into();
    parts.join("_")
}

/// Sets `path`'s modification time `secs` seconds into the past.
fn age(path: &Path, secs: u64) {
    let t = std::time::SystemTime::now() - std::time::Duration::from_secs(secs);
    std::fs::File::options()
        .write(true)
        .open(path)
        .or_else(|_| std::fs::File::open(path))
        .unwrap()
        .set_modified(t)
        .unwrap();
}

/// The outputs of seed 1 and of seed 2, each written by a run into its own folder.
fn two_runs(cache: &Path, root: &Path) -> (PathBuf, PathBuf) {
    let (a, b) = (root.join("a"), root.join("b"));
    run_ok(cache, &a, 1);
    run_ok(cache, &b, 2);
    for name in OUTPUTS {
        assert_ne!(
            std::fs::read(a.join(name)).unwrap(),
            std::fs::read(b.join(name)).unwrap(),
            "{name}: seeds 1 and 2 must give other files for these tests to mean anything"
        );
    }
    (a, b)
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}

#[test]
fn a_failed_export_leaves_the_previous_outputs_whole() {
    let root = tempfile::tempdir().unwrap();
    let cache = root.path().join("cache");
    // Each output in turn is the one that cannot be written, so the failure falls both
    // before and after the other file in the bundle's order.
    for blocked in OUTPUTS {
        let out = root.path().join(format!("out-{blocked}"));
        run_ok(&cache, &out, 1);
        std::fs::remove_file(out.join(blocked)).unwrap();
        std::fs::create_dir(out.join(blocked)).unwrap();
        std::fs::write(out.join(blocked).join("mine.txt"), b"not texsyn's").unwrap();
        std::fs::write(out.join("notes.txt"), b"mine").unwrap();
        let before = snapshot(&out);

        let o = run(&cache, &out, 2);
        assert!(!o.ok, "the run must fail when {blocked} is a directory");
        assert!(
            o.stderr.contains(blocked) && o.stderr.contains("is a directory"),
            "the message must name the output and the problem: {}",
            o.stderr
        );
        assert_eq!(
            snapshot(&out),
            before,
            "{blocked} blocked: the folder must hold exactly the previous run's outputs, \
             with no temporary files or staging folder left"
        );
    }
}

#[test]
fn an_interrupted_swap_is_completed_or_rolled_back_by_the_next_command() {
    let root = tempfile::tempdir().unwrap();
    let cache = root.path().join("cache");
    let (a, b) = two_runs(&cache, root.path());
    // A command that recovers the output folder and then fails (its cache is a file): what
    // it leaves is the recovery alone.
    let not_a_cache = root.path().join("not-a-cache");
    std::fs::write(&not_a_cache, b"").unwrap();
    let recover = |out: &Path| {
        texsyn(&[
            "run",
            CONFIG,
            "-q",
            "--cache",
            not_a_cache.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
    };

    for (case, staged_complete) in [("complete", true), ("incomplete", false)] {
        // A run with seed 2, killed after the journal was written and the first file swapped:
        // coordinates.png is new (old copy aside), synthesized.png still old (new one staged).
        let out = root.path().join(case);
        copy_dir(&a, &out);
        std::fs::write(out.join("notes.txt"), b"mine").unwrap();
        let pid = dead_pid();
        let staging = out.join(format!(".texsyn-staging-{pid}"));
        let old = out.join(format!(".texsyn-old-{pid}"));
        std::fs::create_dir(&staging).unwrap();
        std::fs::create_dir(&old).unwrap();
        std::fs::rename(out.join(OUTPUTS[0]), old.join(OUTPUTS[0])).unwrap();
        std::fs::copy(b.join(OUTPUTS[0]), out.join(OUTPUTS[0])).unwrap();
        if staged_complete {
            std::fs::copy(b.join(OUTPUTS[1]), staging.join(OUTPUTS[1])).unwrap();
        }
        std::fs::write(
            out.join(format!(".texsyn-swap-{pid}")),
            format!(
                "texsyn output swap 1\nreplace {}\nreplace {}\nend\n",
                OUTPUTS[0], OUTPUTS[1]
            ),
        )
        .unwrap();

        let o = recover(&out);
        assert!(!o.ok, "{case}: the cache is a file, the run must fail");
        let mut expected = snapshot(if staged_complete { &b } else { &a });
        expected.insert("notes.txt".into(), Some(b"mine".to_vec()));
        assert_eq!(
            snapshot(&out),
            expected,
            "{case}: the folder must hold all of the {} run's outputs and nothing else of texsyn's",
            if staged_complete { "new" } else { "old" }
        );
    }
}

#[test]
fn stale_temporaries_of_dead_processes_are_removed_and_nothing_else() {
    let root = tempfile::tempdir().unwrap();
    let cache = root.path().join("cache");
    let out = root.path().join("out");
    run_ok(&cache, &out, 1);
    let dead = dead_pid();
    let alive = Owner::this().tag(); // this test process, running
    let stale = [
        format!(".{}.tmp-{dead}", OUTPUTS[0]),
        format!(".{}.tmp-{dead}", OUTPUTS[1]),
    ];
    for s in &stale {
        std::fs::write(out.join(s), b"half written").unwrap();
    }
    std::fs::create_dir(out.join(format!(".texsyn-staging-{dead}"))).unwrap();
    std::fs::write(out.join(format!(".texsyn-staging-{dead}/x.png")), b"x").unwrap();
    let live = format!(".{}.tmp-{alive}", OUTPUTS[0]);
    std::fs::write(out.join(&live), b"being written").unwrap();
    std::fs::write(out.join("notes.txt"), b"mine").unwrap();
    std::fs::write(out.join(".notes.tmp-x"), b"mine too").unwrap();
    // A writer in another PID namespace (or on another host), whose liveness cannot be
    // checked from here: its young files stay, its files past the age limit go. A bare
    // process id says nothing of the namespace: such a file stays too while young.
    let foreign = foreign_owner();
    let foreign_young = format!(".{}.tmp-{foreign}", OUTPUTS[0]);
    let foreign_staging = format!(".texsyn-staging-{foreign}");
    std::fs::write(out.join(&foreign_young), b"being written elsewhere").unwrap();
    std::fs::create_dir(out.join(&foreign_staging)).unwrap();
    std::fs::write(out.join(&foreign_staging).join("x.png"), b"x").unwrap();
    let foreign_old = format!(".{}.tmp-{foreign}", OUTPUTS[1]);
    std::fs::write(out.join(&foreign_old), b"left a day ago").unwrap();
    age(&out.join(&foreign_old), 25 * 3600);
    let bare = format!(".{}.tmp-{}", OUTPUTS[1], dead.rsplit('_').next().unwrap());
    std::fs::write(out.join(&bare), b"no namespace said").unwrap();

    run_ok(&cache, &out, 2);
    let names: Vec<String> = snapshot(&out)
        .keys()
        .map(|k| k.to_string_lossy().into_owned())
        .collect();
    let mut expected: Vec<String> = OUTPUTS.iter().map(|s| s.to_string()).collect();
    expected.extend([
        live,
        "notes.txt".into(),
        ".notes.tmp-x".into(),
        foreign_young,
        foreign_staging.clone(),
        format!("{foreign_staging}/x.png"),
        bare,
    ]);
    expected.sort();
    assert_eq!(names, expected);
    assert_eq!(std::fs::read(out.join("notes.txt")).unwrap(), b"mine");
}

#[test]
fn verify_fresh_removes_the_temporary_caches_of_killed_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let dead = tmp.path().join(format!("texsyn-verify-{}-123", dead_pid()));
    let live = tmp
        .path()
        .join(format!("texsyn-verify-{}-456", Owner::this().tag()));
    for d in [&dead, &live] {
        std::fs::create_dir(d).unwrap();
        std::fs::write(d.join("object"), b"cached").unwrap();
    }
    let o = texsyn_env(
        &["verify", "--fresh", "-q", CONFIG, "configs/synth2d.lock"],
        &[("TMPDIR", tmp.path())],
    );
    assert!(o.ok, "verify failed: {}", o.stderr);
    let left: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(
        left,
        vec![live],
        "only the live process's temporary cache may stay"
    );
}

/// Runs `config` with `key` set to `path` and asserts a quick failure naming the key, the
/// path and that it is not a regular file.
fn assert_refused(config: &str, key: &str, path: &Path) {
    let cache = tempfile::tempdir().unwrap();
    let out = tempfile::tempdir().unwrap();
    let o = texsyn(&[
        "run",
        config,
        "-q",
        "--cache",
        cache.path().to_str().unwrap(),
        "--out",
        out.path().to_str().unwrap(),
        "--set",
        &format!("{key}=\"{}\"", path.display()),
    ]);
    assert!(!o.ok, "{key} = {}: must fail", path.display());
    for word in [key, &path.display().to_string(), "not a regular file"] {
        assert!(
            o.stderr.contains(word),
            "expected {word:?} in: {}",
            o.stderr
        );
    }
}

#[test]
fn a_fifo_or_device_as_an_input_fails_fast_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    // /dev/zero behind a mesh extension, so the mesh reader would be chosen for it.
    let zero = dir.path().join("zero.off");
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    assert_refused("configs/demo.toml", "inputs.mesh", &zero);
    assert_refused(CONFIG, "inputs.exemplar", Path::new("/dev/zero"));

    let fifo = dir.path().join("exemplar.png");
    match Command::new("mkfifo").arg(&fifo).status() {
        Ok(s) if s.success() => assert_refused(CONFIG, "inputs.exemplar", &fifo),
        _ => eprintln!("mkfifo is missing: FIFO case skipped"),
    }
}

#[test]
fn an_off_header_claiming_billions_of_vertices_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = dir.path().join("huge.off");
    std::fs::write(&mesh, "OFF\n2000000000 1 0\n0 0 0\n1 0 0\n0 1 0\n").unwrap();
    let o = texsyn(&[
        "render",
        mesh.to_str().unwrap(),
        "-o",
        dir.path().join("x.png").to_str().unwrap(),
    ]);
    assert!(!o.ok);
    assert!(
        o.stderr.contains("huge.off") && o.stderr.contains("end of file after 3 of 2000000000"),
        "{}",
        o.stderr
    );
}

/// Two processes writing one output folder take turns (the folder's advisory lock): a run
/// waits while another holds the folder, and writes its whole set once it is released. Here
/// the test process plays the other writer. Without the lock, the run would swap its files in
/// while the other writer is mid-swap, and the folder could end with a mix of both.
#[test]
fn a_second_writer_waits_for_the_folder_lock() {
    let root = tempfile::tempdir().unwrap();
    let cache = root.path().join("cache");
    let out = root.path().join("out");
    run_ok(&cache, &out, 1);
    let before = snapshot(&out);
    // Cache the seed-2 result first, so the locked run below only has to write its outputs.
    let other = root.path().join("other");
    run_ok(&cache, &other, 2);

    let held = std::fs::File::open(&out).unwrap();
    held.lock().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_texsyn"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["run", CONFIG, "-q", "--cache"])
        .arg(&cache)
        .arg("--out")
        .arg(&out)
        .args(["--set", "synthesize.seed=2"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // A cached run writes its outputs in well under a second; give it three.
    std::thread::sleep(Duration::from_secs(3));
    let waiting = child.try_wait().unwrap().is_none();
    let untouched = snapshot(&out) == before;
    held.unlock().unwrap();
    let status = child.wait().unwrap();
    assert!(waiting, "the run did not wait for the folder's lock");
    assert!(untouched, "the run wrote into a folder another writer held");
    assert!(status.success());
    assert_eq!(
        snapshot(&out),
        snapshot(&other),
        "the released run wrote its whole set"
    );
}

/// Flips one byte in the middle of every cache object's file (each payload then fails its
/// hash; the headers stay readable).
fn damage_every_object(cache: &Path) {
    fn walk(dir: &Path, files: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            if e.file_type().unwrap().is_dir() {
                walk(&e.path(), files);
            } else {
                files.push(e.path());
            }
        }
    }
    let mut files = Vec::new();
    walk(&cache.join("objects-v1"), &mut files);
    assert!(
        !files.is_empty(),
        "no cache objects under {}",
        cache.display()
    );
    for f in files {
        let mut bytes = std::fs::read(&f).unwrap();
        let mid = bytes.len() - 1 - bytes.len() / 4;
        bytes[mid] ^= 0x5a;
        std::fs::write(&f, bytes).unwrap();
    }
}

/// `texsyn run` of synth2d seed 1 with `extra` flags; its `--report` JSON.
fn run_report(cache: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let report = out.with_extension("report.json");
    let mut args = vec!["--report", report.to_str().unwrap()];
    args.extend(extra);
    let o = run_with(cache, out, 1, &args);
    assert!(o.ok, "run {extra:?} failed: {}", o.stderr);
    serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap()
}

/// The one record of output stamps in `cache` (README, "Set up and run").
fn record_of(cache: &Path) -> PathBuf {
    let records: Vec<PathBuf> = std::fs::read_dir(cache.join(texsyn::pipeline::stamps::RECORDS))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| !p.to_string_lossy().contains(".tmp-"))
        .collect();
    assert_eq!(records.len(), 1, "{records:?}");
    records[0].clone()
}

#[test]
fn a_rerun_trusts_stamped_outputs_and_reads_an_edited_or_missing_one_again() {
    use std::os::unix::fs::MetadataExt;
    let root = tempfile::tempdir().unwrap();
    let (cache, out) = (root.path().join("cache"), root.path().join("out"));
    run_ok(&cache, &out, 1);
    let want: Vec<Vec<u8>> = OUTPUTS
        .iter()
        .map(|n| std::fs::read(out.join(n)).unwrap())
        .collect();
    // The second run reads back the files written in the first one's tick and stamps them.
    run_ok(&cache, &out, 1);
    let record = record_of(&cache);
    let text = std::fs::read_to_string(&record).unwrap();
    assert_eq!(text.lines().count(), 1 + OUTPUTS.len(), "{text}");
    // The record is in the cache; the output folder holds the outputs alone.
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), OUTPUTS.len());

    // A stamp is trusted without reading the file: a record that vouches for wrong bytes
    // (their own stat, the wanted hash) keeps them; --recheck reads them and repairs them.
    let path = out.join(OUTPUTS[1]);
    let mut bytes = want[1].clone();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0xff;
    std::fs::write(&path, &bytes).unwrap();
    let m = std::fs::metadata(&path).unwrap();
    let forged: String = text
        .lines()
        .map(|l| {
            if !l.ends_with(OUTPUTS[1]) {
                return format!("{l}\n");
            }
            let hash = l.split(' ').next().unwrap();
            let ns = |s: i64, n: i64| s as i128 * 1_000_000_000 + n as i128;
            format!(
                "{hash} {} {} {} {} {} {}\n",
                m.len(),
                ns(m.mtime(), m.mtime_nsec()),
                ns(m.ctime(), m.ctime_nsec()),
                m.ino(),
                m.dev(),
                OUTPUTS[1]
            )
        })
        .collect();
    std::fs::write(&record, forged).unwrap();
    run_ok(&cache, &out, 1);
    assert_eq!(
        std::fs::read(&path).unwrap(),
        bytes,
        "the stamp was not trusted"
    );
    run_report(&cache, &out, &["--recheck"]);
    assert_eq!(
        std::fs::read(&path).unwrap(),
        want[1],
        "--recheck kept the wrong bytes"
    );
    run_ok(&cache, &out, 1);

    // An edit that keeps the length and the modification time is read again: the change
    // time moved.
    let modified = std::fs::metadata(&path).unwrap().modified().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    std::fs::write(&path, &bytes).unwrap();
    std::fs::File::options()
        .write(true)
        .open(&path)
        .unwrap()
        .set_modified(modified)
        .unwrap();
    run_ok(&cache, &out, 1);
    assert_eq!(
        std::fs::read(&path).unwrap(),
        want[1],
        "the edited output was trusted"
    );

    // Trusted outputs need no bundle payload: with every cached object damaged, a rerun
    // whose outputs are all on disk reads none (it finds no damage, changes no object and
    // no output)...
    run_ok(&cache, &out, 1);
    damage_every_object(&cache);
    let (objects, before) = (snapshot(&cache.join("objects-v1")), snapshot(&out));
    let report = run_report(&cache, &out, &[]);
    assert_eq!(report["warnings"], serde_json::json!([]), "{report}");
    assert_eq!(snapshot(&out), before);
    assert!(
        snapshot(&cache.join("objects-v1")) == objects,
        "an object was read and repaired"
    );
    // ...and one that must write a file checks the bundle first, finds it damaged, repairs
    // the cache and writes the right bytes.
    std::fs::remove_file(out.join(OUTPUTS[0])).unwrap();
    let report = run_report(&cache, &out, &[]);
    assert_ne!(
        report["warnings"],
        serde_json::json!([]),
        "no damage was found"
    );
    for (name, bytes) in OUTPUTS.iter().zip(&want) {
        assert_eq!(&std::fs::read(out.join(name)).unwrap(), bytes, "{name}");
    }
    // The repair replaced every object on the way to the outputs: a run that re-hashes all
    // it hands out finds nothing damaged.
    let report = run_report(&cache, &out, &["--recheck"]);
    assert_eq!(report["warnings"], serde_json::json!([]), "{report}");
}
