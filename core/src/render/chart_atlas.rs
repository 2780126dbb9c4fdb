//! A texture atlas of *charts* spread over pages, and baking a [`SurfaceShader`] into it.
//!
//! The per-triangle atlas ([`super::atlas`]) gives every triangle its own region; at a million
//! triangles the gutters alone outgrow any texture. Here the caller gives each face a 2D
//! layout in texels at the density it wants (for jump maps, the walk's own texel addresses
//! where they are continuous: Zelinka & Garland §4.2 make most of the surface one patch of the
//! exemplar after another), and neighbouring faces whose layouts agree on their shared edge are
//! kept together:
//!
//! 1. **Charts.** Faces joined across every edge where both layouts give the same two points
//!    (and the same orientation) form candidate charts (union-find; a chart is named by its
//!    lowest face), cut along a grid of [`CANDIDATE_TILE`] texels so that candidates are
//!    bounded tasks that grow in parallel.
//! 2. **Injectivity.** Each candidate is grown breadth-first from its lowest face over an
//!    occupancy grid of texel centres: a face whose centres are already owned by a face it
//!    shares no vertex with (the layout folded over itself) or that would make the chart wider
//!    than a page is left out, and the faces left out form the next round's candidates. Faces
//!    smaller than a texel own no centre, so folds made only of them go unseen; they are
//!    sub-texel and bake to what their neighbours bake to.
//! 3. **Leaves.** A face that joins no neighbour (a seam face of the walk) is laid against one
//!    neighbouring chart: its own layout moved by the similarity that puts its shared edge on
//!    the chart's, if it stays on its side of that edge and claims free texels; otherwise it is
//!    a chart of its own.
//! 4. **Pages.** Chart bounding boxes plus a gutter are packed in shelves (tallest first) into
//!    pages at most `max_page` wide and high, the shelf width chosen so that a page is about
//!    square; a page is only as big as what it holds.
//!
//! Baking owns each texel centre to the lowest face that contains it, else (within
//! [`ATLAS_GUTTER`] texels of a face, in L∞) to the face nearest to it, shaded at the
//! nearest point of that face: gutters repeat the chart's border, so bilinear and mip-mapped
//! sampling never reach a background colour. Ownership is an atomic minimum over a key that
//! orders "inside" before "gutter", then distance, then face: the result does not depend on the
//! thread count.

use super::atlas::{ATLAS_GUTTER, finish_bake, nearest_barycentric, quantize};
use super::shader::SurfaceShader;
use crate::geom::Mesh;
use glam::{DVec2, Vec2};
use rayon::prelude::*;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};

/// Space around each chart's bounding box, in texels: the gutter, plus one texel so that a
/// bilinear sample of the gutter's last texel never reads another chart.
const CHART_MARGIN: f64 = ATLAS_GUTTER as f64 + 1.0;

/// Candidate charts are cut along a grid of this many texels in the layout (a face belongs to
/// the cell of its centroid). Growing a chart is sequential, so without the cut one patch of
/// the walk covering most of a million-triangle mesh kept one core busy while the other
/// idled; with it the candidates are many tasks of bounded size, and so is each task's
/// occupancy grid (its memory no longer grows with the patch, the exemplar or the density).
/// The cut adds chart borders, which the bake's gutters make invisible.
const CANDIDATE_TILE: f64 = 512.0;

/// Texture coordinates for baking over one or more pages.
#[derive(Debug, Clone, PartialEq)]
pub struct ChartAtlas {
    /// Width and height of each page, in texels.
    pub pages: Vec<[u32; 2]>,
    /// The page of each face.
    pub face_page: Vec<u32>,
    /// Corner texture coordinates per face on its page, glTF convention (u right, v down,
    /// [0, 1]).
    pub corner_uv: Vec<[Vec2; 3]>,
    /// The chart of each face (charts numbered from 0 in page order).
    pub face_chart: Vec<u32>,
    /// How many charts.
    pub charts: usize,
}

/// The atlas cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum ChartAtlasError {
    #[error("a face's layout is not finite (face {face})")]
    NotFinite { face: usize },
    #[error("the layout has {faces} faces but the mesh has {mesh}")]
    FaceCount { faces: usize, mesh: usize },
    /// One face alone is wider than a page (with its margins) at the layout's density.
    #[error("face {face} spans {extent:.0} texels, more than a {max_page}-texel page holds")]
    FaceTooLarge {
        face: usize,
        extent: f64,
        max_page: u32,
    },
}

impl ChartAtlasError {
    /// For [`ChartAtlasError::FaceTooLarge`]: the factor by which the density must shrink
    /// for every face to fit a page.
    pub fn shrink_to_fit(&self) -> Option<f64> {
        match self {
            ChartAtlasError::FaceTooLarge {
                extent, max_page, ..
            } => Some((*max_page as f64 - 2.0 * CHART_MARGIN - 1.0).max(1.0) / extent),
            _ => None,
        }
    }
}

/// Signed area (twice) of a layout triangle.
fn area2(t: &[DVec2; 3]) -> f64 {
    (t[1] - t[0]).perp_dot(t[2] - t[0])
}

/// Union-find with the smallest index as root (so roots do not depend on union order).
struct Dsu(Vec<u32>);

impl Dsu {
    fn find(&mut self, mut a: u32) -> u32 {
        while self.0[a as usize] != a {
            let p = self.0[a as usize];
            self.0[a as usize] = self.0[p as usize];
            a = p;
        }
        a
    }
    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            let (lo, hi) = (ra.min(rb), ra.max(rb));
            self.0[hi as usize] = lo;
        }
    }
}

