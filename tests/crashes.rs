//! Issue 40: crashes and hangs found by mutation — each reproducer is built here, and must end
//! with exit 3 (an input) or 2 (an option) and one stderr line naming the file or option, in
//! bounded time and memory, writing nothing at -o and leaving the input as it was.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The longest any reproducer may take.
const LIMIT: Duration = Duration::from_secs(20);

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Runs `cmd` (stdin closed), killed after [`LIMIT`]; returns (exit code, stderr, seconds).
fn run_bounded(mut cmd: Command) -> (i32, String, f64) {
    let t0 = Instant::now();
    let mut child = cmd.stdin(Stdio::null()).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().expect("spawn");
    let mut err = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = std::io::Read::read_to_string(&mut err, &mut text);
        text
    });
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let text = reader.join().unwrap();
            let code = status.code().unwrap_or_else(|| panic!("killed by a signal ({status}); stderr: {text}"));
            return (code, text, t0.elapsed().as_secs_f64());
        }
        if t0.elapsed() > LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("still running after {LIMIT:?}: {cmd:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// geofit `args` must end with `code`, one stderr line holding every one of `says`, nothing
/// written at `out`, and `input` unchanged.
fn refused(args: &[&str], code: i32, says: &[&str], out: &Path, input: &Path) {
    refused_cmd(common::geofit(), args, code, says, out, input)
}

fn refused_cmd(mut cmd: Command, args: &[&str], code: i32, says: &[&str], out: &Path, input: &Path) {
    let before = std::fs::read(input).unwrap();
    cmd.args(args);
    let (got, err, secs) = run_bounded(cmd);
    assert_eq!(got, code, "{args:?}: stderr {err}");
    assert_eq!(err.lines().count(), 1, "{args:?}: one line, got {err}");
    for w in says {
        assert!(err.contains(w), "{args:?}: {err:?} should say {w:?}");
    }
    assert!(!err.contains("panicked"), "{err}");
    assert!(!out.exists(), "{args:?} wrote {}", out.display());
    assert_eq!(std::fs::read(input).unwrap(), before, "{args:?} changed its input");
    eprintln!("{args:?}: exit {got} in {secs:.2} s: {}", err.trim_end());
}

fn u16_at(b: &[u8], i: usize) -> usize {
    u16::from_le_bytes([b[i], b[i + 1]]) as usize
}

/// Offset of the LASzip VLR's first item (type u16, size u16, version u16).
fn laszip_items_at(b: &[u8]) -> usize {
    let mut at = u16_at(b, 94);
    for _ in 0..u32::from_le_bytes(b[100..104].try_into().unwrap()) {
        if &b[at + 2..at + 16] == b"laszip encoded" {
            return at + 54 + 34;
        }
        at += 54 + u16_at(b, at + 20);
    }
    panic!("no LASzip VLR");
}

// ---------------------------------------------------------------------------------------------
// 1. LAZ: the POINT10 item size of the LASzip VLR set to 1 (a panic in laz: `mid > len`)

#[test]
fn laz_item_size_of_one_is_refused() {
    let Some(fixture) = common::fixture("terrain/lidR_Topography.laz") else { return };
    let d = common::tempdir();
    let mut b = std::fs::read(&fixture).unwrap();
    let at = laszip_items_at(&b);
    assert_eq!(u16_at(&b, at), 6, "POINT10 is the first item");
    assert_eq!(u16_at(&b, at + 2), 20);
    b[at + 2] = 1;
    let bad = d.path().join("item.laz");
    std::fs::write(&bad, &b).unwrap();
    let out = d.path().join("out.tif");
    refused(
        &["-q", "rasterize", s(&bad), "--cell", "1", "-o", s(&out)],
        3,
        &["item.laz", "POINT10", "size of 1"],
        &out,
        &bad,
    );
    let out = d.path().join("out.obj");
    refused(&["-q", "implicit", s(&bad), "-o", s(&out)], 3, &["item.laz", "POINT10"], &out, &bad);
}

// ---------------------------------------------------------------------------------------------
// 4. LAZ 1.4 (layered): the first chunk's layer sizes set to 0xFF (4.2 GB before exit 3)

#[test]
fn laz_layer_sizes_beyond_the_file_are_refused_within_a_memory_limit() {
    if !common::tool("bash") {
        return;
    }
    // a layered LAS 1.4 LAZ (point format 6, 1000 points) as the las crate writes it
    let seed = common::repo_root().join("fuzz/corpus/las/format6-1.4.laz");
    let d = common::tempdir();
    let mut b = std::fs::read(&seed).unwrap();
    assert_eq!((b[24], b[25], b[104] & 0x3f), (1, 4, 6), "LAS 1.4, format 6");
    let points = u32::from_le_bytes(b[96..100].try_into().unwrap()) as usize;
    let sizes = points + 8 + 30 + 4; // chunk table offset, raw first point, point count
    b[sizes..sizes + 9 * 4].fill(0xFF);
    let bad = d.path().join("layers.laz");
    std::fs::write(&bad, &b).unwrap();
    let out = d.path().join("out.tif");
    // 1.5 GB of address space: the 9 × 4 GB the layers claim cannot be allocated
    let mut cmd = Command::new("bash");
    cmd.arg("-c").arg("ulimit -v 1500000 && exec \"$0\" \"$@\"").arg(env!("CARGO_BIN_EXE_geofit"));
    refused_cmd(
        cmd,
        &["-q", "rasterize", s(&bad), "--cell", "1", "-o", s(&out)],
        3,
        &["layers.laz", "LAZ chunk 0", "claims layers of"],
        &out,
        &bad,
    );
    // the unmutated file reads under the same limit
    let good = d.path().join("good.laz");
    std::fs::copy(&seed, &good).unwrap();
    let o = Command::new("bash")
        .arg("-c")
        .arg("ulimit -v 1500000 && exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_geofit"))
        .args(["-q", "rasterize", s(&good), "--cell", "1", "-o", s(&out)])
        .output()
        .unwrap();
    assert_eq!(common::code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
}

// ---------------------------------------------------------------------------------------------
// 2. implicit: a .gfim whose value weight is NaN or 1e300; --w-value 1e300 / --w-normal 1e308

/// A small model (100 sphere points, one coarse cube) and its points.
fn small_model(dir: &Path) -> (PathBuf, PathBuf) {
    let (pts, model) = (dir.join("s.xyz"), dir.join("m.gfim"));
    for args in [
        vec!["-q", "implicit", "generate", "sphere", "--n", "100", "--seed", "1", "-o", s(&pts)],
        vec!["-q", "implicit", "interpolate", s(&pts), "--coarse", "1", "--cell", "1", "-o", s(&model)],
    ] {
        let o = common::run(&args, None);
        assert_eq!(common::code(&o), 0, "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    }
    (pts, model)
}

#[test]
fn gfim_with_a_nan_or_huge_value_weight_is_refused() {
    let d = common::tempdir();
    let (_, model) = small_model(d.path());
    let good = std::fs::read(&model).unwrap();
    let at = 16 + 4 + 24 + 8; // magic, version, origin, cell: then ϖ_value
    assert_eq!(f64::from_le_bytes(good[at..at + 8].try_into().unwrap()), 1.0, "the default value weight");
    for (v, says) in
        [(f64::NAN, "value weight NaN"), (1e300, "value weight 1e300"), (f64::INFINITY, "value weight inf")]
    {
        let mut b = good.clone();
        b[at..at + 8].copy_from_slice(&v.to_le_bytes());
        let bad = d.path().join("bad.gfim");
        std::fs::write(&bad, &b).unwrap();
        let out = d.path().join("out.gfim");
        refused(
            &["-q", "implicit", "update", s(&bad), "--move", "0,0,0,0.5", "-o", s(&out)],
            3,
            &["bad.gfim", says],
            &out,
            &bad,
        );
    }
    // the CG iteration cap of a model is bounded too
    let mut b = good.clone();
    b[at + 48..at + 56].copy_from_slice(&u64::MAX.to_le_bytes());
    let bad = d.path().join("cap.gfim");
    std::fs::write(&bad, &b).unwrap();
    let out = d.path().join("out.gfim");
    refused(
        &["-q", "implicit", "update", s(&bad), "--move", "0,0,0,0.5", "-o", s(&out)],
        3,
        &["cap.gfim", "iteration cap"],
        &out,
        &bad,
    );
}

#[test]
fn huge_weights_on_the_command_line_are_usage_errors() {
    let d = common::tempdir();
    let (pts, _) = small_model(d.path());
    let out = d.path().join("out.gfim");
    for (opt, v) in [("--w-value", "1e300"), ("--w-normal", "1e308"), ("--w-rough", "1e11")] {
        refused(
            &["-q", "implicit", "interpolate", s(&pts), opt, v, "-o", s(&out)],
            2,
            &[opt, "largest weight"],
            &out,
            &pts,
        );
    }
}

// ---------------------------------------------------------------------------------------------
// 3. tile plan: one 1e308 coordinate, one vertex at 0 0 0; a plan over a huge extent

/// A 10 × 8 m box building `id` at (x, y) (ground and roof; `odd` replaces the roof's first
/// vertex).
fn building(id: &str, x: f64, y: f64, odd: Option<&str>) -> String {
    let ring = |z: f64| {
        let p = [(x, y), (x + 10.0, y), (x + 10.0, y + 8.0), (x, y + 8.0), (x, y)];
        p.iter().map(|(a, b)| format!("{a} {b} {z}")).collect::<Vec<_>>()
    };
    let ground = ring(50.0).join(" ");
    let mut roof = ring(56.0);
    if let Some(o) = odd {
        roof[1] = o.to_string();
    }
    let roof = roof.join(" ");
    let surface = |kind: &str, k: usize, pos: &str| {
        format!(
            "<bldg:boundedBy><bldg:{kind} gml:id=\"{id}_{k}\"><bldg:lod2MultiSurface><gml:MultiSurface><gml:surfaceMember>\
             <gml:Polygon><gml:exterior><gml:LinearRing><gml:posList srsDimension=\"3\">{pos}</gml:posList>\
             </gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember></gml:MultiSurface></bldg:lod2MultiSurface>\
             </bldg:{kind}></bldg:boundedBy>"
        )
    };
    format!(
        "<core:cityObjectMember><bldg:Building gml:id=\"{id}\">{}{}</bldg:Building></core:cityObjectMember>\n",
        surface("GroundSurface", 0, &ground),
        surface("RoofSurface", 1, &roof)
    )
}

fn city(members: &str) -> String {
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<core:CityModel xmlns:core=\"http://www.opengis.net/citygml/2.0\" \
         xmlns:bldg=\"http://www.opengis.net/citygml/building/2.0\" xmlns:gml=\"http://www.opengis.net/gml\">\n{members}</core:CityModel>\n"
    )
}

#[test]
fn tile_plan_refuses_misplaced_vertices_naming_the_building() {
    let d = common::tempdir();
    let (x, y) = (324_100.0, 5_729_100.0);
    for (file, odd, says) in [
        ("far.gml", "1e308 5729100 56", vec!["far.gml", "building B_odd", "1e308"]),
        ("null.gml", "0 0 0", vec!["null.gml", "building B_odd", "0 0 0"]),
    ] {
        let gml = d.path().join(file);
        let text = city(
            &(building("B_a", x, y, None)
                + &building("B_odd", x + 20.0, y, Some(odd))
                + &building("B_b", x + 40.0, y, None)),
        );
        std::fs::write(&gml, text).unwrap();
        let out = d.path().join("plan.jsonl");
        for size in [vec![], vec!["--tile-size", "1"]] {
            let mut args = vec!["-q", "tile", "plan", s(&gml), "-o", s(&out)];
            args.extend(size);
            let says: Vec<&str> = says.iter().map(|w| &**w).collect();
            refused(&args, 3, &says, &out, &gml);
        }
    }
}

#[test]
fn tile_plan_over_a_huge_extent_does_not_walk_empty_cells() {
    let d = common::tempdir();
    // two buildings 4000 km apart, 1 m tiles: 4·10¹² empty cells between them
    let gml = d.path().join("far_apart.gml");
    std::fs::write(
        &gml,
        city(&(building("B_w", 100_000.0, 1_000_000.0, None) + &building("B_e", 4_100_000.0, 1_000_000.0, None))),
    )
    .unwrap();
    let out = d.path().join("plan.jsonl");
    let mut cmd = common::geofit();
    cmd.args(["-q", "tile", "plan", "--tile-size", "1", s(&gml), "-o", s(&out)]);
    let (code, err, _) = run_bounded(cmd);
    assert_eq!(code, 0, "{err}");
    let plan = std::fs::read_to_string(&out).unwrap();
    assert_eq!(plan.lines().count(), 2, "{plan}");
}

/// A corrupt compressed stream (found by the `las` fuzz target) tripped an assertion inside
/// laz's arithmetic decoder: now exit 3 and one line where it trips, never a panic.
#[test]
fn laz_decoder_panics_become_read_errors() {
    let d = common::tempdir();
    let bad = d.path().join("corrupt.laz");
    std::fs::copy(common::repo_root().join("fuzz/regressions/las/laz-decoder-assertion.laz"), &bad).unwrap();
    let out = d.path().join("out.tif");
    let mut cmd = common::geofit();
    cmd.args(["-q", "rasterize", s(&bad), "--cell", "1", "-o", s(&out)]);
    let (code, err, _) = run_bounded(cmd);
    assert!(code == 0 || code == 3, "exit {code}: {err}");
    assert!(err.lines().count() <= 1 && !err.contains("panicked"), "{err}");
    if code == 3 {
        assert!(err.contains("corrupt.laz") && err.contains("corrupt"), "{err}");
        assert!(!out.exists());
    }
}
