//! The thesis' flat R-tree encoding (spec §6.2, Alg. 5): Nearest-X bulk loading and one `int8`
//! page (⌊x_min⌋, ⌊y_min⌋, ⌈x_max⌉, ⌈y_max⌉, c0, c1, c2, i_obj) per node, searched breadth-first
//! with a fixed-length queue. Kept as the reference encoding of Tables 5.2/6.3; the evaluation
//! kernels use a bucket grid instead (see `eval.rs`, A15).
//!
//! Nearest-X: objects are sorted by their box centre and packed `fanout` at a time; groups of one
//! are not wrapped (a single object is its own leaf page); pages are numbered breadth-first from
//! the root. The sort key the thesis uses is "x-y order"; Table 6.3 is reproduced by ascending
//! (y, x), Table 5.2 by descending (y, x). No single order yields both printed tables, so the
//! order is a parameter ([`Order`]).

/// Sort order of box centres for Nearest-X packing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Order {
    /// Ascending y, then ascending x (Table 6.3).
    YThenX,
    /// Descending y, then descending x (Table 5.2).
    YThenXDescending,
}

/// A page with its exact box (the int8 form rounds it outward).
#[derive(Debug, Clone, PartialEq)]
pub struct Page {
    pub bbox: [f64; 4],
    pub children: Vec<usize>,
    pub object: Option<usize>,
}

impl Page {
    /// The thesis' `int8` encoding (fan-out ≤ 3).
    pub fn int8(&self) -> [i32; 8] {
        let mut c = [-1i32; 3];
        for (k, &ch) in self.children.iter().take(3).enumerate() {
            c[k] = ch as i32;
        }
        [
            self.bbox[0].floor() as i32,
            self.bbox[1].floor() as i32,
            self.bbox[2].ceil() as i32,
            self.bbox[3].ceil() as i32,
            c[0],
            c[1],
            c[2],
            self.object.map(|o| o as i32).unwrap_or(-1),
        ]
    }
}

enum Node {
    Leaf(usize, [f64; 4]),
    Inner(Vec<Node>, [f64; 4]),
}

fn bbox(n: &Node) -> [f64; 4] {
    match n {
        Node::Leaf(_, b) | Node::Inner(_, b) => *b,
    }
}

/// Nearest-X bulk load of boxes (x_min, y_min, x_max, y_max); returns pages, root first.
pub fn nearest_x(boxes: &[[f64; 4]], fanout: usize, order: Order) -> Vec<Page> {
    assert!(fanout >= 2 && !boxes.is_empty());
    let mut idx: Vec<usize> = (0..boxes.len()).collect();
    let centre = |b: &[f64; 4]| ((b[1] + b[3]) * 0.5, (b[0] + b[2]) * 0.5);
    idx.sort_by(|&a, &b| {
        let (ya, xa) = centre(&boxes[a]);
        let (yb, xb) = centre(&boxes[b]);
        let o = ya.partial_cmp(&yb).unwrap().then(xa.partial_cmp(&xb).unwrap());
        if order == Order::YThenX {
            o
        } else {
            o.reverse()
        }
    });
    let mut level: Vec<Node> = idx.into_iter().map(|i| Node::Leaf(i, boxes[i])).collect();
    while level.len() > 1 {
        let mut next = Vec::new();
        let mut it = level.into_iter().peekable();
        while it.peek().is_some() {
            let group: Vec<Node> = it.by_ref().take(fanout).collect();
            if group.len() == 1 {
                next.extend(group);
            } else {
                let b = group.iter().map(bbox).fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |a, b| {
                    [a[0].min(b[0]), a[1].min(b[1]), a[2].max(b[2]), a[3].max(b[3])]
                });
                next.push(Node::Inner(group, b));
            }
        }
        level = next;
    }
    // breadth-first numbering
    let mut pages = Vec::new();
    let mut queue = std::collections::VecDeque::new();
    queue.push_back(level.pop().unwrap());
    while let Some(n) = queue.pop_front() {
        match n {
            Node::Leaf(o, b) => pages.push(Page { bbox: b, children: vec![], object: Some(o) }),
            Node::Inner(kids, b) => {
                let first = pages.len() + queue.len() + 1;
                let children = (first..first + kids.len()).collect();
                pages.push(Page { bbox: b, children, object: None });
                queue.extend(kids);
            }
        }
    }
    pages
}

/// Alg. 5: breadth-first point search with a fixed-length queue; returns candidate objects.
pub fn search(pages: &[[i32; 8]], x: f64, y: f64) -> Vec<usize> {
    const QLEN: usize = 64;
    let mut q = [0usize; QLEN];
    let (mut head, mut tail) = (0usize, 1usize);
    let mut out = Vec::new();
    while head < tail {
        let p = pages[q[head % QLEN]];
        head += 1;
        let inside = p[0] as f64 <= x && x <= p[2] as f64 && p[1] as f64 <= y && y <= p[3] as f64;
        if !inside {
            continue;
        }
        if p[7] >= 0 {
            out.push(p[7] as usize);
        } else {
            for &c in &p[4..7] {
                if c >= 0 && tail - head < QLEN {
                    q[tail % QLEN] = c as usize;
                    tail += 1;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tables 6.2/6.3: three unit boxes around (0.5,0.5), (1.5,0.5), (0.5,1.5), fan-out 3.
    #[test]
    fn table_6_3() {
        let boxes = [[0.0, 0.0, 1.0, 1.0], [1.0, 0.0, 2.0, 1.0], [0.0, 1.0, 1.0, 2.0]];
        let pages: Vec<[i32; 8]> = nearest_x(&boxes, 3, Order::YThenX).iter().map(Page::int8).collect();
        assert_eq!(
            pages,
            vec![
                [0, 0, 2, 2, 1, 2, 3, -1],
                [0, 0, 1, 1, -1, -1, -1, 0],
                [1, 0, 2, 1, -1, -1, -1, 1],
                [0, 1, 1, 2, -1, -1, -1, 2],
            ]
        );
        assert_eq!(search(&pages, 1.5, 0.5), vec![1]);
        assert_eq!(search(&pages, 1.0, 1.0), vec![0, 1, 2]);
        assert!(search(&pages, 2.5, 0.5).is_empty());
    }

    /// Tables 5.1–5.3 with two entries per page. A20: the Z2 leaf box is (1,1)–(2,2), the thesis
    /// prints (1,1)–(2,1).
    #[test]
    fn table_5_2() {
        // cells Z1, Z2, Z3 (object ids 0, 1, 2)
        let boxes = [[0.0, 1.0, 1.0, 2.0], [1.0, 1.0, 2.0, 2.0], [0.0, 0.0, 2.0, 1.0]];
        let pages = nearest_x(&boxes, 2, Order::YThenXDescending);
        let rows: Vec<([f64; 4], Vec<usize>, Option<usize>)> =
            pages.into_iter().map(|p| (p.bbox, p.children, p.object)).collect();
        assert_eq!(
            rows,
            vec![
                ([0.0, 0.0, 2.0, 2.0], vec![1, 2], None),
                ([0.0, 1.0, 2.0, 2.0], vec![3, 4], None),
                ([0.0, 0.0, 2.0, 1.0], vec![], Some(2)),
                ([1.0, 1.0, 2.0, 2.0], vec![], Some(1)),
                ([0.0, 1.0, 1.0, 2.0], vec![], Some(0)),
            ]
        );
    }
}
