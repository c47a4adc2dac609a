//! Parse throughput against the ceiling of a bare quick-xml tokenizer pass over the same bytes.
//!
//! `citygml_bench tokenize FILE...`  only quick-xml events (the ceiling, nothing decoded)
//! `citygml_bench numbers FILE...`   the ceiling + fast-float2 parsing of every text token (the
//!                                   floor any reader that decodes coordinates pays)
//! `citygml_bench numbers-std FILE...` the same with std `str::parse::<f64>`
//! `citygml_bench parse FILE...`     `citygml_io::parse` (whole model, XLinks resolved; the model
//!                                   is dropped after the clock stops)
//! `citygml_bench parse+drop FILE...` the same with the model's drop timed too
//! `citygml_bench stream FILE...`    `ObjectStream`, one object at a time, dropped after counting
//! `citygml_bench counts FILE...`    buildings / parts / solids / polygons / rings / points (debug)
//!
//! Each mode reads the files into memory first and times only the pass itself (best of
//! `REPEAT`, default 5), printing `MODE MB/s bytes seconds`. The clock is the CPU time of the
//! benchmark thread (`CLOCK_THREAD_CPUTIME_ID`), not wall time: on a machine shared with other
//! builds a pass of several milliseconds is almost always descheduled part of the way, which
//! would penalise the longer passes (parse) against the short ones (tokenize). `CLOCK=wall`
//! measures wall time instead.

use std::time::Instant;

