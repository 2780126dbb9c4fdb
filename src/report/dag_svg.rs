//! A run's DAG drawn as SVG for the HTML report: input files and nodes in columns by their
//! depth (the longest path from an input), each box saying what the run table says (stage,
//! status, seconds, size) and the node's key and content hash, edges as curves from an
//! input's right side to its reader's left side.

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
const GAP_X: f32 = 60.0;
const GAP_Y: f32 = 16.0;
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
    let columns = depth.iter().copied().max().map_or(0, |d| d + 1);
    let mut pos = vec![(0.0f32, 0.0f32); n];
    let mut column_bottom = vec![PAD; columns];
    for i in 0..n {
        let d = depth[i];
        pos[i] = (PAD + d as f32 * (WIDTH + GAP_X), column_bottom[d]);
        column_bottom[d] += height(&boxes[i]) + GAP_Y;
    }
    let total_w = PAD * 2.0 + columns as f32 * (WIDTH + GAP_X) - GAP_X;
    let total_h = column_bottom.iter().copied().fold(PAD, f32::max);
    let mut s = format!(
        "<svg class=\"dag\" xmlns=\"http://www.w3.org/2000/svg\" width=\"{total_w:.0}\" \
         height=\"{total_h:.0}\" viewBox=\"0 0 {total_w:.0} {total_h:.0}\">\n"
    );
    for &(a, b) in edges {
        let (ax, ay) = (pos[a].0 + WIDTH, pos[a].1 + height(&boxes[a]) / 2.0);
        let (bx, by) = (pos[b].0, pos[b].1 + height(&boxes[b]) / 2.0);
        let mid = (ax + bx) / 2.0;
        s += &format!(
            "<path class=\"edge\" d=\"M{ax:.1},{ay:.1} C{mid:.1},{ay:.1} {mid:.1},{by:.1} \
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

    /// The x of each box's rect, in order.
    fn xs(svg: &str) -> Vec<f32> {
        svg.split("<rect x=\"")
            .skip(1)
            .map(|r| r.split('"').next().unwrap().parse().unwrap())
            .collect()
    }

    #[test]
    fn a_node_sits_right_of_every_input_it_reads_and_text_is_escaped() {
        // 0 → 2 → 3, 1 → 3, edges out of order.
        let svg = dag_svg(&[b("a"), b("b"), b("c"), b("d")], &[(2, 3), (0, 2), (1, 3)]);
        let x = xs(&svg);
        assert!(x[2] > x[0] && x[3] > x[2] && x[3] > x[1], "{x:?}");
        assert_eq!(x[0], x[1]);
        assert_eq!(svg.matches("<path class=\"edge\"").count(), 3);
        assert!(svg.contains("&lt;key &amp; hash&gt;"));
        assert!(!svg.contains("<key"));
    }
}
