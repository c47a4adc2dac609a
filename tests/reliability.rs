//! End-to-end tests of the reliability findings of issue 13 that hostile input produced: every
//! input is built here, and each case asserts the exit code, a one-line message, no panic or
//! abort, and that an output file already at `-o` is left as it was.
//!
//! - node merging is linear: 1,500 identical buildings at one place convert back in seconds
//!   (pairwise relabelling took 241 s), and the result is the input (a box converts to itself);
//! - allocations are not sized by headers: a LAS header claiming 10¹² points, a LAZ chunk table
//!   of 4·10⁹ entries, `/dev/zero` and an endless point stream end with exit 3 and a message;
//! - inputs read whole stop at a byte budget (`info /dev/zero`, an endless stdin, a big file);
//! - errors quote at most ~200 bytes of the input;
//! - `info` with stdout closed fails, `info -` on empty stdin says there is no input;
//! - temporaries of dead processes are removed by the next run in the directory;
//! - `validate` with XSD refuses an element with 100,000 attributes in time;
//! - `info` and `validate --no-xsd` of a 1 GiB CityGML tile stay under 200 MiB; `rasterize`
//!   (Gauss) memory does not grow with the number of points.

mod common;

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Asserts exit `code`, no panic, one line on stderr containing every needle; returns stderr.
fn fails(o: &Output, code: i32, needles: &[&str]) -> String {
    let e = stderr(o);
    assert_eq!(common::code(o), code, "{e}");
    assert!(!e.contains("panicked") && !e.contains("RUST_BACKTRACE"), "{e}");
    assert_eq!(e.trim_end().lines().count(), 1, "one line expected: {e}");
    for n in needles {
        assert!(e.contains(n), "expected {n:?} in {e:?}");
    }
    e
}

/// An existing output that a failing command must leave as it was.
fn old_output(path: &Path) -> Vec<u8> {
    let old = b"an output of an earlier run\n".to_vec();
    std::fs::write(path, &old).unwrap();
    old
}

// ---------------------------------------------------------------------------------------------
// 1. node merging

/// One LoD2 box building (10 × 8 × 6 m, six polygons with ids, a solid referencing them) at
/// the same place for every `i`; only the ids differ.
fn box_building(i: usize) -> String {
    let (x0, y0, z0, x1, y1, z1) = (324100.0, 5729100.0, 50.0, 324110.0, 5729108.0, 56.0);
    let ring = |pts: &[[f64; 3]]| {
        let mut v: Vec<String> = pts.iter().map(|p| format!("{:.3} {:.3} {:.3}", p[0], p[1], p[2])).collect();
        v.push(v[0].clone());
        v.join(" ")
    };
    let c = |x: f64, y: f64, z: f64| [x, y, z];
    // outward-facing rings (counter-clockwise seen from outside)
    let faces: [(&str, Vec<[f64; 3]>); 6] = [
        ("GroundSurface", vec![c(x0, y0, z0), c(x0, y1, z0), c(x1, y1, z0), c(x1, y0, z0)]),
        ("RoofSurface", vec![c(x0, y0, z1), c(x1, y0, z1), c(x1, y1, z1), c(x0, y1, z1)]),
        ("WallSurface", vec![c(x0, y0, z0), c(x1, y0, z0), c(x1, y0, z1), c(x0, y0, z1)]),
        ("WallSurface", vec![c(x1, y0, z0), c(x1, y1, z0), c(x1, y1, z1), c(x1, y0, z1)]),
        ("WallSurface", vec![c(x1, y1, z0), c(x0, y1, z0), c(x0, y1, z1), c(x1, y1, z1)]),
        ("WallSurface", vec![c(x0, y1, z0), c(x0, y0, z0), c(x0, y0, z1), c(x0, y1, z1)]),
    ];
    let mut solid = String::new();
    let mut bounded = String::new();
    for (k, (kind, pts)) in faces.iter().enumerate() {
        let id = format!("B{i}_P{k}");
        solid.push_str(&format!("<gml:surfaceMember xlink:href=\"#{id}\"/>\n"));
        bounded.push_str(&format!(
            "<bldg:boundedBy><bldg:{kind} gml:id=\"B{i}_S{k}\"><bldg:lod2MultiSurface><gml:MultiSurface><gml:surfaceMember>\
             <gml:Polygon gml:id=\"{id}\"><gml:exterior><gml:LinearRing><gml:posList srsDimension=\"3\">{}</gml:posList>\
             </gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember></gml:MultiSurface></bldg:lod2MultiSurface>\
             </bldg:{kind}></bldg:boundedBy>\n",
            ring(pts)
        ));
    }
    format!(
        "<core:cityObjectMember><bldg:Building gml:id=\"B{i}\"><bldg:lod2Solid><gml:Solid><gml:exterior><gml:CompositeSurface>\n\
         {solid}</gml:CompositeSurface></gml:exterior></gml:Solid></bldg:lod2Solid>\n{bounded}</bldg:Building></core:cityObjectMember>\n"
    )
}

