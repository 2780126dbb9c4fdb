//! Progress bars for long-running nodes: a bar appears only once a node has run for more
//! than a second, so quick reruns print nothing but the final table. The bar shows the time
//! spent and an estimate of the time left (indicatif's, from the rate so far).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::time::{Duration, Instant};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProgressMode {
    /// Bars on stderr (hidden automatically when stderr is not a terminal).
    Bars,
    /// No bars (`--quiet`, `--json`, tests).
    Hidden,
}

const SHOW_AFTER: Duration = Duration::from_secs(1);
const STEPS: u64 = 1000;

/// A node's progress, fed by the algorithm as a fraction in [0, 1]. Thread-safe: rayon
/// workers may report concurrently; the largest fraction wins.
pub struct Progress {
    bar: Option<ProgressBar>,
    start: Instant,
    shown: AtomicBool,
    permille: AtomicU32,
}

impl Progress {
    pub fn new(mode: ProgressMode, label: &str) -> Self {
        let bar = (mode == ProgressMode::Bars).then(|| {
            let b = ProgressBar::with_draw_target(Some(STEPS), ProgressDrawTarget::hidden());
            b.set_style(
                ProgressStyle::with_template(
                    "{msg:>28} [{bar:40}] {percent:>3}% {elapsed}, about {eta} left",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            b.set_message(label.to_owned());
            b
        });
        Progress {
            bar,
            start: Instant::now(),
            shown: AtomicBool::new(false),
            permille: AtomicU32::new(0),
        }
    }

    /// A progress sink that shows nothing.
    pub fn hidden() -> Self {
        Self::new(ProgressMode::Hidden, "")
    }

    /// Reports that `fraction` of the work is done.
    pub fn set(&self, fraction: f32) {
        let p = (fraction.clamp(0.0, 1.0) * STEPS as f32) as u32;
        let prev = self.permille.fetch_max(p, Ordering::Relaxed);
        let Some(bar) = &self.bar else { return };
        if !self.shown.load(Ordering::Relaxed)
            && self.start.elapsed() > SHOW_AFTER
            && !self.shown.swap(true, Ordering::Relaxed)
        {
            bar.set_draw_target(ProgressDrawTarget::stderr());
            bar.enable_steady_tick(Duration::from_millis(200));
        }
        if p > prev {
            bar.set_position(p as u64);
        }
    }

    /// Removes the bar, if one was shown.
    pub fn finish(&self) {
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
