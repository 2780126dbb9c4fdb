//! Progress of long-running nodes. On a terminal, a node that runs for more than a second gets
//! a bar with the time spent and an estimate of the time left (indicatif's, from the rate so
//! far), or a spinner with the time spent when its algorithm reports no fraction. Elsewhere (a
//! log file, a Slurm job, a pipe) a node that runs for more than ten seconds prints one plain
//! line every ten seconds. Quick reruns print nothing but the final table either way.
//!
//! A watcher thread per computed node does the showing, so a node whose algorithm reports
//! nothing still shows that it is alive; the algorithm only stores a fraction.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProgressMode {
    /// Bars on stderr (a terminal).
    Bars,
    /// A plain line on stderr every [`LINE_EVERY`] for nodes that run that long (stderr is
    /// not a terminal).
    Lines,
    /// Nothing (`--quiet`, `--json`, tests).
    Hidden,
}

impl ProgressMode {
    /// Bars when stderr is a terminal, lines otherwise; nothing when `quiet`.
    pub fn for_stderr(quiet: bool) -> Self {
        use std::io::IsTerminal;
        if quiet {
            ProgressMode::Hidden
        } else if std::io::stderr().is_terminal() {
            ProgressMode::Bars
        } else {
            ProgressMode::Lines
        }
    }
}

const SHOW_AFTER: Duration = Duration::from_secs(1);
/// How often (and after how long) a node's plain progress line is printed.
pub const LINE_EVERY: Duration = Duration::from_secs(10);
const STEPS: u32 = 1000;

/// What the node's algorithm and its watcher share.
struct Shared {
    label: String,
    start: Instant,
    /// The fraction done, in thousandths; `None` until the algorithm reports one.
    permille: AtomicU32,
    reported: AtomicBool,
    done: Mutex<bool>,
    wake: Condvar,
}

/// A node's progress, fed by the algorithm as a fraction in [0, 1]. Thread-safe: rayon
/// workers may report concurrently; the largest fraction wins.
pub struct Progress {
    shared: Arc<Shared>,
    bar: Option<ProgressBar>,
    watcher: Mutex<Option<std::thread::JoinHandle<()>>>,
}

impl Progress {
    pub fn new(mode: ProgressMode, label: &str) -> Self {
        let shared = Arc::new(Shared {
            label: label.to_owned(),
            start: Instant::now(),
            permille: AtomicU32::new(0),
            reported: AtomicBool::new(false),
            done: Mutex::new(false),
            wake: Condvar::new(),
        });
        let bar = (mode == ProgressMode::Bars).then(|| {
            let b = ProgressBar::with_draw_target(Some(STEPS as u64), ProgressDrawTarget::hidden());
            b.set_message(label.to_owned());
            b
        });
        let watcher = match mode {
            ProgressMode::Hidden => None,
            ProgressMode::Bars => {
                let (s, b) = (shared.clone(), bar.clone().expect("a bar in Bars mode"));
                std::thread::Builder::new()
                    .name("texsyn-progress".into())
                    .spawn(move || show_bar_after(&s, &b))
                    .ok()
            }
            ProgressMode::Lines => {
                let s = shared.clone();
                std::thread::Builder::new()
                    .name("texsyn-progress".into())
                    .spawn(move || print_lines(&s))
                    .ok()
            }
        };
        Progress {
            shared,
            bar,
            watcher: Mutex::new(watcher),
        }
    }

    /// A progress sink that shows nothing.
    pub fn hidden() -> Self {
        Self::new(ProgressMode::Hidden, "")
    }

    /// Reports that `fraction` of the work is done.
    pub fn set(&self, fraction: f32) {
        let p = (fraction.clamp(0.0, 1.0) * STEPS as f32) as u32;
        let prev = self.shared.permille.fetch_max(p, Ordering::Relaxed);
        let first = !self.shared.reported.swap(true, Ordering::Relaxed);
        if let Some(bar) = &self.bar {
            if first {
                bar.set_style(bar_style());
            }
            if p > prev || first {
                bar.set_position(p as u64);
            }
        }
    }

