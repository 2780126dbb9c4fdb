//! The `texsyn` command as a user meets it: the lock file, bad inputs, and the small commands.

use crate::common;
use common::cli::{object_count, stderr, stdout, succeeded, texsyn};
use common::repo;
use std::path::Path;
use std::process::Output;

/// `texsyn run demo.toml --cache c --out <out>`, then the `extra` arguments, in `dir`.
fn run_demo(dir: &Path, out: &str, extra: &[&str]) -> Output {
    texsyn(
        &[&["run", "demo.toml", "--cache", "c", "--out", out], extra].concat(),
        dir,
    )
}

/// A scratch copy of the demo's config and assets, so tests can break them.
fn scratch() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("assets")).unwrap();
    for f in ["cow.obj", "wood1.png"] {
        std::fs::copy(
            repo().join("configs/assets").join(f),
            dir.path().join("assets").join(f),
        )
        .unwrap();
    }
    let text = std::fs::read_to_string(repo().join("configs/demo.toml")).unwrap();
    let text = text
        .replace("atlas_size = 2048", "atlas_size = 1024")
        .replace("preview_size = 512", "preview_size = 64");
    std::fs::write(dir.path().join("demo.toml"), text).unwrap();
    dir
}

#[test]
fn a_lock_file_that_disagrees_names_each_mismatching_node() {
    let dir = scratch();
    let d = dir.path();
    let cache = d.join("cache");
    let o = succeeded(texsyn(
        &["hashes", "demo.toml", "--cache", cache.to_str().unwrap()],
        d,
    ));
    let lock = stdout(&o);
    assert_eq!(lock.lines().filter(|l| !l.starts_with('#')).count(), 7);
    std::fs::write(d.join("good.lock"), &lock).unwrap();
    let verify = |lock: &str| {
        texsyn(
            &[
                "verify",
                "demo.toml",
                lock,
                "--cache",
                cache.to_str().unwrap(),
            ],
            d,
        )
    };
    succeeded(verify("good.lock"));

    // Change the locked content hash of the walk: verify must fail and name that node.
    let tampered: String = lock
        .lines()
        .map(|l| {
            if l.starts_with("synthesize ") {
                let mut f: Vec<String> = l.split(' ').map(String::from).collect();
                f[2] = "0".repeat(64);
                f.join(" ")
            } else {
                l.to_owned()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(d.join("bad.lock"), &tampered).unwrap();
    let o = verify("bad.lock");
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    // Same key, other content: named as the missing version bump it is.
    assert!(
        e.contains("mismatch: synthesize: key unchanged, content changed: version not bumped"),
        "{e}"
    );
    assert!(!e.contains("mismatch: reconstruct"), "{e}");

    // `hashes -o` will not overwrite that line without being asked.
    let hashes_to = |extra: &[&str]| {
        texsyn(
            &[
                &["hashes", "demo.toml", "--cache", cache.to_str().unwrap()][..],
                extra,
            ]
            .concat(),
            d,
        )
    };
    let o = hashes_to(&["-o", "bad.lock"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("unbumped: synthesize:"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        std::fs::read_to_string(d.join("bad.lock")).unwrap(),
        tampered
    );
    succeeded(hashes_to(&["-o", "bad.lock", "--accept-unbumped"]));
    assert_eq!(std::fs::read_to_string(d.join("bad.lock")).unwrap(), lock);

    // A file that is not a lock at all is kept, and says how to replace it; replaced when
    // asked.
    std::fs::write(d.join("garbage.lock"), "garbage\n").unwrap();
    let o = hashes_to(&["-o", "garbage.lock"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("garbage.lock is not a lock file")
            && stderr(&o).contains("--accept-unbumped"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        std::fs::read_to_string(d.join("garbage.lock")).unwrap(),
        "garbage\n"
    );
    succeeded(hashes_to(&["-o", "garbage.lock", "--accept-unbumped"]));
    assert_eq!(
        std::fs::read_to_string(d.join("garbage.lock")).unwrap(),
        lock
    );

    // A changed key is an ordinary mismatch, and `hashes -o` replaces it.
    let rekeyed = lock.lines().map(|l| {
        if l.starts_with("synthesize ") {
            let mut f: Vec<String> = l.split(' ').map(String::from).collect();
            f[1] = "1".repeat(64);
            f.join(" ")
        } else {
            l.to_owned()
        }
    });
    std::fs::write(
        d.join("rekeyed.lock"),
        rekeyed.collect::<Vec<_>>().join("\n"),
    )
    .unwrap();
    let e = stderr(&verify("rekeyed.lock"));
    assert!(e.contains("mismatch: synthesize: key "), "{e}");
    assert!(!e.contains("version not bumped"), "{e}");
    succeeded(hashes_to(&["-o", "rekeyed.lock"]));
    assert_eq!(
        std::fs::read_to_string(d.join("rekeyed.lock")).unwrap(),
        lock
    );
}

#[test]
fn a_mesh_with_a_nan_is_an_error_naming_file_and_line_and_writes_nothing() {
    let dir = scratch();
    let d = dir.path();
    let obj = std::fs::read_to_string(d.join("assets/cow.obj")).unwrap();
    let mut lines: Vec<String> = obj.lines().map(String::from).collect();
    let i = lines.iter().position(|l| l.starts_with("v ")).unwrap() + 4;
    lines[i] = "v 0.1 nan 0.2".into();
    std::fs::write(d.join("assets/cow.obj"), lines.join("\n")).unwrap();
    let o = run_demo(d, "o", &[]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("cow.obj") && e.contains(&format!("line {}", i + 1)),
        "{e}"
    );
    assert!(
        e.to_lowercase().contains("nan") || e.contains("finite"),
        "{e}"
    );
    assert_eq!(
        object_count(&d.join("c")),
        0,
        "nothing may be cached from a failed import"
    );
    assert!(!d.join("o").exists());
}

#[test]
fn config_mistakes_are_named_by_key() {
    let dir = scratch();
    let d = dir.path();
    // Each bad --set, with what the error must name.
    let cases: [(&str, &[&str]); 4] = [
        ("synthesize.sede=3", &["synthesize", "sede"]),
        (
            "synthesize.boundary_fraction=2",
            &["synthesize.boundary_fraction"],
        ),
        (
            "field.sinks=[{ vertex = 999999 }]",
            &["field.sinks[0]", "999999"],
        ),
        ("method=\"nope\"", &["nope"]),
    ];
    for (set, names) in cases {
        let o = texsyn(&["run", "demo.toml", "--set", set], d);
        assert!(!o.status.success(), "--set {set}");
        let err = stderr(&o);
        assert!(names.iter().all(|n| err.contains(n)), "{err}");
    }
}

#[test]
fn a_scale_too_large_for_the_mesh_names_one_that_fits_and_keeps_earlier_outputs() {
    let dir = scratch();
    let d = dir.path();
    succeeded(run_demo(d, "o", &["-q"]));
    let before = std::fs::read(d.join("o/textured.obj")).unwrap();
    let o = run_demo(d, "o", &["--set", "parameterize.scale=5000"]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("parameterize.scale = 5000"), "{e}");
    // The named scale must really fit: rerun with it.
    let fit: String = e
        .split("fit at scale ≤ ")
        .nth(1)
        .expect("names a fitting scale")
        .chars()
        .take_while(|c| c.is_ascii_digit() || *c == '.')
        .collect();
    assert_eq!(
        std::fs::read(d.join("o/textured.obj")).unwrap(),
        before,
        "earlier outputs intact"
    );
    let fit: f32 = fit.parse().unwrap();
    succeeded(run_demo(
        d,
        "o2",
        &[
            "-q",
            "--set",
            &format!("parameterize.scale={}", fit * 0.999),
        ],
    ));
    // Or keep the scale and let the mesh be refined until its triangles fit (§1).
    assert!(e.contains("parameterize.refine = true"), "{e}");
    let twice = format!("parameterize.scale={}", 2.0 * fit);
    let o = run_demo(d, "o3", &["--set", &twice]);
    assert!(!o.status.success(), "twice the fitting scale is refused");
    let refined = ["-q", "--set", &twice, "--set", "parameterize.refine=true"];
    succeeded(run_demo(d, "o3", &refined));
    let vertices = |p: &str| {
        let t = std::fs::read_to_string(d.join(p)).unwrap();
        t.lines().filter(|l| l.starts_with("v ")).count()
    };
    assert!(
        vertices("o3/textured.obj") > vertices("o/textured.obj"),
        "{} refined against {}",
        vertices("o3/textured.obj"),
        vertices("o/textured.obj")
    );
    let o = run_demo(
        d,
        "o4",
        &[
            "--set",
            "parameterize.scale=\"auto\"",
            "--set",
            "parameterize.refine=true",
        ],
    );
    assert!(!o.status.success());
    assert!(stderr(&o).contains("parameterize.refine"), "{}", stderr(&o));
}

#[test]
fn status_graph_gc_and_render_do_their_jobs() {
    let dir = scratch();
    let d = dir.path();
    let o = succeeded(texsyn(&["status", "demo.toml", "--cache", "c"], d));
    let s = stdout(&o);
    assert!(s.contains("import.mesh") && s.contains("would run"), "{s}");
    assert!(!s.contains("cached"), "{s}");
    succeeded(run_demo(d, "o", &["-q"]));
    let s = stdout(&texsyn(&["status", "demo.toml", "--cache", "c"], d));
    assert_eq!(
        s.lines().filter(|l| l.ends_with("cached")).count(),
        7,
        "{s}"
    );
    let s = stdout(&texsyn(
        &[
            "status",
            "demo.toml",
            "--cache",
            "c",
            "--set",
            "synthesize.seed=9",
        ],
        d,
    ));
    assert!(
        s.lines()
            .any(|l| l.starts_with("synthesize") && l.ends_with("would run")),
        "{s}"
    );
    assert!(
        s.lines()
            .any(|l| l.starts_with("reconstruct") && l.contains("if its inputs change")),
        "{s}"
    );

    let dot = stdout(&texsyn(&["graph", "demo.toml"], d));
    assert!(
        dot.starts_with("digraph") && dot.contains("jump_walk") && dot.contains("->"),
        "{dot}"
    );

    let before = object_count(&d.join("c"));
    succeeded(texsyn(&["gc", "--max-size", "1M", "--cache", "c"], d));
    let after = object_count(&d.join("c"));
    assert!(after < before, "{before} -> {after}");
    let total: u64 = std::fs::read_dir(d.join("c/objects-v1"))
        .unwrap()
        .flatten()
        .flat_map(|s| std::fs::read_dir(s.path()).unwrap().flatten())
        .map(|f| f.metadata().unwrap().len())
        .sum();
    assert!(total <= 1 << 20);

    succeeded(texsyn(
        &[
            "render",
            "o/textured.obj",
            "--texture",
            "o/texture.png",
            "-o",
            "r.png",
            "--size",
            "64",
        ],
        d,
    ));
    let img = image::open(d.join("r.png")).unwrap();
    assert_eq!((img.width(), img.height()), (192, 64));
}

#[test]
fn json_output_reports_every_node() {
    let dir = scratch();
    let d = dir.path();
    let o = succeeded(run_demo(d, "o", &["--json"]));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let nodes = v["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), 7);
    assert!(nodes.iter().all(|n| n["status"] == "ran"));
    assert!(
        v["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .any(|f| f["path"].as_str().unwrap().ends_with("textured.glb"))
    );
}

#[test]
fn synth2d_writes_an_image_of_the_requested_size() {
    let dir = tempfile::tempdir().unwrap();
    succeeded(texsyn(
        &[
            "run",
            repo().join("configs/synth2d.toml").to_str().unwrap(),
            "--cache",
            "c",
            "--out",
            "o",
            "-q",
            "--set",
            "synthesize.width=100",
            "--set",
            "synthesize.height=40",
        ],
        dir.path(),
    ));
    let img = image::open(dir.path().join("o/synthesized.png")).unwrap();
    assert_eq!((img.width(), img.height()), (100, 40));
}

/// CPU seconds (user + system) of this process's finished children.
fn children_cpu_seconds() -> f64 {
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage writes into the struct we pass; RUSAGE_CHILDREN is valid.
    assert_eq!(unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut u) }, 0);
    let s = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    s(u.ru_utime) + s(u.ru_stime)
}

/// `cpu_seconds`: each node that ran says the CPU its process spent on it, a difference of the
/// process's CPU clock: all nodes together are at most the child's whole CPU time (measured
/// here by getrusage; the process's running total per node would add up to several times it);
/// cached nodes say nothing.
#[test]
fn run_json_reports_the_cpu_each_node_that_ran_took() {
    let t = tempfile::tempdir().unwrap();
    let demo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/demo.toml");
    let run = || {
        let o = common::cli::succeeded(common::cli::texsyn(
            &[
                "run",
                demo.to_str().unwrap(),
                "--cache",
                "c",
                "--out",
                "o",
                "--json",
            ],
            t.path(),
        ));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
    };
    let before = children_cpu_seconds();
    let first = run();
    // Other tests' children may end meanwhile: this is an upper bound of the run's CPU.
    let child_cpu = children_cpu_seconds() - before;
    let nodes = first["nodes"].as_array().unwrap();
    let cpu: Vec<f64> = nodes
        .iter()
        .map(|n| {
            n["cpu_seconds"]
                .as_f64()
                .unwrap_or_else(|| panic!("{}: ran, but no cpu_seconds", n["node"]))
        })
        .collect();
    assert!(cpu.iter().all(|&c| c >= 0.0), "{cpu:?}");
    let total: f64 = cpu.iter().sum();
    // The nodes' clock ticks are 1/100 s: a tick per node of slack.
    assert!(
        total > 0.0 && total <= child_cpu + 0.01 * cpu.len() as f64,
        "nodes {total} CPU s, the whole process {child_cpu} CPU s"
    );
    let again = run();
    for n in again["nodes"].as_array().unwrap() {
        assert_eq!(n["status"], "cached");
        assert!(
            n.get("cpu_seconds").is_none(),
            "{}: cached, yet cpu_seconds",
            n["node"]
        );
    }
}

#[test]
fn run_json_reports_each_nodes_own_peak_memory() {
    let t = tempfile::tempdir().unwrap();
    let demo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/demo.toml");
    let o = common::cli::succeeded(common::cli::texsyn(
        &[
            "run",
            demo.to_str().unwrap(),
            "--cache",
            "c",
            "--out",
            "o",
            "--json",
        ],
        t.path(),
    ));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let peaks: Vec<(String, u64)> = r["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| {
            let peak = n["peak_memory_bytes"].as_u64();
            (
                n["node"].as_str().unwrap().to_owned(),
                peak.expect("every node ran: a peak"),
            )
        })
        .collect();
    let run = r["peak_memory_bytes"].as_u64().unwrap();
    // Each is a peak of this process: none above the run's (within the kernel's lag in
    // updating its counters).
    for (node, p) in &peaks {
        assert!(
            *p > 0 && *p as f64 <= run as f64 * 1.02,
            "{node}: {p} vs run {run}"
        );
    }
    // Measured per node: a process's high-water mark never falls, so a node with a lower peak
    // than an earlier one shows the mark was reset for it (the small field after the exemplar
    // analysis).
    assert!(
        peaks.windows(2).any(|w| w[1].1 < w[0].1),
        "peaks never fall from node to node: not measured per node: {peaks:?}"
    );
    // The reconstruct's 2048² atlas (16 MiB of RGBA floats at least) shows in its peak.
    let get = |n: &str| peaks.iter().find(|(m, _)| m == n).unwrap().1;
    assert!(
        get("reconstruct") > get("import.mesh") + (16 << 20),
        "{peaks:?}"
    );
}

/// `texsyn ARGS` in `cwd`, killed if it has not finished after `secs` seconds: `None` then.
fn texsyn_within(args: &[&str], cwd: &Path, secs: u64) -> Option<Output> {
    use std::process::{Command, Stdio};
    let mut child = Command::new(env!("CARGO_BIN_EXE_texsyn"))
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("texsyn runs");
    let start = std::time::Instant::now();
    while start.elapsed() < std::time::Duration::from_secs(secs) {
        if child.try_wait().unwrap().is_some() {
            return Some(child.wait_with_output().unwrap());
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let _ = child.kill();
    let _ = child.wait();
    None
}

#[test]
fn a_fifo_device_or_huge_file_as_config_or_sweep_is_refused_at_once() {
    let dir = scratch();
    let fifo = dir.path().join("config.toml");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    assert!(made.is_ok_and(|s| s.success()), "mkfifo is needed");
    // Over the size limit: a valid TOML comment of 5 MiB.
    let huge = dir.path().join("huge.toml");
    std::fs::write(&huge, format!("#{}\n", "x".repeat(5 << 20))).unwrap();
    let cache = dir.path().join("cache");
    let cache = cache.to_str().unwrap();
    let out = dir.path().join("out");
    let out = out.to_str().unwrap();
    let lock = repo().join("configs/synth2d.lock");
    let lock = lock.to_str().unwrap();
    for (file, why) in [
        (fifo.to_str().unwrap(), "not a regular file"),
        ("/dev/zero", "not a regular file"),
        (huge.to_str().unwrap(), "over the limit"),
    ] {
        let commands: [Vec<&str>; 6] = [
            vec!["run", file, "--out", out],
            vec!["status", file],
            vec!["hashes", file],
            vec!["verify", file, lock],
            vec!["score", file],
            vec!["sweep", file, "--out", out],
        ];
        for mut args in commands {
            args.extend(["--cache", cache]);
            let shown = args.join(" ");
            let Some(o) = texsyn_within(&args, &repo(), 20) else {
                panic!("texsyn {shown}: still running after 20 s");
            };
            assert!(!o.status.success(), "texsyn {shown}: must fail");
            let err = stderr(&o);
            assert!(
                err.contains(file) && err.contains(why) && !err.contains("panicked"),
                "texsyn {shown}: the message must name the file and say {why:?}: {err}"
            );
        }
    }
    assert_eq!(object_count(Path::new(cache)), 0);
}

#[test]
fn a_config_whose_stem_is_dot_or_dot_dot_writes_nothing_outside_out() {
    // work/cfg/ holds the configs, run from work/: `...toml` has the stem `..` (out/.. is
    // work/ itself), `..toml` the stem `.` (out/ itself).
    let t = tempfile::tempdir().unwrap();
    let work = t.path().join("work");
    std::fs::create_dir_all(work.join("cfg/assets")).unwrap();
    std::fs::copy(
        repo().join("configs/assets/leopard.png"),
        work.join("cfg/assets/leopard.png"),
    )
    .unwrap();
    let text = std::fs::read_to_string(repo().join("configs/synth2d.toml")).unwrap();
    for name in ["...toml", "..toml"] {
        std::fs::write(work.join("cfg").join(name), &text).unwrap();
        let config = format!("cfg/{name}");
        let o = texsyn(&["run", &config, "-q", "--cache", "c"], &work);
        let err = stderr(&o);
        assert!(!o.status.success(), "{name}: must fail");
        assert!(
            err.contains(name) && err.contains("--out"),
            "{name}: the message must name the file and say what to do: {err}"
        );
        let mut left: Vec<String> = std::fs::read_dir(&work)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        left.sort();
        assert!(
            left.iter().all(|n| n == "cfg" || n == "c"),
            "{name}: wrote into the working folder: {left:?}"
        );
        // With --out it runs.
        succeeded(texsyn(
            &["run", &config, "-q", "--cache", "c", "--out", "o"],
            &work,
        ));
        assert!(work.join("o").is_dir());
        std::fs::remove_dir_all(work.join("o")).unwrap();
        std::fs::remove_file(work.join("cfg").join(name)).unwrap();
    }
}

#[test]
fn temporaries_of_killed_pack_hashes_and_render_writers_go_with_the_next_write() {
    use texsyn::owner::Owner;
    let t = tempfile::tempdir().unwrap();
    let d = t.path();
    let mut child = std::process::Command::new("true").spawn().unwrap();
    let dead = Owner::with_pid(child.id()).tag();
    child.wait().unwrap();
    let live = Owner::this().tag(); // this test process, running
    let config = repo().join("configs/synth2d.toml");
    let config = config.to_str().unwrap();
    let mesh = repo().join("configs/assets/cow.obj");
    let writes: [(&str, Vec<&str>); 3] = [
        ("r.tar.zst", vec!["pack", config, "-o", "r.tar.zst"]),
        ("h.lock", vec!["hashes", config, "-o", "h.lock"]),
        (
            "v.png",
            vec![
                "render",
                mesh.to_str().unwrap(),
                "-o",
                "v.png",
                "--size",
                "32",
            ],
        ),
    ];
    for (name, mut args) in writes {
        let stale = d.join(format!(".{name}.tmp-{dead}"));
        let young = d.join(format!(".{name}.tmp-{live}"));
        std::fs::write(&stale, b"left by a killed writer").unwrap();
        std::fs::write(&young, b"being written").unwrap();
        args.extend(["-q", "--cache", "c"]);
        succeeded(texsyn(&args, d));
        assert!(d.join(name).is_file(), "{name} written");
        assert!(
            !stale.exists(),
            "{name}: the killed writer's temporary stays"
        );
        assert!(
            young.exists(),
            "{name}: a live writer's temporary was removed"
        );
    }
}

#[test]
fn a_map_whose_file_names_clash_with_the_exports_is_refused_by_run_hashes_and_verify() {
    let dir = scratch();
    let d = dir.path();
    for name in ["basecolor", "preview", "texture", "baked_basecolor"] {
        let set = format!("inputs.maps={{ {name} = \"assets/wood1.png\" }}");
        let key = format!("inputs.maps.{name}");
        for args in [
            vec!["run", "demo.toml", "--out", "o"],
            vec!["hashes", "demo.toml", "-o", "h.lock"],
            vec!["status", "demo.toml"],
        ] {
            let mut args = args.clone();
            args.extend(["--cache", "c", "-q", "--set", &set]);
            let o = texsyn(&args, d);
            let err = stderr(&o);
            assert!(!o.status.success(), "{name}: {args:?} must fail");
            assert!(
                err.contains("demo.toml") && err.contains(&key) && !err.contains("panicked"),
                "{name}: {args:?}: the message must name the file and the key: {err}"
            );
            assert!(!d.join("h.lock").exists(), "{name}: a lock was written");
        }
        // A lock made without the map cannot be verified with it either.
        if !d.join("good.lock").exists() {
            succeeded(texsyn(
                &[
                    "hashes",
                    "demo.toml",
                    "--cache",
                    "c",
                    "-q",
                    "-o",
                    "good.lock",
                ],
                d,
            ));
        }
        let o = texsyn(
            &[
                "verify",
                "demo.toml",
                "good.lock",
                "--cache",
                "c",
                "-q",
                "--set",
                &set,
            ],
            d,
        );
        assert!(
            !o.status.success(),
            "{name}: verify must fail: {}",
            stdout(&o)
        );
    }
}
