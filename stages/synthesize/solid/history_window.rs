//! History windows: which version of each neighbour a correction reads (Zhang, Du, Lai, Ni &
//! Hu, "Sketch guided solid texturing", §5.2–5.3).
//!
//! A voxel's *version* is the number of corrections applied to it so far at its level (0 =
//! upsampled or initialized). A level runs a [`Schedule`]: a list of [`Stage`]s, each a number
//! of passes, each pass either one step over every voxel or `s³ = 8` subpass steps, one per
//! parity class `(x mod 2, y mod 2, z mod 2)` (Lefebvre & Hoppe 2005, §3.4). In a step every
//! active voxel `v` is corrected from its neighbourhood, reading neighbour `w` at version
//! `H(v, w)` given by the stage's [`HistoryWindow`]:
//!
//! - [`HistoryWindow::latest`] (the paper's `H_s`): every neighbour at its latest version.
//!   With subpasses, the latest version of a neighbour in a class corrected earlier in the
//!   same pass is its new one; a neighbour of the active class (the step updates them all at
//!   once) and later classes give their previous pass's version. This is plain correction.
//! - a *barrier* lattice of `M`-cells: a neighbour in `v`'s cell at its latest version, any
//!   other at the version it had when the stage started (Fig. 6d: "version 0"). A window with
//!   barriers is `H_g ∩ H_s` (§5.3.1): [`HistoryWindow::intersect`] takes the minimum version,
//!   which here means the union of the barrier lattices. Grid correction is one lattice at
//!   offset 0, dual-grid correction one at offset `M/2` (cell centres become vertices, §5.3),
//!   run as a second stage that starts from the grid stage's final versions.
//!
//! So versions read are always either "latest" or "stage start" ([`Read`]); [`Step`] turns
//! them into version numbers. The executor (`solid_synthesis/run.rs`) keeps one buffer per kind
//! and the dependency analysis (`dependent_set.rs`) works backwards with the same numbers, so
//! both follow this one representation.

use glam::IVec3;

/// Which copy of a neighbour a correction reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Read {
    /// The neighbour's latest version (before the current step).
    Latest,
    /// The version the neighbour had when the current stage started.
    StageStart,
}

/// A lattice of cubic cells of side `size` whose corners sit at `offset + size·Z³`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Cells {
    pub size: i32,
    pub offset: i32,
}

impl Cells {
    /// The cell index of `v`.
    #[inline]
    pub fn cell_of(&self, v: IVec3) -> IVec3 {
        (v - IVec3::splat(self.offset)).div_euclid(IVec3::splat(self.size))
    }

    /// First coordinate of the cell interval holding coordinate `x` (any axis).
    #[inline]
    pub fn start(&self, x: i32) -> i32 {
        (x - self.offset).div_euclid(self.size) * self.size + self.offset
    }
}

/// The history window of one stage; see the module docs.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct HistoryWindow {
    /// Barrier lattices: a neighbour is read at its latest version only if it shares `v`'s cell
    /// in every one of them. Empty = plain correction.
    pub barriers: Vec<Cells>,
}

impl HistoryWindow {
    /// `H_s`: every neighbour at its latest version.
    pub fn latest() -> Self {
        HistoryWindow { barriers: vec![] }
    }

    /// One barrier lattice.
    pub fn cells(cells: Cells) -> Self {
        HistoryWindow {
            barriers: vec![cells],
        }
    }

    /// `H₁ ∩ H₂`: the smaller version everywhere, i.e. both windows' barriers.
    pub fn intersect(&self, other: &HistoryWindow) -> HistoryWindow {
        let mut barriers = self.barriers.clone();
        for c in &other.barriers {
            if !barriers.contains(c) {
                barriers.push(*c);
            }
        }
        HistoryWindow { barriers }
    }

    /// The box `[lo, hi)` of voxels `v` reads at their latest version (its cell, intersected
    /// over the lattices; unbounded without barriers).
    #[inline]
    pub fn latest_box(&self, v: IVec3) -> (IVec3, IVec3) {
        let mut lo = IVec3::splat(i32::MIN);
        let mut hi = IVec3::splat(i32::MAX);
        for c in &self.barriers {
            let s = IVec3::new(c.start(v.x), c.start(v.y), c.start(v.z));
            lo = lo.max(s);
            hi = hi.min(s + IVec3::splat(c.size));
        }
        (lo, hi)
    }

