//! Feature-curve preprocessing for curve orientation (Xu et al., "Feature-Aligned Shape
//! Texturing", §4.1): "we pre-process the salient curves given on the input surface to group
//! close-by, disconnected curve segments along a smooth salient feature and break long curves
//! at high curvature points. Grouping and breaking are controlled by user-specified distance
//! and curvature thresholds". The orientation algorithm then gives each resulting curve one
//! sign, so a curve must be a piece that can sensibly carry one direction.
//!
//! The paper gives no procedure; this one is:
//!
//! 1. **Joining.** Two open curve ends `a`, `b` are joined when they are at most
//!    `join_distance` apart (straight-line distance) and the feature continues smoothly across
//!    the gap: the outward end tangents point at each other within `break_angle`
//!    (angle(t_a, −t_b) ≤ break_angle) and, when the gap is not empty, each end tangent points
//!    along the gap within `break_angle`. The gap is bridged by the shortest edge path between
//!    the two end vertices (Dijkstra on edge lengths, searched only up to
//!    3·gap + 3·mean edge length: a longer detour is not "close-by"). The two ends of one curve
//!    may join too, closing it into a loop. Candidates are taken shortest gap first (ties by
//!    curve index and end), one join at a time, so the result does not depend on input order
//!    beyond those ties.
//! 2. **Breaking.** A curve is broken at vertices where it turns by more than `break_angle`.
//!    Vertex paths along mesh edges zig-zag (on a grid whose cells have one diagonal, a line
//!    at −45° is a staircase of 90° turns), so the turn at vertex i is measured between the
//!    chords p(i) − p(i−4) and p(i+4) − p(i) ([`SPAN`] = 4 edges, clamped at open ends): a
//!    regular staircase then measures 0°, and a feature traced one edge off here and there
//!    (a quantized wave) stays below ~50°, while a real corner keeps its full angle. A corner
//!    exceeds the threshold at up to 2·SPAN − 1 consecutive vertices; the curve is broken only
//!    at the sharpest vertex of each such run (two corners closer than SPAN edges count as
//!    one), and never within two edges of an open end (no piece shorter than two edges). The
//!    break vertex is kept in both pieces, so the pieces still meet (the field constraint
//!    there is the average of the two pieces' tangents, see `feature_field`). A loop with a
//!    single break vertex is
//!    left whole: one piece would get one sign anyway.
//!
//! Joining runs before breaking, so a join whose bridging path makes a kink is broken again.
//! Curves with fewer than two vertices (no tangent) and curves naming vertices outside the mesh
//! are dropped.

use crate::extract::crease_lines::Polyline;
use crate::geom::Mesh;
use crate::graph::Dijkstra;
use glam::Vec3;
use texsyn_core::math::PureMath;

/// Number of edges over which incoming/outgoing directions are measured (see module doc).
pub const SPAN: usize = 4;

/// Joins and breaks `curves` (see the module doc). `join_distance` is in object units,
/// `break_angle` in degrees. `fixed[i]` (missing: false) says `curves[i]`'s direction is the
/// user's: two fixed curves are joined only where their directions run on through the join
/// (spokes drawn outward from one centre stay apart even where two are collinear).
///
/// Returns each resulting curve with the sign that keeps the fixed curves it holds running
/// their own way (+1: its vertex order), `None` for a curve that holds none. Joining reverses
/// whole curves and breaking keeps order, so a piece of a fixed curve, or a join of one with
/// free curves and bridging paths, has one such sign.
pub fn group_and_break(
    mesh: &Mesh,
    curves: &[Polyline],
    fixed: &[bool],
    join_distance: f32,
    break_angle: f32,
) -> Vec<(Polyline, Option<i8>)> {
    let n = mesh.vertex_count();
    let (mut work, mut direction): (Vec<Polyline>, Vec<Option<bool>>) = curves
        .iter()
        .enumerate()
        .filter(|(_, c)| c.vertices.len() >= 2 && c.vertices.iter().all(|&v| (v as usize) < n))
        .map(|(i, c)| {
            (
                c.clone(),
                fixed.get(i).copied().unwrap_or(false).then_some(true),
            )
        })
        .unzip();
    let cos_limit = break_angle.to_radians().cos_pure();
    join_all(mesh, &mut work, &mut direction, join_distance, cos_limit);
    work.iter()
        .zip(&direction)
        .flat_map(|(c, d)| {
            let sign = d.map(|along| if along { 1 } else { -1 });
            break_curve(mesh, c, cos_limit)
                .into_iter()
                .map(move |piece| (piece, sign))
        })
        .filter(|(c, _)| c.vertices.len() >= 2)
        .collect()
}