/// The faces across each edge: for face f and edge k (corners k, k+1), the neighbouring face
/// and its edge index, when the edge has exactly two faces.
fn edge_neighbours(mesh: &Mesh) -> Vec<[(u32, u8); 3]> {
    let faces = mesh.triangles.len();
    let mut half: Vec<(u32, u32, u32, u8)> = (0..faces)
        .into_par_iter()
        .flat_map_iter(|f| {
            let t = mesh.triangles[f];
            (0..3u8).map(move |k| {
                let (a, b) = (t[k as usize], t[(k as usize + 1) % 3]);
                (a.min(b), a.max(b), f as u32, k)
            })
        })
        .collect();
    half.par_sort_unstable();
    let mut out = vec![[(u32::MAX, 0u8); 3]; faces];
    let mut i = 0;
    while i < half.len() {
        let mut j = i + 1;
        while j < half.len() && half[j].0 == half[i].0 && half[j].1 == half[i].1 {
            j += 1;
        }
        if j - i == 2 && half[i].0 != half[i].1 {
            let (f, k) = (half[i].2, half[i].3);
            let (g, l) = (half[i + 1].2, half[i + 1].3);
            if f != g {
                out[f as usize][k as usize] = (g, l);
                out[g as usize][l as usize] = (f, k);
            }
        }
        i = j;
    }
    out
}

/// How close (texels, L∞ from a face) another face's texels must be continuous with it: a
/// bilinear sample at a face's border reads texels up to one away, and mip levels further.
const CLEARANCE: f64 = 1.5;
/// How far apart (texels, at the face's own density) the surface points two faces give the
/// same texel may be and still count as continuous.
const CONTINUITY_TOLERANCE: f64 = 1.0;

/// A chart being grown: an owner grid of texel centres (the face that contains the centre, or
/// failing that a face within [`CLEARANCE`] of it), so that a new face can be checked against
/// the faces already near it.
struct Grower<'a> {
    mesh: &'a Mesh,
    /// Grid origin (texel cell of index 0) and size.
    origin: [i64; 2],
    size: [usize; 2],
    /// Owner face and whether the centre is inside it.
    owner: Vec<(u32, bool)>,
    /// Largest chart extent (texels) that fits a page with its margin.
    max_extent: f64,
    lo: DVec2,
    hi: DVec2,
    /// Scratch of [`Grower::try_add`], kept between faces (it runs once per face).
    claims: Vec<(usize, bool)>,
    continuous: Vec<u32>,
}

/// The surface point of face `f` nearest (in the layout) to the layout position `c`, how far
/// from `c` that is in texels, and the face's density in texels per world unit.
fn nearest_surface_point(
    mesh: &Mesh,
    f: u32,
    t: &[DVec2; 3],
    c: DVec2,
) -> Option<(glam::DVec3, f64, f64)> {
    let tri = mesh.triangles[f as usize];
    let p = tri.map(|v| mesh.positions[v as usize].as_dvec3());
    let area3 = (p[1] - p[0]).cross(p[2] - p[0]).length();
    let d = area2(t).abs();
    if area3 == 0.0 || d == 0.0 {
        return None;
    }
    let b = nearest_barycentric(c, t).as_dvec3();
    let q = t[0] * b.x + t[1] * b.y + t[2] * b.z;
    Some((
        p[0] * b.x + p[1] * b.y + p[2] * b.z,
        (q - c).length(),
        (d / area3).sqrt(),
    ))
}

impl<'a> Grower<'a> {
    fn shares_vertex(&self, f: u32, g: u32) -> bool {
        let (a, b) = (
            self.mesh.triangles[f as usize],
            self.mesh.triangles[g as usize],
        );
        a.iter().any(|v| b.contains(v))
    }

    fn new(mesh: &'a Mesh, lo: DVec2, hi: DVec2, max_extent: f64) -> Self {
        let pad = CLEARANCE.ceil() as i64 + 1;
        let origin = [lo.x.floor() as i64 - pad, lo.y.floor() as i64 - pad];
        let size = [
            (hi.x.ceil() as i64 + pad + 1 - origin[0]).max(1) as usize,
            (hi.y.ceil() as i64 + pad + 1 - origin[1]).max(1) as usize,
        ];
        Grower {
            mesh,
            origin,
            size,
            owner: vec![(u32::MAX, false); size[0] * size[1]],
            max_extent,
            lo: DVec2::INFINITY,
            hi: DVec2::NEG_INFINITY,
            claims: Vec::new(),
            continuous: Vec::new(),
        }
    }

