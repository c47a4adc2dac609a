//! Counts before/after normalization, in the shape of the spec's Tables 7.1 and 7.4.

use serde::Serialize;

/// Source-side counts (Table 7.4, left): polygons, rings and points (the repeated closing point of
/// a ring not counted).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct SourceCounts {
    pub polygons: usize,
    pub rings: usize,
    pub points: usize,
}

/// One column of Table 7.1.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageCounts {
    /// `points` (the soup: distinct nodes/edges, input polygons), `planar`, `parallel`, `coplanar`,
    /// `orthogonal` (after parameter sharing; equals `coplanar` when sharing is off).
    pub stage: String,
    pub nodes: usize,
    pub edges: usize,
    pub faces: usize,
    pub planes: usize,
    pub normals: usize,
    pub parameters: usize,
    /// Stored unknowns relative to 3 × nodes coordinates (the last row of Table 7.1), in percent.
    pub unknowns_percent: f64,
}

impl StageCounts {
    pub fn new(
        stage: &str,
        nodes: usize,
        edges: usize,
        faces: usize,
        planes: usize,
        normals: usize,
        parameters: usize,
    ) -> Self {
        let unknowns = if planes == 0 { 3 * nodes } else { planes + parameters };
        let pct = if nodes == 0 { 0.0 } else { 100.0 * unknowns as f64 / (3 * nodes) as f64 };
        StageCounts { stage: stage.into(), nodes, edges, faces, planes, normals, parameters, unknowns_percent: pct }
    }
}

/// All counts of one normalized object.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Counts {
    pub name: String,
    pub source: SourceCounts,
    pub stages: Vec<StageCounts>,
    pub half_edges: usize,
    /// Largest distance of a node recomputed from its planes to its source point (m).
    pub max_node_shift: f64,
}

impl Counts {
    /// The final stage.
    pub fn last(&self) -> &StageCounts {
        self.stages.last().expect("stages")
    }

    /// Sums per stage over several objects (for a whole file).
    pub fn sum<'a>(name: &str, all: impl IntoIterator<Item = &'a Counts>) -> Counts {
        let mut out: Option<Counts> = None;
        for c in all {
            match out.as_mut() {
                None => {
                    let mut c = c.clone();
                    c.name = name.into();
                    out = Some(c);
                }
                Some(o) => {
                    o.source.polygons += c.source.polygons;
                    o.source.rings += c.source.rings;
                    o.source.points += c.source.points;
                    o.half_edges += c.half_edges;
                    o.max_node_shift = o.max_node_shift.max(c.max_node_shift);
                    for (a, b) in o.stages.iter_mut().zip(&c.stages) {
                        *a = StageCounts::new(
                            &a.stage,
                            a.nodes + b.nodes,
                            a.edges + b.edges,
                            a.faces + b.faces,
                            a.planes + b.planes,
                            a.normals + b.normals,
                            a.parameters + b.parameters,
                        );
                    }
                }
            }
        }
        out.unwrap_or(Counts {
            name: name.into(),
            source: SourceCounts::default(),
            stages: Vec::new(),
            half_edges: 0,
            max_node_shift: 0.0,
        })
    }

    /// The table as text, one row per quantity and one column per stage (like Table 7.1).
    pub fn table(&self) -> String {
        let mut s = format!(
            "{}: {} polygons, {} rings, {} points → {} faces, {} half-edges, {} edges, {} nodes (max node shift {:.2e} m)\n",
            self.name,
            self.source.polygons,
            self.source.rings,
            self.source.points,
            self.stages.last().map_or(0, |x| x.faces),
            self.half_edges,
            self.stages.last().map_or(0, |x| x.edges),
            self.stages.last().map_or(0, |x| x.nodes),
            self.max_node_shift
        );
        s.push_str(&format!("{:<12}", ""));
        for st in &self.stages {
            s.push_str(&format!("{:>12}", st.stage));
        }
        s.push('\n');
        let rows: [(&str, fn(&StageCounts) -> String); 7] = [
            ("nodes", |x| x.nodes.to_string()),
            ("edges", |x| x.edges.to_string()),
            ("faces", |x| x.faces.to_string()),
            ("planes", |x| if x.planes == 0 { "-".into() } else { x.planes.to_string() }),
            ("normals", |x| if x.normals == 0 { "-".into() } else { x.normals.to_string() }),
            ("parameters", |x| if x.parameters == 0 { "-".into() } else { x.parameters.to_string() }),
            ("unknowns", |x| format!("{:.0} %", x.unknowns_percent)),
        ];
        for (name, f) in rows {
            s.push_str(&format!("{name:<12}"));
            for st in &self.stages {
                s.push_str(&format!("{:>12}", f(st)));
            }
            s.push('\n');
        }
        s
    }
}