fn pos(mesh: &Mesh, v: u32) -> Vec3 {
    mesh.positions[v as usize]
}

/// Outward tangent at one end of an open curve (end 0: first vertex, end 1: last).
fn end_tangent(mesh: &Mesh, c: &Polyline, end: usize) -> Vec3 {
    let m = c.vertices.len();
    let s = SPAN.min(m - 1);
    let (at, inner) = if end == 0 {
        (c.vertices[0], c.vertices[s])
    } else {
        (c.vertices[m - 1], c.vertices[m - 1 - s])
    };
    (pos(mesh, at) - pos(mesh, inner)).normalize_or_zero()
}

fn end_vertex(c: &Polyline, end: usize) -> u32 {
    if end == 0 {
        c.vertices[0]
    } else {
        *c.vertices
            .last()
            .expect("curves have at least two vertices")
    }
}

/// Joins curve ends one pair at a time, smallest gap first, until no pair qualifies.
/// `direction[i]`: for a curve holding fixed pieces, whether they run along its vertex order
/// (`None`: no fixed piece); kept up to date through joins.
fn join_all(
    mesh: &Mesh,
    curves: &mut Vec<Polyline>,
    direction: &mut Vec<Option<bool>>,
    join_distance: f32,
    cos_limit: f32,
) {
    let mean_edge = mesh.mean_edge_length();
    let mut search = Dijkstra::new(mesh.vertex_count(), u32::MAX);
    loop {
        // (gap, curve i, end of i, curve j, end of j) with (i, ei) < (j, ej).
        let mut cand: Vec<(f32, usize, usize, usize, usize)> = Vec::new();
        for i in 0..curves.len() {
            if curves[i].closed {
                continue;
            }
            for ei in 0..2 {
                for j in i..curves.len() {
                    if curves[j].closed {
                        continue;
                    }
                    for ej in 0..2 {
                        if (j, ej) <= (i, ei) {
                            continue;
                        }
                        // Closing a curve into a loop needs enough vertices for a loop.
                        if i == j && curves[i].vertices.len() < 2 * SPAN + 1 {
                            continue;
                        }
                        let (a, b) = (end_vertex(&curves[i], ei), end_vertex(&curves[j], ej));
                        let gap = pos(mesh, b) - pos(mesh, a);
                        let d = gap.length();
                        if d > join_distance {
                            continue;
                        }
                        let (ta, tb) = (
                            end_tangent(mesh, &curves[i], ei),
                            end_tangent(mesh, &curves[j], ej),
                        );
                        if ta.dot(-tb) < cos_limit {
                            continue;
                        }
                        if d > 0.0 {
                            let g = gap / d;
                            if ta.dot(g) < cos_limit || tb.dot(-g) < cos_limit {
                                continue;
                            }
                        }
                        cand.push((d, i, ei, j, ej));
                    }
                }
            }
        }
        cand.sort_by(|x, y| {
            x.0.total_cmp(&y.0)
                .then((x.1, x.2, x.3, x.4).cmp(&(y.1, y.2, y.3, y.4)))
        });
        let mut joined = false;
        for &(d, i, ei, j, ej) in &cand {
            // The joined curve runs along i towards its end ei, then along j from its end ej.
            let along_i = direction[i].map(|f| f == (ei == 1));
            let along_j = direction[j].map(|f| f == (ej == 0));
            if i != j && along_i.is_some() && along_j.is_some() && along_i != along_j {
                continue;
            }
            let (a, b) = (end_vertex(&curves[i], ei), end_vertex(&curves[j], ej));
            let limit = 3.0 * d as f64 + 3.0 * mean_edge as f64;
            let Some(path) = shortest_path_in(mesh, &mut search, a, b, limit) else {
                continue;
            };
            // Curve i oriented to end at a.
            let mut seq = curves[i].vertices.clone();
            if ei == 0 {
                seq.reverse();
            }
            if i == j {
                // Closing into a loop: the path's last vertex b is seq[0].
                seq.extend(path.iter().skip(1).take(path.len().saturating_sub(2)));
                if a == b {
                    seq.pop();
                }
                curves[i] = Polyline {
                    vertices: seq,
                    closed: true,
                };
                direction[i] = along_i;
            } else {
                let mut other = curves[j].vertices.clone();
                if ej == 1 {
                    other.reverse();
                }
                seq.extend(path.iter().skip(1));
                seq.extend(other.iter().skip(1));
                curves[i] = Polyline {
                    vertices: seq,
                    closed: false,
                };
                direction[i] = along_i.or(along_j);
                curves.remove(j);
                direction.remove(j);
            }
            joined = true;
            break;
        }
        if !joined {
            return;
        }
    }
}

