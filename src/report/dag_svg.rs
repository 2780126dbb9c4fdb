//! A run's DAG drawn as SVG for the HTML report: input files and nodes in rows by their depth
//! (the longest path from an input), top to bottom, so a pipeline of any length fits the
//! page's width; each box says what the run table says (stage, status, seconds, size) and the
//! node's key and content hash; edges are curves from an input's bottom to its reader's top.

use super::escape;

/// One box of the drawing.
pub struct Box {
    /// The first line, bold: the node's name or the input file's name.
    pub title: String,
    /// The following lines.
    pub lines: Vec<String>,
    /// The fill: "ran", "cached", "file" or "missing" (a CSS class of the page).
    pub class: &'static str,
    /// The tooltip (the full key and hash).
    pub tooltip: String,
}

const WIDTH: f32 = 230.0;
const LINE: f32 = 14.0;
const GAP_X: f32 = 24.0;
const GAP_Y: f32 = 40.0;
const PAD: f32 = 8.0;

/// The SVG of `boxes` with `edges` (from, to) between them; `edges` must not form a cycle.
pub fn dag_svg(boxes: &[Box], edges: &[(usize, usize)]) -> String {
    let n = boxes.len();
    // Depth: the longest path from a source (edges may come in any order: relax n times).
    let mut depth = vec![0usize; n];
    for _ in 0..n {
        let mut changed = false;
        for &(a, b) in edges {
            if depth[b] < depth[a] + 1 {
                depth[b] = depth[a] + 1;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    let height = |b: &Box| PAD * 2.0 + LINE * (1 + b.lines.len()) as f32;
    let rows = depth.iter().copied().max().map_or(0, |d| d + 1);
    let mut row_height = vec![0.0f32; rows];
    let mut row_count = vec![0usize; rows];
    for i in 0..n {
        row_height[depth[i]] = row_height[depth[i]].max(height(&boxes[i]));
    }
    let mut row_top = vec![PAD; rows];
    for r in 1..rows {
        row_top[r] = row_top[r - 1] + row_height[r - 1] + GAP_Y;
    }
    let mut pos = vec![(0.0f32, 0.0f32); n];
    for i in 0..n {
        let d = depth[i];
        pos[i] = (PAD + row_count[d] as f32 * (WIDTH + GAP_X), row_top[d]);
        row_count[d] += 1;
    }
    let widest = row_count.iter().copied().max().unwrap_or(0);
    let total_w = PAD * 2.0 + widest as f32 * (WIDTH + GAP_X) - GAP_X;
    let total_h = rows
        .checked_sub(1)
        .map_or(PAD, |r| row_top[r] + row_height[r] + PAD);
    let mut s = format!(
        "<svg class=\"dag\" xmlns=\"http://www.w3.org/2000/svg\" width=\"{total_w:.0}\" \
         height=\"{total_h:.0}\" viewBox=\"0 0 {total_w:.0} {total_h:.0}\">\n"
    );
    for &(a, b) in edges {
        let (ax, ay) = (pos[a].0 + WIDTH / 2.0, pos[a].1 + height(&boxes[a]));
        let (bx, by) = (pos[b].0 + WIDTH / 2.0, pos[b].1);
        let mid = (ay + by) / 2.0;
        s += &format!(
            "<path class=\"edge\" d=\"M{ax:.1},{ay:.1} C{ax:.1},{mid:.1} {bx:.1},{mid:.1} \
             {bx:.1},{by:.1}\"/>\n"
        );
    }
    for (b, &(x, y)) in boxes.iter().zip(&pos) {
        s += &format!(
            "<g class=\"node {}\"><title>{}</title><rect x=\"{x:.1}\" y=\"{y:.1}\" \
             width=\"{WIDTH}\" height=\"{:.1}\" rx=\"6\"/>",
            b.class,
            escape(&b.tooltip),
            height(b)
        );
        s += &format!(
            "<text x=\"{:.1}\" y=\"{:.1}\" class=\"title\">{}</text>",
            x + PAD,
            y + PAD + LINE - 3.0,
            escape(&b.title)
        );
        for (k, line) in b.lines.iter().enumerate() {
            s += &format!(
                "<text x=\"{:.1}\" y=\"{:.1}\">{}</text>",
                x + PAD,
                y + PAD + LINE * (k + 2) as f32 - 3.0,
                escape(line)
            );
        }
        s += "</g>\n";
    }
    s += "</svg>";
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b(t: &str) -> Box {
        Box {
            title: t.into(),
            lines: vec!["x".into()],
            class: "ran",
            tooltip: "<key & hash>".into(),
        }
    }

    /// The y of each box's rect, in order.
    fn ys(svg: &str) -> Vec<f32> {
        svg.split("<rect x=\"")
            .skip(1)
            .map(|r| {
                r.split("y=\"")
                    .nth(1)
                    .unwrap()
                    .split('"')
                    .next()
                    .unwrap()
                    .parse()
                    .unwrap()
            })
            .collect()
    }

    #[test]
    fn a_node_sits_below_every_input_it_reads_and_text_is_escaped() {
        // 0 → 2 → 3, 1 → 3, edges out of order.
        let svg = dag_svg(&[b("a"), b("b"), b("c"), b("d")], &[(2, 3), (0, 2), (1, 3)]);
        let y = ys(&svg);
        assert!(y[2] > y[0] && y[3] > y[2] && y[3] > y[1], "{y:?}");
        assert_eq!(y[0], y[1]);
        assert_eq!(svg.matches("<path class=\"edge\"").count(), 3);
        assert!(svg.contains("&lt;key &amp; hash&gt;"));
        assert!(!svg.contains("<key"));
    }
}