    /// Adds face `f` laid at `t` if the texels within [`CLEARANCE`] of it that other faces
    /// already hold show the same surface (no fold, no unrelated face alongside) and the chart
    /// stays within a page, or unconditionally if `force` (a chart's first face); returns
    /// whether it was added. `layouts` gives the layout of an owner face.
    fn try_add(
        &mut self,
        f: u32,
        t: &[DVec2; 3],
        force: bool,
        layouts: &dyn Fn(u32) -> [DVec2; 3],
    ) -> bool {
        let lo = self.lo.min(t[0].min(t[1]).min(t[2]));
        let hi = self.hi.max(t[0].max(t[1]).max(t[2]));
        if !force && (hi - lo).max_element() > self.max_extent {
            return false;
        }
        let sign = area2(t).signum();
        let (blo, bhi) = (
            t[0].min(t[1]).min(t[2]) - DVec2::splat(CLEARANCE + 0.5),
            t[0].max(t[1]).max(t[2]) + DVec2::splat(CLEARANCE - 0.5),
        );
        let mut claims = std::mem::take(&mut self.claims);
        claims.clear();
        // Owners already found continuous with `f` (one check per owner, not per texel).
        let mut continuous = std::mem::take(&mut self.continuous);
        continuous.clear();
        for y in blo.y.ceil() as i64..=bhi.y.floor() as i64 {
            for x in blo.x.ceil() as i64..=bhi.x.floor() as i64 {
                let (i, j) = (x - self.origin[0], y - self.origin[1]);
                if i < 0 || j < 0 || i as usize >= self.size[0] || j as usize >= self.size[1] {
                    if force {
                        continue;
                    }
                    self.claims = claims;
                    self.continuous = continuous;
                    return false;
                }
                let c = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                let inside = sign != 0.0
                    && (0..3).all(|k| sign * (t[(k + 1) % 3] - t[k]).perp_dot(c - t[k]) > 0.0);
                // Every centre of the box grown by the clearance counts as near (a little
                // more than the L∞ clearance at the corners; cheaper than the exact distance).
                let cell = j as usize * self.size[0] + i as usize;
                let (o, _) = self.owner[cell];
                // Faces that share a vertex meet continuously wherever their layouts agree,
                // which is what joined them; any other owner is checked.
                if o != u32::MAX
                    && o != f
                    && !force
                    && !continuous.contains(&o)
                    && !self.shares_vertex(o, f)
                {
                    // Continuous faces put surface points about as far apart as the texel
                    // is from each face; an unrelated face's are far apart.
                    let mine = nearest_surface_point(self.mesh, f, t, c);
                    let theirs = nearest_surface_point(self.mesh, o, &layouts(o), c);
                    if let (Some((p, dp, density)), Some((q, dq, _))) = (mine, theirs)
                        && (p - q).length() * density > dp + dq + CONTINUITY_TOLERANCE
                    {
                        self.claims = claims;
                        self.continuous = continuous;
                        return false;
                    }
                    continuous.push(o);
                }
                if inside || o == u32::MAX {
                    claims.push((cell, inside));
                }
            }
        }
        for &(c, inside) in &claims {
            let (o, o_inside) = self.owner[c];
            if o == u32::MAX || (inside && !o_inside) {
                self.owner[c] = (f, inside);
            }
        }
        self.claims = claims;
        self.continuous = continuous;
        self.lo = lo;
        self.hi = hi;
        true
    }
}

/// One chart: its faces and their layout in chart coordinates (texels).
struct Chart {
    faces: Vec<u32>,
    layout: Vec<[DVec2; 3]>,
    lo: DVec2,
    hi: DVec2,
}