/// Shortest edge path from `a` to `b` (both included), or None when it is longer than
/// `limit` (object units).
pub fn shortest_path(mesh: &Mesh, a: u32, b: u32, limit: f64) -> Option<Vec<u32>> {
    shortest_path_in(
        mesh,
        &mut Dijkstra::new(mesh.vertex_count(), u32::MAX),
        a,
        b,
        limit,
    )
}

/// [`shortest_path`] with the search's arrays reused from earlier calls.
fn shortest_path_in(
    mesh: &Mesh,
    search: &mut Dijkstra,
    a: u32,
    b: u32,
    limit: f64,
) -> Option<Vec<u32>> {
    if a == b {
        return Some(vec![a]);
    }
    let adj = mesh.adjacency();
    search.reset();
    search.add_source(a);
    let found = search.run(&[b], |search, v, d| {
        for &w in adj.neighbors(v as usize) {
            let nd = d + pos(mesh, v).as_dvec3().distance(pos(mesh, w).as_dvec3());
            if nd > limit {
                continue;
            }
            search.relax(w, nd, v);
        }
    });
    found.then(|| search.path(a, b))
}

/// Turning angle cosine at index i (see the module doc): between the chords over SPAN edges
/// before and after i; 1 (no turn) where a chord is empty.
fn turn_cos(mesh: &Mesh, c: &Polyline, i: usize) -> f32 {
    let m = c.vertices.len();
    let (prev, next) = if c.closed {
        let s = SPAN.min((m - 1) / 2).max(1);
        (c.vertices[(i + m - s) % m], c.vertices[(i + s) % m])
    } else {
        (
            c.vertices[i.saturating_sub(SPAN)],
            c.vertices[(i + SPAN).min(m - 1)],
        )
    };
    let p = pos(mesh, c.vertices[i]);
    let (din, dout) = (
        (p - pos(mesh, prev)).normalize_or_zero(),
        (pos(mesh, next) - p).normalize_or_zero(),
    );
    if din == Vec3::ZERO || dout == Vec3::ZERO {
        1.0
    } else {
        din.dot(dout)
    }
}