fn city(members: &str) -> String {
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<core:CityModel xmlns:core=\"http://www.opengis.net/citygml/1.0\" \
         xmlns:bldg=\"http://www.opengis.net/citygml/building/1.0\" xmlns:gml=\"http://www.opengis.net/gml\" \
         xmlns:xlink=\"http://www.w3.org/1999/xlink\">\n<gml:boundedBy><gml:Envelope srsName=\"urn:ogc:def:crs:EPSG::25832\" srsDimension=\"3\">\
         <gml:lowerCorner>324100 5729100 50</gml:lowerCorner><gml:upperCorner>324110 5729108 56</gml:upperCorner></gml:Envelope></gml:boundedBy>\n\
         {members}</core:CityModel>\n"
    )
}

fn timed(args: &[&str]) -> (Output, Duration) {
    let t = Instant::now();
    let o = common::run(args, None);
    (o, t.elapsed())
}

/// 1,500 identical buildings at one place (every corner is shared by 1,500 nodes): the pipe
/// citygml2popa3d → popa3d2citygml took 241 s for 1,529 with the pairwise node relabelling
/// (7 s for 400); with the union–find it takes seconds. A box converts back to itself, so the
/// written document equals the input byte for byte (the truth does not depend on geofit).
#[test]
fn identical_buildings_at_one_place_convert_back_in_linear_time() {
    let dir = common::tempdir();
    let d = dir.path();
    let n = 1500;
    let text = city(&(0..n).map(box_building).collect::<String>());
    let gml = d.join("same.gml");
    std::fs::write(&gml, &text).unwrap();
    let model = d.join("same.popa3d");
    let (o, t1) = timed(&["-q", "citygml2popa3d", s(&gml), "-o", s(&model)]);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    let back = d.join("back.gml");
    let (o, t2) = timed(&["-q", "popa3d2citygml", s(&model), "--template", s(&gml), "-o", s(&back)]);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    eprintln!("{n} identical buildings: citygml2popa3d {t1:?}, popa3d2citygml {t2:?}");
    assert!(t2 < Duration::from_secs(20), "popa3d2citygml took {t2:?} for {n} identical buildings");
    assert_eq!(std::fs::read_to_string(&back).unwrap(), text, "a box converts back to itself");
    let healed = d.join("healed.gml");
    let (o, t3) = timed(&["-q", "heal", s(&gml), "-o", s(&healed)]);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    eprintln!("heal {t3:?}");
    assert!(t3 < Duration::from_secs(30), "heal took {t3:?} for {n} identical buildings");
}

// ---------------------------------------------------------------------------------------------
// 2. allocations sized by headers

/// A LAS 1.4 header (375 bytes, point format 0, 20-byte records) claiming `points`, followed by
/// `stored` zero points.
fn las14(points: u64, stored: usize) -> Vec<u8> {
    let mut h = vec![0u8; 375];
    h[..4].copy_from_slice(b"LASF");
    h[24] = 1;
    h[25] = 4;
    h[94..96].copy_from_slice(&375u16.to_le_bytes());
    h[96..100].copy_from_slice(&375u32.to_le_bytes());
    h[104] = 0;
    h[105..107].copy_from_slice(&20u16.to_le_bytes());
    for k in 0..3 {
        h[131 + 8 * k..139 + 8 * k].copy_from_slice(&0.01f64.to_le_bytes()); // scale
    }
    h[247..255].copy_from_slice(&points.to_le_bytes());
    h.extend(vec![0u8; 20 * stored]);
    h
}

/// A LAZ file (LAS 1.4, compressed point format 0 with its LASzip VLR: pointwise chunked
/// compressor, one Point10 item) whose chunk table, found through the offset at the start of the
/// point data, claims 4·10⁹ chunks for 100 bytes of compressed data: the laz crate
/// pre-allocated 64 GB for the table and aborted (exit 134).
fn laz_chunks() -> Vec<u8> {
    let mut data = Vec::new();
    for v in [2u16, 0] {
        data.extend(v.to_le_bytes()); // compressor (pointwise chunked), coder
    }
    data.extend([2u8, 2]); // LASzip version 2.2
    data.extend(0u16.to_le_bytes()); // revision
    data.extend(0u32.to_le_bytes()); // options
    data.extend(50_000u32.to_le_bytes()); // chunk size
    data.extend((-1i64).to_le_bytes()); // special EVLRs: none
    data.extend((-1i64).to_le_bytes());
    data.extend(1u16.to_le_bytes()); // one item: Point10, 20 bytes, version 2
    for v in [6u16, 20, 2] {
        data.extend(v.to_le_bytes());
    }
    let mut vlr = vec![0u8; 2];
    vlr.extend(b"laszip encoded\0\0");
    vlr.extend(22204u16.to_le_bytes());
    vlr.extend((data.len() as u16).to_le_bytes());
    vlr.extend([0u8; 32]);
    vlr.extend(data);
    let mut f = las14(10, 0);
    f[104] = 0x80; // compressed point format 0
    let offset = (f.len() + vlr.len()) as u32;
    f[96..100].copy_from_slice(&offset.to_le_bytes());
    f[100..104].copy_from_slice(&1u32.to_le_bytes());
    f.extend(vlr);
    let table = offset as u64 + 8 + 100;
    f.extend(table.to_le_bytes());
    f.extend(vec![0u8; 100]);
    f.extend(0u32.to_le_bytes());
    f.extend(4_000_000_000u32.to_le_bytes());
    f.extend([0u8; 16]);
    f
}

