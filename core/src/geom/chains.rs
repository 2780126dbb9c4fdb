//! Chains of an undirected graph of low degree: the polylines that crease edges, crest-line
//! segments and thinned texel lines form. One tracing for all of them, so they agree on what
//! a junction, an end and a loop are.

use std::collections::BTreeMap;

/// Paths of an undirected graph from every node whose degree is not two to the next such
/// node (in node order, each node's edges in the order listed), then the loops that remain,
/// each without repeating its first node (`true`: closed). Every edge is used once.
pub fn trace_chains(graph: &BTreeMap<u32, Vec<u32>>) -> Vec<(Vec<u32>, bool)> {
    let key = |a: u32, b: u32| (a.min(b), a.max(b));
    let mut used: std::collections::BTreeSet<(u32, u32)> = Default::default();
    let walk = |start: u32, first: u32, used: &mut std::collections::BTreeSet<(u32, u32)>| {
        let mut line = vec![start, first];
        used.insert(key(start, first));
        let (mut prev, mut cur) = (start, first);
        while graph[&cur].len() == 2 {
            let Some(next) = graph[&cur].iter().copied().find(|&n| n != prev) else {
                break;
            };
            if !used.insert(key(cur, next)) {
                break;
            }
            line.push(next);
            prev = cur;
            cur = next;
        }
        line
    };
    let mut out = Vec::new();
    for (&v, nbrs) in graph {
        if nbrs.len() == 2 {
            continue;
        }
        for &n in nbrs {
            if !used.contains(&key(v, n)) {
                out.push((walk(v, n, &mut used), false));
            }
        }
    }
    for (&v, nbrs) in graph {
        if let Some(&n) = nbrs.iter().find(|&&n| !used.contains(&key(v, n))) {
            let mut l = walk(v, n, &mut used);
            if l.last() == Some(&v) {
                l.pop();
            }
            out.push((l, true));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph(edges: &[(u32, u32)]) -> BTreeMap<u32, Vec<u32>> {
        let mut g: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
        for &(a, b) in edges {
            g.entry(a).or_default().push(b);
            g.entry(b).or_default().push(a);
        }
        g
    }

    #[test]
    fn paths_run_between_ends_and_junctions_and_loops_come_last() {
        // A "T" (0-1-2 with 1-3) and a separate triangle loop 10-11-12.
        let g = graph(&[(0, 1), (1, 2), (1, 3), (10, 11), (11, 12), (12, 10)]);
        let chains = trace_chains(&g);
        assert_eq!(
            chains,
            vec![
                (vec![0, 1], false),
                (vec![1, 2], false),
                (vec![1, 3], false),
                (vec![10, 11, 12], true),
            ]
        );
        // A plain path is one chain, whichever way its edges were listed.
        let g = graph(&[(5, 6), (7, 6), (7, 8)]);
        assert_eq!(trace_chains(&g), vec![(vec![5, 6, 7, 8], false)]);
    }
}
