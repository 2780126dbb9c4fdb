//! `texsyn watch`: reruns after the config or an input changes, saying what reran; keeps
//! watching through a broken config; serves the page and its version; stops on Ctrl-C with
//! the outputs whole (the same bytes a plain `run` writes). In the full tier, the served page
//! reloads itself in headless Chromium after a config edit.

use crate::common::cli::{succeeded, texsyn};
use crate::common::repo;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::Receiver;
use std::time::Duration;

/// A `texsyn watch` process and its output (stdout and stderr, line by line, in the order
/// the reading threads got them: a line of one stream may come before an earlier line of
/// the other, so lines are looked for among all those not yet matched).
struct Watch {
    child: Child,
    lines: Receiver<String>,
    unmatched: Vec<String>,
    seen: Vec<String>,
    port: u16,
}

impl Watch {
    fn start(config: &Path, root: &Path) -> Watch {
        let mut child = Command::new(env!("CARGO_BIN_EXE_texsyn"))
            .args(["watch", config.to_str().unwrap(), "--serve", "0"])
            .arg("--cache")
            .arg(root.join("cache"))
            .arg("--out")
            .arg(root.join("out"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let (tx, lines) = std::sync::mpsc::channel();
        let out = child.stdout.take().unwrap();
        let err = child.stderr.take().unwrap();
        for stream in [Box::new(out) as Box<dyn Read + Send>, Box::new(err)] {
            let tx = tx.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(stream).lines().map_while(Result::ok) {
                    let _ = tx.send(line);
                }
            });
        }
        let mut w = Watch {
            child,
            lines,
            unmatched: Vec::new(),
            seen: Vec::new(),
            port: 0,
        };
        let serving = w.expect("serving the report on http://127.0.0.1:");
        w.port = serving
            .rsplit(':')
            .next()
            .unwrap()
            .trim_end_matches('/')
            .parse()
            .unwrap();
        w
    }

    /// The first line not yet matched that contains `text` (failing after 60 s).
    fn expect(&mut self, text: &str) -> String {
        if let Some(i) = self.unmatched.iter().position(|l| l.contains(text)) {
            return self.unmatched.remove(i);
        }
        loop {
            match self.lines.recv_timeout(Duration::from_secs(60)) {
                Ok(line) => {
                    self.seen.push(line.clone());
                    if line.contains(text) {
                        return line;
                    }
                    self.unmatched.push(line);
                }
                Err(_) => panic!(
                    "no line with {text:?} within 60 s; saw:\n{}",
                    self.seen.join("\n")
                ),
            }
        }
    }
}

impl Drop for Watch {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The body of `GET path` on 127.0.0.1:`port`.
fn get(port: u16, path: &str) -> String {
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    write!(s, "GET {path} HTTP/1.0\r\nHost: 127.0.0.1:{port}\r\n\r\n").unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).unwrap();
    text.split_once("\r\n\r\n")
        .map(|(_, b)| b.to_owned())
        .unwrap_or_default()
}

/// configs/synth2d.toml in `dir` with its own copy of the exemplar, so both can be edited.
fn editable_config(dir: &Path) -> std::path::PathBuf {
    let text = std::fs::read_to_string(repo().join("configs/synth2d.toml")).unwrap();
    let exemplar = text
        .lines()
        .find_map(|l| l.strip_prefix("exemplar = \""))
        .and_then(|r| r.split('"').next())
        .expect("synth2d names its exemplar")
        .to_owned();
    std::fs::copy(
        repo().join("configs").join(&exemplar),
        dir.join("exemplar.png"),
    )
    .unwrap();
    let config = dir.join("watched.toml");
    std::fs::write(&config, text.replace(&exemplar, "exemplar.png")).unwrap();
    config
}

/// Saves `text` as an editor does: a new file renamed over the old one.
fn save(path: &Path, bytes: &[u8]) {
    let tmp = path.with_extension("swp");
    std::fs::write(&tmp, bytes).unwrap();
    std::fs::rename(&tmp, path).unwrap();
}

#[test]
fn watch_reruns_what_an_edit_changes_survives_a_broken_config_and_stops_whole() {
    let root = tempfile::tempdir().unwrap();
    let config = editable_config(root.path());
    let mut w = Watch::start(&config, root.path());
    let port = w.port;
    let first = w.expect("run 1:");
    assert!(
        first.contains("reran") && first.contains("synthesize"),
        "{first}"
    );
    w.expect("watching");
    assert_eq!(get(port, "/version"), "1");
    assert!(get(port, "/").contains("data-version=\"1\""));

    // A parameter: only synthesis and what follows rerun.
    let text = std::fs::read_to_string(&config).unwrap();
    let seeded = text
        .lines()
        .map(|l| {
            if l.starts_with("seed =") {
                "seed = 5"
            } else {
                l
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert_ne!(seeded.trim(), text.trim(), "synth2d sets a seed");
    save(&config, seeded.as_bytes());
    let second = w.expect("run 2:");
    assert!(second.contains("reran synthesize"), "{second}");
    assert!(!second.contains("analyse_exemplar"), "{second}");
    w.expect("watching");

    // A broken config is reported, in the terminal and on the served page; watching goes
    // on, and the fix reruns.
    save(&config, b"method = \"synth2d\"\n[synthesize\n");
    w.expect("error:");
    w.expect("watching");
    assert_eq!(get(port, "/version"), "3");
    assert!(get(port, "/").contains("the run failed"));
    save(&config, seeded.as_bytes());
    let fixed = w.expect("run 4:");
    assert!(fixed.contains("nothing reran"), "{fixed}");
    w.expect("watching");

    // An input file: its import and everything after rerun.
    let other = std::fs::read(repo().join("configs/assets/wood2.png")).unwrap();
    save(&root.path().join("exemplar.png"), &other);
    let fifth = w.expect("run 5:");
    assert!(fifth.contains("import.exemplar"), "{fifth}");
    w.expect("watching");
    assert_eq!(get(port, "/version"), "5");
    assert!(get(port, "/").contains("data-version=\"5\""));
    assert!(root.path().join("out/report.html").is_file());

    // Ctrl-C: a clean stop, and the outputs are what a plain run writes.
    let pid = w.child.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-INT", &pid])
            .status()
            .unwrap()
            .success()
    );
    w.expect("stopped");
    let status = w.child.wait().unwrap();
    assert!(status.success(), "{status}");
    let fresh = root.path().join("fresh");
    succeeded(texsyn(
        &[
            "run",
            config.to_str().unwrap(),
            "-q",
            "--cache",
            root.path().join("cache").to_str().unwrap(),
            "--out",
            fresh.to_str().unwrap(),
        ],
        &repo(),
    ));
    for name in ["coordinates.png", "synthesized.png"] {
        assert_eq!(
            std::fs::read(root.path().join("out").join(name)).unwrap(),
            std::fs::read(fresh.join(name)).unwrap(),
            "{name}"
        );
    }
}

#[test]
fn the_served_page_reloads_itself_after_a_config_edit_in_chromium() {
    crate::full_tier_only!("headless Chromium");
    crate::common::install_browser();
    let root = tempfile::tempdir().unwrap();
    let config = editable_config(root.path());
    let mut w = Watch::start(&config, root.path());
    let port = w.port;
    w.expect("watching");
    let o = Command::new(repo().join("scripts/browser"))
        .args([
            "check-reload",
            &format!("http://127.0.0.1:{port}/"),
            config.to_str().unwrap(),
        ])
        .current_dir(repo())
        .output()
        .unwrap();
    let summary = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success() && summary.contains("\"pass\": true"),
        "{summary}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    w.expect("run 2:");
}