/// A header claiming 10¹² points (`implicit` pre-allocated them, `info`/`rasterize` read the
/// file's 3 points and then failed) and a LAZ chunk table of 4·10⁹ entries (an abort inside
/// the laz crate): exit 3 naming what the file claims, for every command that reads points.
#[test]
fn point_headers_are_checked_against_the_file_size() {
    let dir = common::tempdir();
    let d = dir.path();
    let big = d.join("big.las");
    std::fs::write(&big, las14(1_000_000_000_000, 3)).unwrap();
    let laz = d.join("chunks.laz");
    std::fs::write(&laz, laz_chunks()).unwrap();
    let out = d.join("out.tif");
    let old = old_output(&out);
    let obj = d.join("out.obj");
    let old_obj = old_output(&obj);
    for (file, claim) in [(&big, "claims 1000000000000 points of 20 bytes"), (&laz, "claims 4000000000 chunks")] {
        fails(&common::run(&["info", s(file)], None), 3, &[s(file), claim]);
        fails(&common::run(&["-q", "rasterize", s(file), "--cell", "1", "-o", s(&out)], None), 3, &[s(file), claim]);
        fails(&common::run(&["-q", "implicit", s(file), "-o", s(&obj)], None), 3, &[claim]);
        // stdin: the same check on the bytes
        let bytes = std::fs::read(file).unwrap();
        fails(&common::run(&["-q", "implicit", "-", "-o", s(&obj)], Some(&bytes)), 3, &[claim]);
    }
    assert_eq!(std::fs::read(&out).unwrap(), old);
    assert_eq!(std::fs::read(&obj).unwrap(), old_obj);
    // the header's own count still holds when it fits: 3 points of 20 bytes are read
    let ok = d.join("ok.las");
    std::fs::write(&ok, las14(3, 3)).unwrap();
    let o = common::run(&["info", "--json", s(&ok)], None);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v.to_string().contains('3'), "{v}");
}

/// `/dev/zero` has no newline: the text reader gave it all the memory there was. The device is
/// now refused by name, and a line longer than 1 MiB (NUL bytes on stdin) ends the read (exit 3); an endless stream of valid points stops at the
/// point budget (here lowered with GEOFIT_MAX_POINTS). The old raster stays.
#[test]
fn endless_inputs_end_with_a_message() {
    let dir = common::tempdir();
    let out = dir.path().join("r.tif");
    let old = old_output(&out);
    let t = Instant::now();
    let o = common::run(&["-q", "rasterize", "/dev/zero", "--cell", "1", "-o", s(&out)], None);
    fails(&o, 3, &["/dev/zero", "not a data file"]);
    let o = common::run(&["-q", "rasterize", "-", "--cell", "1", "-o", s(&out)], Some(&vec![0u8; 3 << 20]));
    fails(&o, 3, &["<stdin>:1:", "longer than 1 MiB"]);
    assert!(t.elapsed() < Duration::from_secs(20));
    let points: String = (0..5000).map(|i| format!("{} {} 1\n", i % 70, i / 70)).collect();
    let mut cmd = common::geofit();
    cmd.args(["-q", "rasterize", "-", "--cell", "1", "-o", s(&out)]).env("GEOFIT_MAX_POINTS", "1000");
    cmd.stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::piped());
    let mut child = cmd.spawn().unwrap();
    let mut si = child.stdin.take().unwrap();
    std::thread::spawn(move || {
        use std::io::Write;
        let _ = si.write_all(points.as_bytes());
    });
    let o = child.wait_with_output().unwrap();
    fails(&o, 3, &["<stdin>", "more than 1000 points set by GEOFIT_MAX_POINTS"]);
    assert_eq!(std::fs::read(&out).unwrap(), old);
}