    /// What `v` reads of neighbour `w`.
    pub fn read(&self, v: IVec3, w: IVec3) -> Read {
        let (lo, hi) = self.latest_box(v);
        if w.cmpge(lo).all() && w.cmplt(hi).all() {
            Read::Latest
        } else {
            Read::StageStart
        }
    }

    /// The paper's `H(v, w)` during `step`: the version of `w` that `v` reads.
    pub fn version(&self, step: &Step, v: IVec3, w: IVec3) -> u32 {
        match self.read(v, w) {
            Read::Latest => step.latest(w),
            Read::StageStart => step.stage_start,
        }
    }
}

/// Parity class of a voxel for `s³ = 8` subpasses.
#[inline]
pub fn class_of(v: IVec3) -> u8 {
    ((v.x & 1) | ((v.y & 1) << 1) | ((v.z & 1) << 2)) as u8
}

/// One stage of a level's corrections.
#[derive(Clone, Debug, PartialEq)]
pub struct Stage {
    pub passes: u32,
    /// `s³ = 8` subpasses per pass, or one step per pass.
    pub subpasses: bool,
    pub window: HistoryWindow,
}

/// One correction step.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// Index into [`Schedule::stages`].
    pub stage: usize,
    /// Pass within the stage, from 1.
    pub pass: u32,
    /// Parity class corrected, or `None` for all voxels.
    pub class: Option<u8>,
    /// Corrections every voxel has had before the stage started.
    pub stage_start: u32,
}

impl Step {
    /// Whether `v` is corrected in this step.
    #[inline]
    pub fn active(&self, v: IVec3) -> bool {
        self.class.is_none_or(|c| class_of(v) == c)
    }

    /// The version an active voxel has after this step.
    #[inline]
    pub fn version_after(&self) -> u32 {
        self.stage_start + self.pass
    }

    /// The latest version of `w` before this step.
    #[inline]
    pub fn latest(&self, w: IVec3) -> u32 {
        self.latest_for_class(class_of(w))
    }

    #[inline]
    pub fn latest_for_class(&self, class: u8) -> u32 {
        let base = self.stage_start + self.pass - 1;
        match self.class {
            Some(c) if class < c => base + 1,
            _ => base,
        }
    }
}

/// The corrections of one level.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Schedule {
    pub stages: Vec<Stage>,
}

impl Schedule {
    /// Plain correction (the "standard" scheme of Lefebvre & Hoppe and Dong et al.).
    pub fn plain(passes: u32, subpasses: bool) -> Schedule {
        Schedule {
            stages: vec![Stage {
                passes,
                subpasses,
                window: HistoryWindow::latest(),
            }],
        }
    }

    /// Grid correction: every pass behind barriers at the `M`-cells.
    pub fn grid(passes: u32, subpasses: bool, m: i32) -> Schedule {
        Schedule {
            stages: vec![Stage {
                passes,
                subpasses,
                window: HistoryWindow::cells(Cells { size: m, offset: 0 }),
            }],
        }
    }

    /// Dual-grid correction (§5.3): `⌈P/2⌉` grid passes, then `⌊P/2⌋` passes behind the dual
    /// lattice (offset `⌊M/2⌋`), starting from the grid passes' result.
    pub fn dual_grid(passes: u32, subpasses: bool, m: i32) -> Schedule {
        let mut stages = vec![Stage {
            passes: passes.div_ceil(2),
            subpasses,
            window: HistoryWindow::cells(Cells { size: m, offset: 0 }),
        }];
        if passes / 2 > 0 {
            stages.push(Stage {
                passes: passes / 2,
                subpasses,
                window: HistoryWindow::cells(Cells {
                    size: m,
                    offset: m / 2,
                }),
            });
        }
        Schedule { stages }
    }

    /// Corrections each voxel of the level's result has had.
    pub fn corrections(&self) -> u32 {
        self.stages.iter().map(|s| s.passes).sum()
    }

