//! The neighbourhood templates (causal Γ and full, plus the coarser level's window): their taps,
//! the feature length they give, and the texels of a level whose whole template lies inside.

/// Which template a feature set describes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Template {
    /// The causal Γ half window of the scanline synthesis (§4.2.1).
    Causal,
    /// The full window of boundary resynthesis (§4.2.2).
    Full,
}

/// Side of the full coarser-level neighbourhood added to a template of side `side`:
/// `side − 2`, at least 3.
pub fn coarse_window(side: u32) -> u32 {
    side.saturating_sub(2).max(3)
}

/// Offsets `(dx, dy)` of a template's taps at its own level, in feature order (row by row):
/// for [`Template::Causal`] the `side / 2` rows above the centre and the texels left of it on
/// its row, for [`Template::Full`] the whole window.
pub fn template_taps(kind: Template, side: u32) -> Vec<(i32, i32)> {
    let r = (side / 2) as i32;
    let mut taps = Vec::new();
    for dy in -r..=r {
        for dx in -r..=r {
            if kind == Template::Causal && (dy > 0 || (dy == 0 && dx >= 0)) {
                continue;
            }
            taps.push((dx, dy));
        }
    }
    taps
}

/// Offsets of the coarser-level taps (the full window of [`coarse_window`]), in feature order.
pub fn coarse_taps(side: u32) -> Vec<(i32, i32)> {
    template_taps(Template::Full, coarse_window(side))
}

/// Feature length of a template with `channels` values per tap.
pub fn feature_dim(kind: Template, side: u32, with_coarse: bool, channels: u32) -> usize {
    let mut taps = template_taps(kind, side).len();
    if with_coarse {
        taps += coarse_taps(side).len();
    }
    taps * channels as usize
}

/// Candidate centres of a template on a `w × h` level (`coarse` the size of the next coarser
/// level, if any), row-major.
pub(super) fn candidates(
    kind: Template,
    side: u32,
    w: u32,
    h: u32,
    coarse: Option<(u32, u32)>,
) -> Vec<u32> {
    let r = side / 2;
    let y_hi = match kind {
        Template::Causal => h as i64 - 1,
        Template::Full => h as i64 - 1 - r as i64,
    };
    let x_hi = w as i64 - 1 - r as i64;
    let rc = coarse_window(side) / 2;
    let mut out = Vec::new();
    for y in r as i64..=y_hi {
        for x in r as i64..=x_hi {
            if let Some((cw, ch)) = coarse {
                let (cx, cy) = (x / 2, y / 2);
                if cx < rc as i64
                    || cy < rc as i64
                    || cx > cw as i64 - 1 - rc as i64
                    || cy > ch as i64 - 1 - rc as i64
                {
                    continue;
                }
            }
            out.push((y * w as i64 + x) as u32);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn causal_template_reads_only_earlier_texels() {
        let taps = template_taps(Template::Causal, 5);
        assert_eq!(taps.len(), 12);
        assert!(taps.iter().all(|&(dx, dy)| dy < 0 || (dy == 0 && dx < 0)));
        assert_eq!(template_taps(Template::Full, 5).len(), 25);
        assert_eq!(coarse_taps(5).len(), 9);
        assert_eq!(feature_dim(Template::Causal, 5, true, 3), 63);
    }
}