/// Commands that read an input whole (CityGML, popa3d, OBJ) grew without limit on a device or
/// an endless stdin (`info /dev/zero`). A memory device is now refused by name at once, and an
/// endless stdin stops at the byte budget (available memory, or
/// GEOFIT_MAX_INPUT_BYTES as here); a regular file over the budget is refused by its size before
/// it is read. The old output stays.
#[test]
fn inputs_read_whole_stop_at_the_byte_budget() {
    let dir = common::tempdir();
    let out = dir.path().join("out.gml");
    let old = old_output(&out);
    let budget = [("GEOFIT_MAX_INPUT_BYTES", "1000000")];
    let run_with = |args: &[&str], stdin: Option<Vec<u8>>| {
        let mut cmd = common::geofit();
        cmd.args(args).envs(budget);
        cmd.stdin(if stdin.is_some() { Stdio::piped() } else { Stdio::null() })
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut child = cmd.spawn().unwrap();
        if let Some(bytes) = stdin {
            let mut si = child.stdin.take().unwrap();
            std::thread::spawn(move || {
                use std::io::Write;
                let _ = si.write_all(&bytes);
            });
        }
        child.wait_with_output().unwrap()
    };
    let t = Instant::now();
    let o = run_with(&["info", "/dev/zero"], None);
    fails(&o, 3, &["/dev/zero", "not a data file"]);
    let o = run_with(&["info", "-"], Some(vec![0u8; 3_000_000]));
    fails(&o, 3, &["<stdin>", "more than 1000000 bytes set by GEOFIT_MAX_INPUT_BYTES"]);
    assert!(t.elapsed() < Duration::from_secs(20));
    let endless_xml =
        b"<!-- a comment that never ends ".iter().copied().chain(std::iter::repeat_n(b'x', 3_000_000)).collect();
    let o = run_with(&["-q", "heal", "-", "-o", s(&out)], Some(endless_xml));
    fails(&o, 3, &["<stdin>", "more than 1000000 bytes"]);
    let big = dir.path().join("big.gml");
    std::fs::write(&big, city(&box_building(0))).unwrap();
    let f = std::fs::OpenOptions::new().append(true).open(&big).unwrap();
    f.set_len(2_000_000).unwrap();
    let o = run_with(&["-q", "heal", s(&big), "-o", s(&out)], None);
    fails(&o, 3, &["big.gml", "more than 1000000 bytes"]);
    assert_eq!(std::fs::read(&out).unwrap(), old);
}

// ---------------------------------------------------------------------------------------------
// 3. bounded quotes

/// A 1 MB value where a number or an id belongs: the message quotes ~200 bytes of it.
#[test]
fn errors_quote_at_most_200_bytes_of_the_input() {
    let dir = common::tempdir();
    let d = dir.path();
    let huge = "7".repeat(500_000) + "x";
    // popa3d XML: an attribute that is not an id
    let p = d.join("m.popa3d");
    std::fs::write(&p, format!("<?xml version=\"1.0\"?>\n<popa3d xmlns=\"urn:geofit:popa3d:1\" version=\"1\">\n  <origin x=\"0\" y=\"0\" z=\"0\"/>\n  <nodes><node id=\"{huge}\"/></nodes>\n</popa3d>\n")).unwrap();
    // XYZ text: a coordinate that is not a number
    let x = d.join("p.xyz");
    std::fs::write(&x, format!("1 2 3\n{huge} 2 3\n")).unwrap();
    // CityGML: an end tag that does not match a huge start tag
    let g = d.join("c.gml");
    std::fs::write(&g, format!("<?xml version=\"1.0\"?>\n<core:CityModel xmlns:core=\"http://www.opengis.net/citygml/2.0\"><a{huge}></b></core:CityModel>\n")).unwrap();
    // T-mesh XML: a degree that is not a number
    let t = d.join("m.tmesh");
    std::fs::write(
        &t,
        format!("<?xml version=\"1.0\"?>\n<tmesh xmlns=\"{}\" degree=\"{huge}\"/>\n", tspline_namespace()),
    )
    .unwrap();
    let (out, tif, popa) = (d.join("out.gml"), d.join("out.tif"), d.join("out.popa3d"));
    let (old, old_tif, old_popa) = (old_output(&out), old_output(&tif), old_output(&popa));
    let cases: [(&[&str], &str); 5] = [
        (&["info", s(&t)], "m.tmesh"),
        (&["adjust", s(&p), "-o", s(&popa)], "m.popa3d"),
        (&["-q", "rasterize", s(&x), "--cell", "1", "-o", s(&tif)], "p.xyz:2"),
        (&["info", s(&g)], "c.gml"),
        (&["-q", "heal", s(&g), "-o", s(&out)], "c.gml"),
    ];
    for (args, name) in cases {
        let o = common::run(args, None);
        let e = stderr(&o);
        let code = common::code(&o);
        assert!(code == 3 || code == 1, "{args:?}: exit {code}: {}", &e[..e.len().min(400)]);
        assert!(!e.contains("panicked"));
        assert!(e.len() < 1000, "{args:?}: {} bytes of message", e.len());
        assert!(e.contains(name) && e.contains('…') && e.contains("bytes)"), "{args:?}: {e}");
    }
    assert_eq!(std::fs::read(&out).unwrap(), old);
    assert_eq!(std::fs::read(&tif).unwrap(), old_tif);
    assert_eq!(std::fs::read(&popa).unwrap(), old_popa);
}