/// Splits `c` at the sharpest vertex of every run of vertices turning more than the limit.
fn break_curve(mesh: &Mesh, c: &Polyline, cos_limit: f32) -> Vec<Polyline> {
    let m = c.vertices.len();
    if m < 3 {
        return vec![c.clone()];
    }
    let cos: Vec<f32> = (0..m).map(|i| turn_cos(mesh, c, i)).collect();
    let sharp = |i: usize| {
        let interior = c.closed || (i >= 2 && i + 2 < m);
        interior && cos[i] < cos_limit
    };
    // Walk runs of sharp vertices; for a loop start just after a non-sharp vertex so no run
    // wraps around the start.
    let start = if c.closed {
        match (0..m).find(|&i| !sharp(i)) {
            Some(i) => i + 1,
            None => return vec![c.clone()], // turns everywhere: a tiny loop, keep it
        }
    } else {
        0
    };
    let mut breaks: Vec<usize> = Vec::new();
    let mut k = 0;
    while k < m {
        let i = (start + k) % m;
        if !sharp(i) {
            k += 1;
            continue;
        }
        let mut best = i;
        while k < m && sharp((start + k) % m) {
            let j = (start + k) % m;
            if cos[j] < cos[best] {
                best = j;
            }
            k += 1;
        }
        breaks.push(best);
    }
    breaks.sort_unstable();
    let piece = |from: usize, to: usize| -> Polyline {
        // Indices from..=to, wrapping for loops.
        let len = (to + m - from) % m + 1;
        Polyline {
            vertices: (0..len).map(|k| c.vertices[(from + k) % m]).collect(),
            closed: false,
        }
    };
    if c.closed {
        if breaks.len() < 2 {
            return vec![c.clone()];
        }
        (0..breaks.len())
            .map(|k| piece(breaks[k], breaks[(k + 1) % breaks.len()]))
            .collect()
    } else {
        let mut cuts = vec![0];
        cuts.extend(&breaks);
        cuts.push(m - 1);
        cuts.windows(2).map(|w| piece(w[0], w[1])).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives::grid;

    fn open(v: Vec<u32>) -> Polyline {
        Polyline {
            vertices: v,
            closed: false,
        }
    }

    #[test]
    fn pieces_keep_the_directions_of_the_fixed_curves_they_hold() {
        // A 21×21 grid (vertex = 21·y + x). Row 10 drawn as two fixed halves: outward from
        // its middle (they stay apart) or both left to right (joined, one direction); an L of
        // row 3 and column 15 fixed (broken at the corner, both pieces along it); a free row.
        let g = grid(21, 0.05);
        let row = |y: u32, xs: Vec<u32>| open(xs.into_iter().map(|x| 21 * y + x).collect());
        let out =
            |curves: &[Polyline], fixed: &[bool]| group_and_break(&g, curves, fixed, 0.02, 60.0);

        let outward = [
            row(10, (10..=18).collect()),
            row(10, (2..=10).rev().collect()),
        ];
        let r = out(&outward, &[true, true]);
        assert_eq!(r.len(), 2, "outward spokes stay apart");
        assert!(r.iter().all(|(_, s)| *s == Some(1)));
        // Free, the same two are one line.
        assert_eq!(out(&outward, &[false, false]).len(), 1);

        let along = [row(10, (10..=18).collect()), row(10, (2..=10).collect())];
        let r = out(&along, &[true, false]);
        assert_eq!(r.len(), 1, "a fixed and a free half join");
        let (c, s) = &r[0];
        let first = c.vertices.iter().position(|&v| v == 21 * 10 + 11).unwrap();
        let second = c.vertices.iter().position(|&v| v == 21 * 10 + 12).unwrap();
        // The fixed half runs left to right: the joined curve's sign must say so.
        assert_eq!(*s == Some(1), first < second, "{c:?} {s:?}");
        assert!(s.is_some());

        let mut l = row(3, (2..=15).collect());
        l.vertices.extend((4..=17).map(|y| 21 * y + 15));
        let r = out(&[l, row(18, (2..=18).collect())], &[true]);
        assert_eq!(r.len(), 3, "{r:?}");
        assert_eq!(r[0].1, Some(1));
        assert_eq!(r[1].1, Some(1));
        assert_eq!(r[2].1, None, "the free row");
    }
}