/// Grows the charts of one candidate component (faces sorted ascending), with the leaves
/// assigned to it; returns the charts and the faces left for the next round.
#[allow(clippy::too_many_arguments)] // the builder's shared tables, passed down as they are
fn grow_component(
    mesh: &Mesh,
    layout: &[[DVec2; 3]],
    joins: &[[bool; 3]],
    neighbours: &[[(u32, u8); 3]],
    member: &dyn Fn(u32, u32) -> bool,
    faces: &[u32],
    leaves: &[(u32, u8)],
    max_extent: f64,
    queued: &[std::sync::atomic::AtomicBool],
) -> (Vec<Chart>, Vec<u32>) {
    let mut lo = DVec2::INFINITY;
    let mut hi = DVec2::NEG_INFINITY;
    for &f in faces {
        for p in layout[f as usize] {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    // Leaves may reach a little beyond the component's box.
    let reach = leaves
        .iter()
        .map(|&(f, _)| {
            let t = &layout[f as usize];
            (t[1] - t[0])
                .length()
                .max((t[2] - t[1]).length())
                .max((t[0] - t[2]).length())
        })
        .fold(0.0, f64::max);
    let mut g = Grower::new(
        mesh,
        lo - DVec2::splat(reach),
        hi + DVec2::splat(reach),
        max_extent,
    );
    let mut added: Vec<u32> = Vec::new();
    let mut chart_layout: Vec<[DVec2; 3]> = Vec::new();
    // Where each leaf of the chart is laid (other faces lie at their own layout).
    let mut leaf_layout: std::collections::HashMap<u32, [DVec2; 3]> = Default::default();
    // Components are disjoint, so the flags of their faces are touched by one task each.
    let mut queue = VecDeque::from([faces[0]]);
    queued[faces[0] as usize].store(true, Ordering::Relaxed);
    while let Some(f) = queue.pop_front() {
        let placed = |o: u32| layout[o as usize];
        if !g.try_add(f, &layout[f as usize], added.is_empty(), &placed) {
            continue;
        }
        added.push(f);
        chart_layout.push(layout[f as usize]);
        for k in 0..3 {
            let (n, _) = neighbours[f as usize][k];
            if joins[f as usize][k]
                && member(f, n)
                && !queued[n as usize].swap(true, Ordering::Relaxed)
            {
                queue.push_back(n);
            }
        }
    }
    let in_chart: std::collections::HashMap<u32, usize> =
        added.iter().enumerate().map(|(i, &f)| (f, i)).collect();
    // Leaves: laid against the chart face across their edge `k`.
    let mut singles = Vec::new();
    for &(f, k) in leaves {
        let (n, l) = neighbours[f as usize][k as usize];
        let placed = in_chart.get(&n).and_then(|&i| {
            let own = &layout[f as usize];
            let theirs = &chart_layout[i];
            // Edge k of f runs from vertex va to vb; find each in n by its index, so that
            // inconsistently wound neighbours are mapped right too.
            let (k, l) = (k as usize, l as usize);
            let tf = mesh.triangles[f as usize];
            let tn = mesh.triangles[n as usize];
            let (va, vb) = (tf[k], tf[(k + 1) % 3]);
            let (Some(ia), Some(ib)) = (
                tn.iter().position(|&v| v == va),
                tn.iter().position(|&v| v == vb),
            ) else {
                return None;
            };
            let (a, b) = (own[k], own[(k + 1) % 3]);
            let (ca, cb) = (theirs[ia], theirs[ib]);
            let _ = l;
            let (e, ce) = (b - a, cb - ca);
            if e.length_squared() == 0.0 || ce.length_squared() == 0.0 {
                return None;
            }
            // The similarity z ↦ ca + (z - a)·ce/e in complex arithmetic.
            let rot = DVec2::new(e.dot(ce), e.perp_dot(ce)) / e.length_squared();
            let map = |p: DVec2| {
                ca + DVec2::new(
                    rot.x * (p - a).x - rot.y * (p - a).y,
                    rot.x * (p - a).y + rot.y * (p - a).x,
                )
            };
            let mut t = own.map(map);
            // The shared corners exactly where the chart has them (so they stay one vertex).
            t[k] = ca;
            t[(k + 1) % 3] = cb;
            // It must lie on the other side of the shared edge from the chart face.
            let apex = theirs[3 - ia - ib];
            let side = |p: DVec2| ce.perp_dot(p - ca);
            let opp = t[(k + 2) % 3];
            let placed = |o: u32| leaf_layout.get(&o).copied().unwrap_or(layout[o as usize]);
            if side(opp) * side(apex) >= 0.0 || !g.try_add(f, &t, false, &placed) {
                return None;
            }
            Some(t)
        });
        match placed {
            Some(t) => {
                added.push(f);
                chart_layout.push(t);
                leaf_layout.insert(f, t);
            }
            None => singles.push(f),
        }
    }
    let (lo, hi) = (g.lo, g.hi);
    let mut charts = vec![Chart {
        faces: added,
        layout: chart_layout,
        lo,
        hi,
    }];
    for f in singles {
        let t = layout[f as usize];
        charts.push(Chart {
            faces: vec![f],
            layout: vec![t],
            lo: t[0].min(t[1]).min(t[2]),
            hi: t[0].max(t[1]).max(t[2]),
        });
    }
    let taken: std::collections::HashSet<u32> = charts
        .iter()
        .flat_map(|c| c.faces.iter().copied())
        .collect();
    let left = faces
        .iter()
        .copied()
        .filter(|f| !taken.contains(f))
        .collect();
    (charts, left)
}

/// Builds the chart atlas of `mesh` from a per-face `layout` (corner positions in texels at
/// the wanted density; faces are joined where their layouts agree on a shared edge), with
/// pages at most `max_page` texels wide and high. Deterministic for any thread count.
pub fn build_chart_atlas(
    mesh: &Mesh,
    layout: &[[Vec2; 3]],
    max_page: u32,
) -> Result<ChartAtlas, ChartAtlasError> {
    let faces = mesh.triangles.len();
    if layout.len() != faces {
        return Err(ChartAtlasError::FaceCount {
            faces: layout.len(),
            mesh: faces,
        });
    }
    if let Some(face) = layout.iter().position(|t| !t.iter().all(|p| p.is_finite())) {
        return Err(ChartAtlasError::NotFinite { face });
    }
    let clock = std::time::Instant::now();
    let lap = |what: &str| {
        tracing::debug!(
            "chart atlas: {what} at {:.3} s",
            clock.elapsed().as_secs_f64()
        )
    };
    // Pages are a multiple of 4 texels wide and high, and no larger than `max_page`.
    let max_page = (max_page & !3).max(4);
    let lay: Vec<[DVec2; 3]> = layout.par_iter().map(|t| t.map(|p| p.as_dvec2())).collect();
    let max_extent = (max_page as f64 - 2.0 * CHART_MARGIN - 1.0).max(1.0);
    // A face wider than a page fails before any chart grows (the widest one is named).
    if let Some((face, extent)) = lay
        .par_iter()
        .enumerate()
        .map(|(f, t)| {
            (
                f,
                (t[0].max(t[1]).max(t[2]) - t[0].min(t[1]).min(t[2])).max_element(),
            )
        })
        .filter(|&(_, e)| e > max_extent)
        .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
    {
        return Err(ChartAtlasError::FaceTooLarge {
            face,
            extent,
            max_page,
        });
    }
    let neighbours = edge_neighbours(mesh);
    lap("edge neighbours");
    let sign = |f: usize| area2(&lay[f]).signum();
    // Joined edges: the neighbour has the same two points and the same orientation.
    let joins: Vec<[bool; 3]> = (0..faces)
        .into_par_iter()
        .map(|f| {
            let t = mesh.triangles[f];
            std::array::from_fn(|k| {
                let (g, _) = neighbours[f][k];
                if g == u32::MAX || sign(f) == 0.0 || sign(f) != sign(g as usize) {
                    return false;
                }
                let g = g as usize;
                // The same two vertices at the same two points, whatever the winding.
                let u = mesh.triangles[g];
                let at = |v: u32| u.iter().position(|&w| w == v).map(|i| lay[g][i]);
                at(t[k]) == Some(lay[f][k]) && at(t[(k + 1) % 3]) == Some(lay[f][(k + 1) % 3])
            })
        })
        .collect();
    let joined = |f: usize| joins[f].iter().any(|&j| j);
    let tile: Vec<[i64; 2]> = lay
        .par_iter()
        .map(|t| {
            let c = (t[0] + t[1] + t[2]) / (3.0 * CANDIDATE_TILE);
            [c.x.floor() as i64, c.y.floor() as i64]
        })
        .collect();

    // Leaves: faces joined to nobody, each given to the neighbouring joined face of lowest
    // index (so to that face's component).
    let mut leaf_of: Vec<Option<(u32, u8)>> = vec![None; faces];
    for f in 0..faces {
        if joined(f) {
            continue;
        }
        let mut best: Option<(u32, u8)> = None;
        for k in 0..3 {
            let (g, _) = neighbours[f][k];
            if g != u32::MAX && joined(g as usize) && best.is_none_or(|(b, _)| g < b) {
                best = Some((g, k as u8));
            }
        }
        leaf_of[f] = best.map(|(_, k)| (f as u32, k));
    }

    lap("joins, tiles, leaves");
    let mut charts: Vec<Chart> = Vec::new();
    let mut pool: Vec<u32> = (0..faces as u32).filter(|&f| joined(f as usize)).collect();
    let mut first_round = true;
    while !pool.is_empty() {
        let in_pool = {
            let mut m = vec![false; faces];
            for &f in &pool {
                m[f as usize] = true;
            }
            m
        };
        let member = |f: u32, g: u32| in_pool[g as usize] && tile[f as usize] == tile[g as usize];
        let mut dsu = Dsu((0..faces as u32).collect());
        for &f in &pool {
            for k in 0..3 {
                let (g, _) = neighbours[f as usize][k];
                if joins[f as usize][k] && member(f, g) {
                    dsu.union(f, g);
                }
            }
        }
        let mut groups: std::collections::BTreeMap<u32, Vec<u32>> = Default::default();
        for &f in &pool {
            groups.entry(dsu.find(f)).or_default().push(f);
        }
        let mut leaves: std::collections::BTreeMap<u32, Vec<(u32, u8)>> = Default::default();
        if first_round {
            for (f, l) in leaf_of.iter().enumerate() {
                if let Some((_, k)) = l {
                    let (g, _) = neighbours[f][*k as usize];
                    leaves.entry(dsu.find(g)).or_default().push((f as u32, *k));
                }
            }
        }
        let groups: Vec<(u32, Vec<u32>)> = groups.into_iter().collect();
        tracing::debug!(
            "chart atlas: {} candidates, the largest of {} faces",
            groups.len(),
            groups.iter().map(|(_, g)| g.len()).max().unwrap_or(0)
        );
        let queued: Vec<std::sync::atomic::AtomicBool> = (0..faces)
            .map(|_| std::sync::atomic::AtomicBool::new(false))
            .collect();
        let results: Vec<(Vec<Chart>, Vec<u32>)> = groups
            .par_iter()
            // One task per candidate: candidates are ordered by lowest face, so the big ones sit
            // together, and rayon's default split (a few pieces, each run sequentially unless
            // stolen early) left them all to one thread: growing took as long on two threads
            // as on one (1.9 s on the 1.4M-triangle elephant; 1.2 + 0.9 s of work per thread
            // with one task each).
            .with_max_len(1)
            .map(|(root, fs)| {
                let empty = Vec::new();
                let lv = if first_round {
                    leaves.get(root).unwrap_or(&empty)
                } else {
                    &empty
                };
                grow_component(
                    mesh,
                    &lay,
                    &joins,
                    &neighbours,
                    &member,
                    fs,
                    lv,
                    max_extent,
                    &queued,
                )
            })
            .collect();
        let mut next = Vec::new();
        for (c, left) in results {
            charts.extend(c);
            next.extend(left);
        }
        next.sort_unstable();
        lap(&format!(
            "a round: {} charts so far, {} faces left",
            charts.len(),
            next.len()
        ));
        pool = next;
        first_round = false;
    }
    // Faces joined to nobody and with no joined neighbour: charts of their own.
    for f in 0..faces {
        if !joined(f) && leaf_of[f].is_none() {
            let t = lay[f];
            charts.push(Chart {
                faces: vec![f as u32],
                layout: vec![t],
                lo: t[0].min(t[1]).min(t[2]),
                hi: t[0].max(t[1]).max(t[2]),
            });
        }
    }
    lap("single charts");
    // A chart's name is its lowest face: order them so, for a layout independent of rounds.
    charts.par_sort_unstable_by_key(|c| c.faces.iter().copied().min().unwrap_or(u32::MAX));
    lap("charts sorted");
    // Only a chart's forced first face can exceed a page; name the widest such face.
    if let Some((face, extent)) = charts
        .iter()
        .filter(|c| (c.hi - c.lo).max_element() > max_extent)
        .map(|c| (c.faces[0] as usize, (c.hi - c.lo).max_element()))
        .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
    {
        return Err(ChartAtlasError::FaceTooLarge {
            face,
            extent,
            max_page,
        });
    }
    let atlas = pack_pages(faces, &charts, max_page);
    lap("packed");
    Ok(atlas)
}

/// Shelf-packs the charts' boxes (plus margins) into pages.
fn pack_pages(faces: usize, charts: &[Chart], max_page: u32) -> ChartAtlas {
    let dims: Vec<[u32; 2]> = charts
        .iter()
        .map(|c| {
            let e = (c.hi - c.lo).max(DVec2::ZERO);
            [
                (e.x + 2.0 * CHART_MARGIN).ceil() as u32,
                (e.y + 2.0 * CHART_MARGIN).ceil() as u32,
            ]
        })
        .collect();
    let area: f64 = dims.iter().map(|d| d[0] as f64 * d[1] as f64).sum();
    let widest = dims.iter().map(|d| d[0]).max().unwrap_or(1);
    // Shelves waste some room: aim the width at a square page of 1.25× the charts' area.
    let width = ((area * 1.25).sqrt().ceil() as u32)
        .next_multiple_of(4)
        .max(widest)
        .min(max_page);
    let mut order: Vec<usize> = (0..charts.len()).collect();
    order.sort_by(|&a, &b| {
        dims[b][1]
            .cmp(&dims[a][1])
            .then(dims[b][0].cmp(&dims[a][0]))
            .then(a.cmp(&b))
    });
    let mut origin = vec![(0u32, [0u32; 2]); charts.len()];
    let mut pages: Vec<[u32; 2]> = vec![[0, 0]];
    let (mut x, mut y, mut shelf) = (0u32, 0u32, 0u32);
    for &c in &order {
        let [w, h] = dims[c];
        if x + w > width {
            y += shelf;
            x = 0;
            shelf = 0;
        }
        if y + h > max_page {
            pages.push([0, 0]);
            x = 0;
            y = 0;
            shelf = 0;
        }
        let p = pages.len() - 1;
        origin[c] = (p as u32, [x, y]);
        pages[p][0] = pages[p][0].max(x + w);
        pages[p][1] = pages[p][1].max(y + h);
        x += w;
        shelf = shelf.max(h);
    }
    for p in &mut pages {
        p[0] = p[0].max(1).next_multiple_of(4);
        p[1] = p[1].max(1).next_multiple_of(4);
    }
    let mut face_page = vec![0u32; faces];
    let mut corner_uv = vec![[Vec2::ZERO; 3]; faces];
    let mut face_chart = vec![0u32; faces];
    for (ci, c) in charts.iter().enumerate() {
        let (p, [x0, y0]) = origin[ci];
        let size = DVec2::new(pages[p as usize][0] as f64, pages[p as usize][1] as f64);
        let shift = DVec2::new(x0 as f64, y0 as f64) + DVec2::splat(CHART_MARGIN) - c.lo;
        for (&f, t) in c.faces.iter().zip(&c.layout) {
            face_page[f as usize] = p;
            face_chart[f as usize] = ci as u32;
            corner_uv[f as usize] = t.map(|q| ((q + shift) / size).as_vec2());
        }
    }
    ChartAtlas {
        pages,
        face_page,
        corner_uv,
        face_chart,
        charts: charts.len(),
    }
}

/// Bakes every shader into page `page` of the atlas: one image per shader (opaque,
/// sRGB-encoded like the shaders' colours). Deterministic for any thread count.
pub fn bake_page(
    atlas: &ChartAtlas,
    page: usize,
    mesh: &Mesh,
    shaders: &[&dyn SurfaceShader],
) -> Vec<image::RgbaImage> {
    let [w, h] = atlas.pages[page];
    let (wu, hu) = (w as usize, h as usize);
    let size = DVec2::new(w as f64, h as f64);
    let g = ATLAS_GUTTER as f64;
    let faces: Vec<u32> = (0..atlas.face_page.len().min(mesh.triangles.len()) as u32)
        .filter(|&f| atlas.face_page[f as usize] == page as u32)
        .collect();
    let tri = |f: u32| atlas.corner_uv[f as usize].map(|uv| uv.as_dvec2() * size);
    // Ownership keys: face (inside) < 2^63 | distance bits << 32 | face (gutter).
    let keys: Vec<AtomicU64> = (0..wu * hu).map(|_| AtomicU64::new(u64::MAX)).collect();
    // Two passes over each face's box: every inside key is below every gutter key, so once the
    // first pass has set the inside keys, the second (over the box grown by the gutter) skips
    // the nearest-point search (most of the bake's work on a dense page) wherever one is set:
    // every key it skips would have lost, so each texel ends with the same least key as in one
    // pass, for any thread count.
    for gutter in [false, true] {
        faces.par_iter().for_each(|&f| {
            let t = tri(f);
            let pad = if gutter { g } else { 0.0 };
            let lo = t[0].min(t[1]).min(t[2]) - DVec2::splat(pad + 0.5);
            let hi = t[0].max(t[1]).max(t[2]) + DVec2::splat(pad - 0.5);
            let (x0, x1) = (
                lo.x.ceil().max(0.0) as i64,
                hi.x.floor().min(size.x - 1.0) as i64,
            );
            let (y0, y1) = (
                lo.y.ceil().max(0.0) as i64,
                hi.y.floor().min(size.y - 1.0) as i64,
            );
            let sign = area2(&t).signum();
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let slot = &keys[y as usize * wu + x as usize];
                    let c = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                    let inside = sign != 0.0
                        && (0..3).all(|k| {
                            let (a, b) = (t[k], t[(k + 1) % 3]);
                            sign * (b - a).perp_dot(c - a) >= 0.0
                        });
                    let key = match (gutter, inside) {
                        // The second pass gives inside keys again over its wider box: the
                        // inside test on a sliver that is one only through rounding may pass
                        // beyond the face's own box, where the first pass did not look.
                        // (`fetch_min` of a key already there changes nothing.)
                        (_, true) => f as u64,
                        (false, false) => continue,
                        (true, false) => {
                            if slot.load(Ordering::Relaxed) < 1 << 63 {
                                continue;
                            }
                            let b = nearest_barycentric(c, &t).as_dvec3();
                            let p = t[0] * b.x + t[1] * b.y + t[2] * b.z;
                            let d = (p - c).abs().max_element();
                            if d > g {
                                continue;
                            }
                            (1u64 << 63)
                                | (((p - c).length() as f32).to_bits() as u64) << 32
                                | f as u64
                        }
                    };
                    slot.fetch_min(key, Ordering::Relaxed);
                }
            }
        });
    }
    let keys: Vec<u64> = keys.into_iter().map(|k| k.into_inner()).collect();
    shaders
        .iter()
        .map(|shader| {
            let mut px = vec![[0u8; 4]; wu * hu];
            px.par_chunks_mut(wu).enumerate().for_each(|(y, row)| {
                for (x, out) in row.iter_mut().enumerate() {
                    let key = keys[y * wu + x];
                    if key == u64::MAX {
                        continue;
                    }
                    let f = (key & 0xffff_ffff) as u32;
                    let c = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                    let col = shader.albedo(f as usize, nearest_barycentric(c, &tri(f)));
                    *out = [quantize(col.x), quantize(col.y), quantize(col.z), 255];
                }
            });
            finish_bake(px, w, h)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::PureMath;
    use crate::render::views::tests::uv_sphere;
    use glam::Vec3;

    /// Colour = a smooth function of the surface point: what a correct bake reproduces at any
    /// point of any face, whatever chart or page it lands in.
    struct PositionColour<'a>(&'a Mesh);
    impl SurfaceShader for PositionColour<'_> {
        fn albedo(&self, face: usize, bary: Vec3) -> Vec3 {
            let t = self.0.triangles[face];
            let p = self.0.positions[t[0] as usize] * bary.x
                + self.0.positions[t[1] as usize] * bary.y
                + self.0.positions[t[2] as usize] * bary.z;
            p * 0.5 + Vec3::splat(0.5)
        }
    }

    fn sample(img: &image::RgbaImage, uv: Vec2) -> Vec3 {
        let (w, h) = (img.width() as f32, img.height() as f32);
        let (x, y) = (uv.x * w - 0.5, uv.y * h - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let px = |i: f32, j: f32| {
            let p = img.get_pixel(i.clamp(0.0, w - 1.0) as u32, j.clamp(0.0, h - 1.0) as u32);
            Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32) / 255.0
        };
        (px(x0, y0) * (1.0 - fx) + px(x0 + 1.0, y0) * fx) * (1.0 - fy)
            + (px(x0, y0 + 1.0) * (1.0 - fx) + px(x0 + 1.0, y0 + 1.0) * fx) * fy
    }

    /// Every page of `atlas` baked with `shader`.
    fn bake_every_page(
        atlas: &ChartAtlas,
        mesh: &Mesh,
        shader: &dyn SurfaceShader,
    ) -> Vec<image::RgbaImage> {
        (0..atlas.pages.len())
            .map(|p| bake_page(atlas, p, mesh, &[shader]).remove(0))
            .collect()
    }

    /// A layout where neighbouring faces agree (the sphere's own (u, v) unrolled, in texels)
    /// except along one meridian, plus per-face shapes there.
    fn sphere_layout(mesh: &Mesh, texels: f32) -> Vec<[Vec2; 3]> {
        mesh.triangles
            .iter()
            .map(|t| {
                let p = t.map(|v| mesh.positions[v as usize]);
                let ang = p.map(|q| q.z.atan2_pure(q.x));
                let wraps = ang.iter().any(|a| *a > 2.5) && ang.iter().any(|a| *a < -2.5);
                let pole = p.iter().any(|q| q.y.abs() > 0.999);
                if wraps || pole {
                    // Its true shape, alone.
                    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
                    let x = e1.normalize();
                    let y = e1.cross(e2).cross(x).normalize();
                    [
                        Vec2::ZERO,
                        Vec2::new(e1.dot(x), 0.0),
                        Vec2::new(e2.dot(x), e2.dot(y)),
                    ]
                    .map(|q| q * texels)
                } else {
                    std::array::from_fn(|k| Vec2::new(ang[k], p[k].y.acos_pure()) * texels)
                }
            })
            .collect()
    }

    #[test]
    fn every_face_bakes_to_its_own_colours_on_any_page() {
        let (mesh, _) = uv_sphere(16, 32);
        let mesh = Mesh::new(mesh.positions, mesh.triangles);
        let layout = sphere_layout(&mesh, 40.0);
        // Small pages: the charts spread over several.
        let atlas = build_chart_atlas(&mesh, &layout, 96).unwrap();
        assert!(atlas.pages.len() > 2, "{:?}", atlas.pages);
        assert!(
            atlas.charts < mesh.triangles.len() / 4,
            "{} charts",
            atlas.charts
        );
        let shader = PositionColour(&mesh);
        let pages = bake_every_page(&atlas, &mesh, &shader);
        let mut worst: f32 = 0.0;
        for f in 0..mesh.triangles.len() {
            for bary in [
                Vec3::splat(1.0 / 3.0),
                Vec3::new(0.6, 0.2, 0.2),
                Vec3::new(0.1, 0.45, 0.45),
            ] {
                let uv = atlas.corner_uv[f];
                let at = uv[0] * bary.x + uv[1] * bary.y + uv[2] * bary.z;
                let got = sample(&pages[atlas.face_page[f] as usize], at);
                let want = shader.albedo(f, bary);
                worst = worst.max((got - want).abs().max_element());
            }
        }
        assert!(worst < 0.04, "worst colour error {worst}");
    }

    /// A flat strip laid along a spiral that overlaps itself after one turn: every shared
    /// corner agrees, so only the fold check keeps the turns apart.
    #[test]
    fn a_layout_that_folds_over_itself_is_cut_and_every_face_keeps_its_colours() {
        let (cols, rows) = (80u32, 3u32);
        let mut positions = Vec::new();
        for j in 0..=rows {
            for i in 0..=cols {
                positions.push(Vec3::new(
                    i as f32 / cols as f32 * 2.0 - 1.0,
                    j as f32 * 0.04,
                    0.0,
                ));
            }
        }
        let id = |i: u32, j: u32| j * (cols + 1) + i;
        let mut triangles = Vec::new();
        for j in 0..rows {
            for i in 0..cols {
                triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let mesh = Mesh::new(positions, triangles);
        // 96 texels of strip (x in [-1, 1], red 0 to 1) along circles of radius 8 to 11
        // texels (50 to 69 around): the strip goes round about 1.6 times, and the turns that
        // overlap differ by about half the red range.
        let laid = |v: u32| {
            let p = mesh.positions[v as usize];
            let (x, y) = ((p.x + 1.0) * 48.0, p.y / 0.04);
            let r = 8.0 + y;
            let a = x / 8.0;
            Vec2::new(40.0 + r * a.cos_pure(), 40.0 + r * a.sin_pure())
        };
        let layout: Vec<[Vec2; 3]> = mesh.triangles.iter().map(|t| t.map(laid)).collect();
        let atlas = build_chart_atlas(&mesh, &layout, 256).unwrap();
        assert!(atlas.charts >= 2, "the spiral was kept as one chart");
        // No two faces of one chart claim the same texel centre with different colours: each
        // face bakes to its own position colour wherever it lies.
        let shader = PositionColour(&mesh);
        let pages = bake_every_page(&atlas, &mesh, &shader);
        let mut worst: f32 = 0.0;
        for f in 0..mesh.triangles.len() {
            let uv = atlas.corner_uv[f];
            let at = (uv[0] + uv[1] + uv[2]) / 3.0;
            let got = sample(&pages[atlas.face_page[f] as usize], at);
            worst = worst.max(
                (got - shader.albedo(f, Vec3::splat(1.0 / 3.0)))
                    .abs()
                    .max_element(),
            );
        }
        assert!(worst < 0.03, "worst colour error {worst}");
    }

    #[test]
    fn pages_stay_within_a_side_that_is_not_a_multiple_of_four() {
        let (mesh, _) = uv_sphere(12, 24);
        let mesh = Mesh::new(mesh.positions, mesh.triangles);
        let layout = sphere_layout(&mesh, 30.0);
        let atlas = build_chart_atlas(&mesh, &layout, 130).unwrap();
        assert!(atlas.pages.len() > 1);
        for [w, h] in &atlas.pages {
            assert!(*w <= 130 && *h <= 130, "{w}×{h}");
        }
    }

    #[test]
    fn candidate_charts_are_cut_on_the_tile_grid_and_keep_their_faces_whole() {
        // A flat 41×41-vertex grid laid at 40 texels per cell: one continuous layout of 1600
        // texels, which the tile grid must cut into bounded charts (4 × 4 tiles, as the
        // seams are off the cell lines), each face kept whole in exactly one chart.
        let mesh = crate::geom::primitives::grid(41, 1.0);
        let layout: Vec<[Vec2; 3]> = mesh
            .triangles
            .iter()
            .map(|t| t.map(|v| mesh.positions[v as usize].truncate() * 40.0 + Vec2::splat(3.0)))
            .collect();
        let atlas = build_chart_atlas(&mesh, &layout, 8192).unwrap();
        assert!(atlas.charts >= 16, "{} charts", atlas.charts);
        // No chart spans more than a tile plus one face.
        let mut lo = vec![Vec2::splat(f32::INFINITY); atlas.charts];
        let mut hi = vec![Vec2::splat(f32::NEG_INFINITY); atlas.charts];
        for (f, t) in layout.iter().enumerate() {
            let c = atlas.face_chart[f] as usize;
            for p in t {
                lo[c] = lo[c].min(*p);
                hi[c] = hi[c].max(*p);
            }
        }
        for c in 0..atlas.charts {
            let e = (hi[c] - lo[c]).max_element();
            assert!(
                e <= CANDIDATE_TILE as f32 + 40.0,
                "chart {c} spans {e} texels"
            );
        }
        // Inside a chart the layout is kept up to a translation: corners keep their spacing.
        let page = atlas.pages[0];
        for (f, t) in layout.iter().enumerate() {
            let uv = atlas.corner_uv[f];
            let d = (uv[1] - uv[0]) * Vec2::new(page[0] as f32, page[1] as f32);
            assert!(
                (d - (t[1] - t[0])).length() < 1e-2,
                "face {f}: {d} vs {}",
                t[1] - t[0]
            );
        }
    }

    #[test]
    fn bakes_do_not_depend_on_the_thread_count() {
        let (mesh, _) = uv_sphere(12, 24);
        let mesh = Mesh::new(mesh.positions, mesh.triangles);
        let layout = sphere_layout(&mesh, 30.0);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let atlas = build_chart_atlas(&mesh, &layout, 128).unwrap();
                    let shader = PositionColour(&mesh);
                    let pages: Vec<Vec<u8>> = (0..atlas.pages.len())
                        .map(|p| bake_page(&atlas, p, &mesh, &[&shader]).remove(0).into_raw())
                        .collect();
                    (atlas, pages)
                })
        };
        assert_eq!(run(1), run(3));
    }
}