/// The T-mesh XML namespace, read from the format's source so the test follows it.
fn tspline_namespace() -> String {
    let src = std::fs::read_to_string(common::repo_root().join("crates/tspline/src/format.rs")).unwrap();
    let line = src.lines().find(|l| l.starts_with("pub const NAMESPACE")).unwrap();
    line.split('"').nth(1).unwrap().to_string()
}

// ---------------------------------------------------------------------------------------------
// 4. info and its stdout

/// `info` with fd 1 closed wrote nothing and exited 0; `info -` on an empty stdin said "no
/// points".
#[test]
fn info_reports_a_closed_stdout_and_an_empty_input() {
    let dir = common::tempdir();
    let f = dir.path().join("p.xyz");
    std::fs::write(&f, "0 0 1\n1 0 2\n0 1 3\n").unwrap();
    let o = Command::new("sh")
        .arg("-c")
        .arg(format!("exec '{}' info '{}' >&-", env!("CARGO_BIN_EXE_geofit"), s(&f)))
        .output()
        .unwrap();
    fails(&o, 4, &["stdout is closed"]);
    let o = common::run(&["info", "-"], Some(b""));
    let e = fails(&o, 3, &["<stdin>: no input (the previous stage wrote nothing)"]);
    assert!(!e.contains("no points"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// 5. temporaries

/// A process id that is not running (a child that has exited and been reaped).
fn dead_pid() -> u32 {
    let mut c = Command::new("true").spawn().unwrap();
    let pid = c.id();
    c.wait().unwrap();
    assert!(!Path::new(&format!("/proc/{pid}")).exists());
    pid
}

/// Temporaries left by a killed run (`.geofit-PID-….tmp` files of the atomic writer,
/// `.geofit-raster-PID-N.tmp` staging directories) are removed by the next run writing into
/// the directory when their process is gone and nothing wrote them for an hour; a running
/// process's temporary stays, and so does a fresh one of a PID this host cannot see.
#[test]
fn stale_temporaries_of_dead_processes_are_removed() {
    if !Path::new("/proc/self").exists() {
        eprintln!("SKIP: no /proc");
        return;
    }
    let dir = common::tempdir();
    let d = dir.path();
    let dead = dead_pid();
    let live = std::process::id();
    let stale_file = d.join(format!(".geofit-{dead}-aB3dE9.tmp"));
    let stale_dir = d.join(format!(".geofit-raster-{dead}-0.tmp"));
    let running = d.join(format!(".geofit-{live}-Zz9Yy8.tmp"));
    let other = d.join(".geofit-notes.tmp"); // not a geofit temporary name: left alone
    std::fs::write(&stale_file, "half a file").unwrap();
    std::fs::create_dir(&stale_dir).unwrap();
    std::fs::write(stale_dir.join("r.tif"), "half a raster").unwrap();
    std::fs::write(&running, "being written").unwrap();
    std::fs::write(&other, "mine").unwrap();
    // a fresh temporary of a process this host cannot see (another container's PID namespace on
    // the same volume) is being written: it stays; the killed run's are two hours old
    let elsewhere = d.join(format!(".geofit-{dead}-Qq7Ww6.tmp"));
    std::fs::write(&elsewhere, "another container's output").unwrap();
    let two_hours_ago = std::time::SystemTime::now() - Duration::from_secs(7200);
    let age = |p: &Path| std::fs::File::open(p).unwrap().set_modified(two_hours_ago).unwrap();
    age(&stale_file);
    age(&stale_dir.join("r.tif"));
    age(&stale_dir);
    let pts = d.join("p.xyz");
    std::fs::write(&pts, "0 0 1\n1 0 2\n0 1 3\n1 1 4\n").unwrap();
    let o = common::run(&["-q", "rasterize", s(&pts), "--cell", "0.5", "-o", s(&d.join("r.tif"))], None);
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    assert!(!stale_file.exists() && !stale_dir.exists(), "stale temporaries left");
    assert!(running.exists() && other.exists() && elsewhere.exists());
    // the atomic writer (a text output) cleans too, and its own temporary is gone after the run
    std::fs::write(&stale_file, "half a file").unwrap();
    age(&stale_file);
    let o = common::run(
        &["-q", "citygml2popa3d", "-", "-o", s(&d.join("m.popa3d"))],
        Some(city(&box_building(0)).as_bytes()),
    );
    assert_eq!(common::code(&o), 0, "{}", stderr(&o));
    assert!(!stale_file.exists());
    let left: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert_eq!(left.len(), 3, "{left:?}");
}

// ---------------------------------------------------------------------------------------------
// 6. XSD on one element with many attributes

/// One element with 100,000 attributes took libxml2's schema check 100 s; it is now a finding
/// (exit 1) naming the element, found before libxml2 sees the document.
#[test]
fn validate_refuses_an_element_with_100k_attributes_in_time() {
    let Some(xsd) = common::shared_xsd() else { return };
    let dir = common::tempdir();
    let f = dir.path().join("attrs.gml");
    let attrs: String = (0..100_000).map(|i| format!(" a{i}=\"{i}\"")).collect();
    let doc = city(&box_building(0)).replacen(
        "<bldg:Building gml:id=\"B0\"",
        &format!("<bldg:Building gml:id=\"B0\"{attrs}"),
        1,
    );
    std::fs::write(&f, doc).unwrap();
    let t = Instant::now();
    let o = common::run(&["validate", "--no-geometry", "--schemas", s(&xsd), s(&f)], None);
    let e = format!("{}{}", String::from_utf8_lossy(&o.stdout), stderr(&o));
    assert_eq!(common::code(&o), 1, "{}", &e[..e.len().min(2000)]);
    assert!(t.elapsed() < Duration::from_secs(20), "{:?}", t.elapsed());
    assert!(e.contains("100001 attributes") && e.contains("Building"), "{}", &e[..e.len().min(2000)]);
    assert!(!e.contains("panicked"));
}

// ---------------------------------------------------------------------------------------------
// 6. bounded memory

/// Runs geofit with stdout and stderr to files in `dir`; returns the exit code, the child's peak
/// resident set in MiB (wait4's rusage of that one process, so tests running beside it do not
/// count) and its stdout.
#[allow(clippy::zombie_processes)] // reaped by wait4, which std's Child::wait cannot replace
fn run_measuring_rss(dir: &Path, args: &[&str]) -> (i32, f64, Vec<u8>) {
    let out = dir.join("stdout");
    let err = dir.join("stderr");
    let child = common::geofit()
        .args(args)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out).unwrap())
        .stderr(std::fs::File::create(&err).unwrap())
        .spawn()
        .unwrap();
    let pid = child.id() as libc::pid_t;
    let mut status = 0;
    // SAFETY: a zeroed rusage is a valid value for wait4 to fill; the child is ours and waited once.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    assert_eq!(unsafe { libc::wait4(pid, &mut status, 0, &mut usage) }, pid);
    let stderr = std::fs::read_to_string(&err).unwrap();
    assert!(libc::WIFEXITED(status), "{args:?} ended by a signal: {stderr}");
    let peak_mib = usage.ru_maxrss as f64 / 1024.0; // kilobytes on Linux
    (libc::WEXITSTATUS(status), peak_mib, std::fs::read(&out).unwrap())
}

/// NRW tile 332's 62 buildings repeated, each copy with its own gml:ids (and XLinks renamed
/// with them), until the file has at least `min_bytes`; returns the number of copies.
fn repeated_tile(tile: &Path, dest: &Path, min_bytes: u64) -> u64 {
    use std::io::Write;
    let src = std::fs::read_to_string(tile).unwrap();
    let first = src.find("<core:cityObjectMember>").unwrap();
    let end_tag = "</core:cityObjectMember>";
    let last = src.rfind(end_tag).unwrap() + end_tag.len();
    let (head, members, tail) = (&src[..first], &src[first..last], &src[last..]);
    let mut w = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(dest).unwrap());
    w.write_all(head.as_bytes()).unwrap();
    let mut copies = 0;
    while (head.len() + tail.len()) as u64 + copies * members.len() as u64 + 1000 < min_bytes {
        let renamed = members
            .replace("gml:id=\"", &format!("gml:id=\"c{copies}_"))
            .replace("xlink:href=\"#", &format!("xlink:href=\"#c{copies}_"));
        w.write_all(renamed.as_bytes()).unwrap();
        copies += 1;
    }
    w.write_all(tail.as_bytes()).unwrap();
    w.flush().unwrap();
    copies
}

