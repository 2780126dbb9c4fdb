//! The speed goal of `texsyn score` (issue 12): exact nearest-patch search for a 512² output
//! against a 256² exemplar in under 30 s on 2 cores.

use super::{Row, time, verdict_below};
use anyhow::Result;
use texsyn::image::Image;
use texsyn::image::patch_score::{ScoreParams, patch_score};
use texsyn::random::counter_unit;

/// Two rows: an output that is mostly the exemplar's own material (a 512² image against its
/// top-left 256² quarter: the prunings work best), and seeded noise (nothing to prune with).
/// Both at the defaults (7 × 7 patches, a 20 000-patch subset).
pub(crate) fn rows(brick_wall_512: &Image, runs: usize, rows: &mut Vec<Row>) -> Result<()> {
    let img = brick_wall_512;
    let ex = Image::from_fn(256, 256, |x, y| img.view().get(x, y));
    let noise = Image::from_fn(512, 512, |x, y| {
        let i = (y * 512 + x) as u64;
        [
            counter_unit(1, 0, i),
            counter_unit(1, 1, i),
            counter_unit(1, 2, i),
            1.0,
        ]
    });
    for (what, out) in [
        (
            "brick_wall_512.png (512²) against its top-left 256² quarter",
            img,
        ),
        ("512² seeded noise against the same 256² quarter", &noise),
    ] {
        let (t, s) = time(runs, || {
            patch_score(out.view(), ex.view(), &ScoreParams::default())
        });
        let s = s?;
        rows.push(Row {
            what: format!(
                "score: exact nearest-patch search, {what}, 7×7 patches, {} of them (plus the baseline's)",
                s.queries
            ),
            measured: format!("{t:.2} s (ratio {:.3})", s.ratio),
            goal: "< 30 s on 2 cores".into(),
            verdict: verdict_below(t, 30.0),
        });
    }
    Ok(())
}