    /// Stops the watcher and removes the bar, if one was shown.
    pub fn finish(&self) {
        *self.shared.done.lock().unwrap_or_else(|e| e.into_inner()) = true;
        self.shared.wake.notify_all();
        let watcher = self
            .watcher
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        if let Some(w) = watcher {
            let _ = w.join();
        }
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.finish();
    }
}

impl Shared {
    /// Waits until `deadline` or until the node is done; whether it is done.
    fn wait_until(&self, deadline: Instant) -> bool {
        let mut done = self.done.lock().unwrap_or_else(|e| e.into_inner());
        while !*done {
            let now = Instant::now();
            if now >= deadline {
                return false;
            }
            done = self
                .wake
                .wait_timeout(done, deadline - now)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
        true
    }

    fn fraction(&self) -> Option<f32> {
        self.reported
            .load(Ordering::Relaxed)
            .then(|| self.permille.load(Ordering::Relaxed) as f32 / STEPS as f32)
    }
}

fn bar_style() -> ProgressStyle {
    ProgressStyle::with_template("{msg:>28} [{bar:40}] {percent:>3}% {elapsed}, about {eta} left")
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ")
}

fn spinner_style() -> ProgressStyle {
    ProgressStyle::with_template("{msg:>28} {spinner} running, {elapsed}")
        .unwrap_or_else(|_| ProgressStyle::default_spinner())
}

/// Shows the bar once the node has run for [`SHOW_AFTER`], as a spinner until a fraction
/// arrives.
fn show_bar_after(s: &Shared, bar: &ProgressBar) {
    if s.wait_until(s.start + SHOW_AFTER) {
        return;
    }
    if s.fraction().is_none() {
        bar.set_style(spinner_style());
    } else {
        bar.set_style(bar_style());
    }
    bar.set_draw_target(ProgressDrawTarget::stderr());
    bar.enable_steady_tick(Duration::from_millis(200));
}

/// Prints a line every [`LINE_EVERY`] until the node is done.
fn print_lines(s: &Shared) {
    let mut next = s.start + LINE_EVERY;
    while !s.wait_until(next) {
        eprintln!("{}", line(&s.label, s.start.elapsed(), s.fraction()));
        next += LINE_EVERY;
    }
}

/// One plain progress line: the node, the share done and the time spent, and an estimate of
/// the time left from the rate so far.
fn line(label: &str, elapsed: Duration, fraction: Option<f32>) -> String {
    let secs = elapsed.as_secs_f64();
    match fraction {
        Some(f) if f > 0.0 => {
            let left = secs * (1.0 - f as f64) / f as f64;
            format!(
                "{label}: {:.0} % after {secs:.0} s, about {left:.0} s left",
                f * 100.0
            )
        }
        _ => format!("{label}: running for {secs:.0} s"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_say_the_share_done_and_estimate_the_rest_from_the_rate() {
        assert_eq!(
            line("field", Duration::from_secs(10), Some(0.25)),
            "field: 25 % after 10 s, about 30 s left"
        );
        assert_eq!(
            line("field", Duration::from_secs(20), None),
            "field: running for 20 s"
        );
        assert_eq!(
            line("field", Duration::from_secs(20), Some(0.0)),
            "field: running for 20 s"
        );
    }

    #[test]
    fn a_finished_node_stops_its_watcher_at_once() {
        for mode in [ProgressMode::Bars, ProgressMode::Lines] {
            let t = Instant::now();
            let p = Progress::new(mode, "quick");
            p.set(0.5);
            p.finish();
            assert!(
                t.elapsed() < SHOW_AFTER,
                "{mode:?}: finish waited for the watcher's timer"
            );
            assert_eq!(p.shared.fraction(), Some(0.5));
        }
    }
}