fn json_number(report: &[u8], pointer: &str) -> u64 {
    let v: serde_json::Value = serde_json::from_slice(report).unwrap();
    v.pointer(pointer).and_then(|n| n.as_u64()).unwrap_or_else(|| panic!("no {pointer} in the report"))
}

/// `info` and `validate --no-xsd` read CityGML object by object from a memory map that releases
/// the pages behind the reader, and the line index is built as the reader goes: on a 1 GiB tile
/// (read whole, the RSS was the file plus ~110 MB) both stay under 200 MiB, and what they report
/// is the single tile's counts and findings times the number of copies.
#[test]
fn citygml_of_1_gib_is_summarised_and_validated_in_200_mib() {
    let Some(tile) = common::fixture("citygml/nrw/LoD2_32_332_5729_1_NW.gml") else { return };
    let dir = common::tempdir();
    let (_, _, one_info) = run_measuring_rss(dir.path(), &["info", "--json", s(&tile)]);
    let (_, _, one_check) = run_measuring_rss(dir.path(), &["-q", "validate", "--no-xsd", "--json", s(&tile)]);
    let big = dir.path().join("big.gml");
    let copies = repeated_tile(&tile, &big, 1 << 30);
    assert!(std::fs::metadata(&big).unwrap().len() >= 1 << 30);

    let (code, peak, info) = run_measuring_rss(dir.path(), &["info", "--json", s(&big)]);
    assert_eq!(code, 0);
    eprintln!("info of {copies} copies of tile 332: peak RSS {peak:.0} MiB");
    assert!(peak <= 200.0, "info: peak RSS {peak:.0} MiB for a 1 GiB file");
    for key in ["/top_level_objects", "/polygons", "/points", "/xlinks_resolved"] {
        assert_eq!(json_number(&info, key), copies * json_number(&one_info, key), "{key}");
    }

    let (code, peak, check) = run_measuring_rss(dir.path(), &["-q", "validate", "--no-xsd", "--json", s(&big)]);
    assert_eq!(code, 1, "the tile has findings, so has the big file");
    eprintln!("validate --no-xsd of the same: peak RSS {peak:.0} MiB");
    assert!(peak <= 200.0, "validate --no-xsd: peak RSS {peak:.0} MiB for a 1 GiB file");
    let findings = |r: &[u8]| {
        serde_json::from_slice::<serde_json::Value>(r).unwrap()["geometry"]["findings"].as_array().unwrap().len() as u64
    };
    assert_eq!(findings(&check), copies * findings(&one_check));
    assert_eq!(json_number(&check, "/geometry/features"), copies * json_number(&one_check, "/geometry/features"));
}