/// Seconds of CPU time used by this thread (or wall time with `CLOCK=wall`).
fn now(wall: bool, t0: Instant) -> f64 {
    if wall {
        return t0.elapsed().as_secs_f64();
    }
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: plain syscall wrapper writing into a local timespec.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

use citygml_io::{GeometryKind, ObjectStream};
use quick_xml::events::Event;
use quick_xml::Reader;

fn tokenize(src: &[u8]) -> usize {
    let mut r = Reader::from_reader(src);
    r.config_mut().trim_text(false);
    let mut n = 0usize;
    loop {
        match r.read_event() {
            Ok(Event::Eof) => break,
            Ok(_) => n += 1,
            Err(e) => panic!("{e}"),
        }
    }
    n
}

/// The ceiling plus the one thing every reader must do on top: turn each coordinate into a
/// number. Only the text of the coordinate elements (`posList`, `pos`, `coordinates`,
/// `lowerCorner`, `upperCorner`) is decoded, token by token in place with `fast-float2` (the
/// parser `citygml_io` uses), so this is the floor of any reader that decodes the coordinates
/// it must give (envelopes and geometry need them all); `numbers-std` uses `str::parse::<f64>`.
fn tokenize_numbers_fast(src: &[u8]) -> usize {
    let mut r = Reader::from_reader(src);
    r.config_mut().trim_text(false);
    let mut n = 0usize;
    let mut acc = 0.0f64;
    let mut coords = false;
    loop {
        match r.read_event() {
            Ok(Event::Eof) => break,
            Ok(Event::Start(e)) => {
                coords = matches!(
                    e.local_name().as_ref(),
                    b"posList" | b"pos" | b"coordinates" | b"lowerCorner" | b"upperCorner"
                );
                n += 1;
            }
            Ok(Event::Text(t)) if coords => {
                let b: &[u8] = &t;
                let mut i = 0;
                while i < b.len() {
                    if b[i].is_ascii_whitespace() {
                        i += 1;
                        continue;
                    }
                    match fast_float2::parse_partial::<f64, _>(&b[i..]) {
                        Ok((x, used)) => {
                            acc += x;
                            n += 1;
                            i += used.max(1);
                        }
                        Err(_) => i += 1,
                    }
                }
            }
            Ok(_) => {
                coords = false;
                n += 1
            }
            Err(e) => panic!("{e}"),
        }
    }
    std::hint::black_box(acc);
    n
}

fn tokenize_numbers(src: &[u8]) -> usize {
    let mut r = Reader::from_reader(src);
    r.config_mut().trim_text(false);
    let mut n = 0usize;
    let mut acc = 0.0f64;
    loop {
        match r.read_event() {
            Ok(Event::Eof) => break,
            Ok(Event::Text(t)) => {
                for tok in t.split(|b| b.is_ascii_whitespace()).filter(|t| !t.is_empty()) {
                    if let Some(x) = std::str::from_utf8(tok).ok().and_then(|s| s.parse::<f64>().ok()) {
                        acc += x;
                        n += 1;
                    }
                }
            }
            Ok(_) => n += 1,
            Err(e) => panic!("{e}"),
        }
    }
    std::hint::black_box(acc);
    n
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mode = args.get(1).map(String::as_str).unwrap_or("parse");
    let repeat: usize = std::env::var("REPEAT").ok().and_then(|v| v.parse().ok()).unwrap_or(5);
    let files: Vec<Vec<u8>> = args[2..].iter().map(|p| std::fs::read(p).expect("read")).collect();
    let bytes: usize = files.iter().map(|f| f.len()).sum();
    if mode == "counts" {
        for (p, f) in args[2..].iter().zip(&files) {
            match citygml_io::parse(f) {
                Ok(m) => {
                    let objs = m.all_objects();
                    let b = objs.iter().filter(|o| o.kind == "Building").count();
                    let bp = objs.iter().filter(|o| o.kind == "BuildingPart").count();
                    let mut solids = 0;
                    let mut polys = 0;
                    let mut rings = 0;
                    let mut pts = 0;
                    for o in &objs {
                        for g in &o.geometries {
                            solids += match &g.kind {
                                GeometryKind::Solid { .. } => 1,
                                GeometryKind::Solids(v) => v.len(),
                                _ => 0,
                            };
                            if g.gml_type == "TriangulatedSurface" || g.gml_type == "Tin" {
                                continue;
                            }
                            for p in g.polygons() {
                                if p.via_xlink.is_none() {
                                    polys += 1;
                                    rings += 1 + p.interiors.len();
                                    pts += p.exterior.points.len()
                                        + p.interiors.iter().map(|r| r.points.len()).sum::<usize>();
                                }
                            }
                        }
                    }
                    let xl: usize = m
                        .all_objects()
                        .iter()
                        .flat_map(|o| o.geometries.iter())
                        .flat_map(|g| g.polygons())
                        .filter(|p| p.via_xlink.is_some())
                        .count();
                    println!(
                        "{p} {} {b} {bp} {solids} {polys} {xl} {rings} {pts} unresolved={}",
                        m.version.as_str(),
                        m.unresolved_xlinks.len()
                    );
                }
                Err(e) => println!("{p} ERROR {e}"),
            }
        }
        return;
    }
    let wall = std::env::var("CLOCK").is_ok_and(|v| v == "wall");
    let t0 = Instant::now();
    let mut best = f64::INFINITY;
    for _ in 0..repeat {
        let t = now(wall, t0);
        let mut sink = 0usize;
        // `parse`: the models are dropped after the clock stops (building them is the parse;
        // freeing them is the caller's business, and the tokenizer builds nothing to free).
        let mut models = Vec::new();
        for f in &files {
            sink += match mode {
                "tokenize" => tokenize(f),
                "none" => f.len(), // baseline for instruction counts (valgrind): start-up and file reading
                "numbers" => tokenize_numbers_fast(f),
                "numbers-std" => tokenize_numbers(f),
                "parse" => {
                    models.push(citygml_io::parse(f).expect("parse"));
                    models.last().unwrap().objects.len()
                }
                "parse+drop" => citygml_io::parse(f).expect("parse").objects.len(),
                "stream" => ObjectStream::new(f).expect("parse").map(|o| o.expect("parse").children.len() + 1).sum(),
                _ => panic!("unknown mode {mode}"),
            };
        }
        std::hint::black_box(sink);
        best = best.min(now(wall, t0) - t);
        drop(models);
    }
    println!("{mode} {:.1} MB/s {bytes} bytes {:.4} s", bytes as f64 / best / 1e6, best);
}