    /// All steps in order.
    pub fn steps(&self) -> Vec<Step> {
        let mut out = Vec::new();
        let mut before = 0;
        for (si, st) in self.stages.iter().enumerate() {
            for pass in 1..=st.passes {
                if st.subpasses {
                    for c in 0..8u8 {
                        out.push(Step {
                            stage: si,
                            pass,
                            class: Some(c),
                            stage_start: before,
                        });
                    }
                } else {
                    out.push(Step {
                        stage: si,
                        pass,
                        class: None,
                        stage_start: before,
                    });
                }
            }
            before += st.passes;
        }
        out
    }

    /// An upper bound of the impact distance (§5, in voxels of the level) for a neighbourhood
    /// reach `r`: each step can reach `r` farther, but behind barriers a stage reaches at most
    /// across its cell plus `r` (§5.3.2: `min(P N s³/2, M + N/2)`).
    pub fn impact_distance(&self, r: i32) -> i32 {
        self.stages
            .iter()
            .map(|st| {
                let steps = st.passes as i32 * if st.subpasses { 8 } else { 1 };
                let free = steps * r;
                match st.window.barriers.iter().map(|c| c.size).min() {
                    Some(m) => free.min(m - 1 + r),
                    None => free,
                }
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subpass_versions_follow_the_class_order() {
        let s = Schedule::plain(2, true);
        let steps = s.steps();
        assert_eq!(steps.len(), 16);
        // Pass 1, class 3: classes 0..2 are already corrected once, 3.. not yet.
        let st = &steps[3];
        assert_eq!(st.class, Some(3));
        assert_eq!(st.latest_for_class(0), 1);
        assert_eq!(st.latest_for_class(2), 1);
        assert_eq!(st.latest_for_class(3), 0);
        assert_eq!(st.latest_for_class(7), 0);
        assert_eq!(st.version_after(), 1);
        // Pass 2, class 0: everyone has one correction.
        let st = &steps[8];
        assert_eq!(st.latest_for_class(0), 1);
        assert_eq!(st.latest_for_class(5), 1);
        assert_eq!(st.version_after(), 2);
    }

    #[test]
    fn barriers_read_outside_the_cell_at_the_stage_start() {
        let s = Schedule::dual_grid(3, false, 10);
        assert_eq!(s.stages.len(), 2);
        assert_eq!(s.stages[0].passes, 2);
        assert_eq!(s.stages[1].passes, 1);
        let steps = s.steps();
        let g = &steps[1]; // grid, pass 2
        let dual = &steps[2];
        let hg = &s.stages[0].window;
        let hd = &s.stages[1].window;
        let v = IVec3::new(9, 3, 3);
        // Same grid cell: latest; across the grid boundary at 10: stage start.
        assert_eq!(hg.version(g, v, IVec3::new(8, 3, 3)), 1);
        assert_eq!(hg.version(g, v, IVec3::new(10, 3, 3)), 0);
        // The dual cell of v spans 5..15: x = 10 is latest, 4 is the dual stage's start (2).
        assert_eq!(hd.version(dual, v, IVec3::new(10, 3, 3)), 2);
        assert_eq!(hd.version(dual, v, IVec3::new(4, 3, 3)), 2);
        assert_eq!(hd.read(v, IVec3::new(4, 3, 3)), Read::StageStart);
        // Intersection = min of versions.
        let both = hg.intersect(hd);
        for w in [
            IVec3::new(4, 3, 3),
            IVec3::new(8, 3, 3),
            IVec3::new(10, 3, 3),
        ] {
            assert_eq!(
                both.version(g, v, w),
                hg.version(g, v, w).min(hd.version(g, v, w))
            );
        }
        assert_eq!(HistoryWindow::latest().intersect(hg), *hg);
    }

    #[test]
    fn impact_distance_is_bounded_by_the_cells() {
        let r = 6;
        assert_eq!(Schedule::plain(2, true).impact_distance(r), 96);
        assert_eq!(
            Schedule::dual_grid(2, true, 12).impact_distance(r),
            2 * (11 + 6)
        );
        assert_eq!(Schedule::plain(1, false).impact_distance(r), 6);
    }
}