/// A LAS 1.4 file of `n` ground points (format 0, 1 cm resolution) spread over 2000 × 2000 m
/// by a fixed pseudo-random sequence, heights a smooth function of x and y.
fn las_points(path: &Path, n: u64) {
    use std::io::Write;
    let mut w = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    w.write_all(&las14(n, 0)).unwrap();
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..n {
        let (x, y) = (2000.0 * next(), 2000.0 * next());
        let z = 100.0 + 10.0 * (x / 100.0).sin() * (y / 150.0).cos();
        let mut record = [0u8; 20];
        for (k, v) in [x, y, z].iter().enumerate() {
            record[4 * k..4 * k + 4].copy_from_slice(&((v * 100.0) as i32).to_le_bytes());
        }
        record[15] = 2; // class: ground
        w.write_all(&record).unwrap();
    }
    w.flush().unwrap();
}

/// `rasterize --method gauss` of a point file streams the points (a pass for the bounds, a
/// pass to splat) and holds only the grid's accumulators: four times the points on the same
/// grid cost about the same memory, where holding them cost 24 bytes a point (3·10⁶ more points:
/// ≥ 69 MiB more). Both rasters have a value in (almost) every cell, within the heights' range.
#[test]
fn gauss_rasterize_memory_does_not_grow_with_the_points() {
    let dir = common::tempdir();
    let mut peaks = Vec::new();
    for n in [1_000_000u64, 4_000_000] {
        let las = dir.path().join(format!("p{n}.las"));
        las_points(&las, n);
        let tif = dir.path().join(format!("p{n}.tif"));
        let report = dir.path().join(format!("p{n}.json"));
        let args = [
            "-q",
            "rasterize",
            s(&las),
            "--cell",
            "2",
            "--bounds",
            "0",
            "0",
            "2000",
            "2000",
            "-o",
            s(&tif),
            "--report",
            s(&report),
        ];
        let (code, peak, _) = run_measuring_rss(dir.path(), &args);
        assert_eq!(code, 0);
        let r = std::fs::read(&report).unwrap();
        assert_eq!(json_number(&r, "/points"), n);
        assert!(
            json_number(&r, "/cells_with_value") >= 999_000,
            "a point within 1.5 cells of almost every cell centre"
        );
        let raster = raster_io::read_raster(&tif).unwrap();
        let (lo, hi) = raster.data.iter().fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(*v), b.max(*v)));
        assert!(lo >= 89.99 && hi <= 110.01, "heights {lo}..{hi}");
        eprintln!("rasterize of {n} points onto 10⁶ cells: peak RSS {peak:.0} MiB");
        peaks.push(peak);
        std::fs::remove_file(&las).unwrap();
    }
    assert!(peaks[1] - peaks[0] < 20.0, "3·10⁶ more points cost {:.0} MiB more", peaks[1] - peaks[0]);
    assert!(peaks[1] <= 150.0, "peak {:.0} MiB", peaks[1]);
}

/// A 10 KB netCDF grid with one attribute count flipped to 2³¹ + 2 made GDAL's netCDF driver
/// (libnetcdf) allocate 16 GB before it found the file too short (fuzzing the shipped GMT grids:
/// 1.7–21 GB peaks, one hang). The classic header is now checked first: `info`, `fit` and
/// `tile plan` end with exit 3 naming the attribute, in the memory of a small run, and leave an
/// old output as it was.
#[test]
fn a_netcdf_header_claiming_billions_of_values_is_refused_before_gdal_reads_it() {
    let Some(grid) = common::fixture("terrain/gmt_tut_bathy.nc") else { return };
    let dir = common::tempdir();
    let mut bytes = std::fs::read(&grid).unwrap();
    let at = bytes.windows(12).position(|w| w == b"actual_range").unwrap() + 12 + 4;
    bytes[at] = 0x80; // the attribute's value count, big-endian: 2 → 2³¹ + 2
    let bad = dir.path().join("bad.nc");
    std::fs::write(&bad, &bytes).unwrap();
    let out = dir.path().join("out.tmesh");
    let old = old_output(&out);
    for args in [
        vec!["info", s(&bad)],
        vec!["-q", "fit", s(&bad), "--max-error", "10", "-o", s(&out)],
        vec!["-q", "tile", "plan", s(&bad)],
    ] {
        let (code, peak, _) = run_measuring_rss(dir.path(), &args);
        let e = std::fs::read_to_string(dir.path().join("stderr")).unwrap();
        assert_eq!(code, 3, "{args:?}: {e}");
        assert_eq!(e.trim_end().lines().count(), 1, "{e}");
        assert!(e.contains("bad.nc") && e.contains("values of attribute 'actual_range'"), "{e}");
        assert!(peak < 300.0, "{args:?}: peak RSS {peak:.0} MiB");
    }
    assert_eq!(std::fs::read(&out).unwrap(), old);
}

/// A command with several outputs replaces all of them or none (issue 40): the disk of one
/// output fills while it is written, and the outputs written before it keep their old bytes
/// (they wait as temporaries until every output is complete). Root only: each case mounts a
/// 64 KiB tmpfs in a private mount namespace (`unshare -m`), nothing of the host is touched.
#[test]
fn a_full_disk_between_outputs_leaves_every_old_output() {
    let root = std::process::Command::new("id").arg("-u").output().map(|o| o.stdout == b"0\n").unwrap_or(false);
    if !root || !std::process::Command::new("unshare").args(["-m", "true"]).status().is_ok_and(|s| s.success()) {
        eprintln!("SKIP: needs root and unshare -m (a private tmpfs)");
        return;
    }
    let dir = common::tempdir();
    let d = dir.path();
    let grid = d.join("g.asc");
    let rows: String = (0..40)
        .map(|r| {
            (0..40).map(|c| format!("{}", ((r * 7 + c * 13) % 17) as f64 * 0.9)).collect::<Vec<_>>().join(" ") + "\n"
        })
        .collect();
    std::fs::write(&grid, format!("ncols 40\nnrows 40\nxllcorner 0\nyllcorner 0\ncellsize 1\n{rows}")).unwrap();
    let bin = env!("CARGO_BIN_EXE_geofit");
    // the full disk holds the mesh (written first) and then the report (written last)
    for full in ["mesh", "report"] {
        let (small, big) = (d.join(format!("small-{full}")), d.join(format!("big-{full}")));
        std::fs::create_dir_all(&small).unwrap();
        std::fs::create_dir_all(&big).unwrap();
        let (mesh, report) = if full == "mesh" {
            (small.join("m.tmesh"), big.join("r.json"))
        } else {
            (big.join("m.tmesh"), small.join("r.json"))
        };
        let script = format!(
            "mount -t tmpfs -o size=64k none '{small}' || exit 99; echo 'old mesh' > '{mesh}'; echo 'old report' > '{report}'; \
             head -c 1000000 /dev/zero > '{small}/filler' 2>/dev/null; \
             '{bin}' -q fit '{grid}' --max-error 0.01 --degree 1 -o '{mesh}' --report '{report}'; echo \"exit $?\"; cat '{mesh}' '{report}'",
            small = small.display(), mesh = mesh.display(), report = report.display(), bin = bin, grid = grid.display()
        );
        let o = std::process::Command::new("unshare").args(["-m", "bash", "-c", &script]).output().unwrap();
        let out = String::from_utf8_lossy(&o.stdout);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(out.contains("exit 4"), "{full}: the fit must fail writing: {out} {err}");
        assert!(
            out.contains("old mesh") && out.contains("old report"),
            "{full}: an old output was replaced: {out} {err}"
        );
        assert!(err.contains("No space left"), "{err}");
    }
}
