//! Issue 40: limits. The byte, point and cell budgets follow `ulimit -v` and the memory cgroup
//! (docs/decisions.md#budgets-under-cgroups-and-ulimit), and inputs that broke the message rules
//! (a 1 MB name in a popa3d file, NUL bytes in a T-mesh, a CityGML file heal cannot heal a
//! building of) end with one bounded line and the exit of every other command
//! (docs/decisions.md#messages-and-refusals-of-issue-40).

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Asserts exit `code`, no panic, one line on stderr shorter than 1000 bytes containing every
/// needle, and that `out` was not written; returns stderr.
fn fails(o: &Output, code: i32, needles: &[&str], out: &Path) -> String {
    let e = String::from_utf8_lossy(&o.stderr).into_owned();
    let head = &e[..e.len().min(600)];
    assert_eq!(common::code(o), code, "{head}");
    assert!(e.len() < 1000, "{} bytes of message: {head}", e.len());
    assert!(!e.contains("panicked") && !e.contains("RUST_BACKTRACE"), "{e}");
    assert_eq!(e.trim_end().lines().count(), 1, "one line expected: {e}");
    for n in needles {
        assert!(e.contains(n), "expected {n:?} in {e:?}");
    }
    assert!(!out.exists(), "{} was written", out.display());
    e
}

/// The directory of this run's `geofit`, for `bash -c` lines that name it.
fn geofit_path() -> &'static str {
    env!("CARGO_BIN_EXE_geofit")
}

/// Runs `line` with bash in `dir` (stdout discarded, stderr kept) under a wall-clock bound.
fn bash(dir: &Path, line: &str) -> (Output, Duration) {
    let t = Instant::now();
    let mut cmd = Command::new("bash");
    cmd.current_dir(dir)
        .arg("-c")
        .arg(line)
        .env_remove("GEOFIT_MAX_POINTS")
        .env_remove("GEOFIT_MAX_INPUT_BYTES")
        .env_remove("GEOFIT_MAX_CELLS");
    let o = cmd.stdin(Stdio::null()).stdout(Stdio::null()).stderr(Stdio::piped()).output().unwrap();
    (o, t.elapsed())
}

/// The two endless inputs of the issue, each prefixed by `setup` (a `ulimit`, or joining a
/// cgroup): `yes '1 2 3' | rasterize -` and 3 GB of zeros into `info -`. Both end with exit 3
/// and one line naming `limit`, in bounded time, and write nothing.
fn endless_inputs_stop_at(dir: &Path, setup: &str, limit: &str) {
    let g = geofit_path();
    let tif = dir.join("x.tif");
    let line =
        format!("{setup}; timeout 240 bash -c \"yes '1 2 3' 2>/dev/null | '{g}' -q rasterize - --cell 1 -o x.tif\"");
    let (o, took) = bash(dir, &line);
    fails(&o, 3, &["<stdin>", "more than", "points", limit], &tif);
    assert!(took < Duration::from_secs(200), "{took:?}");
    let line = format!("{setup}; timeout 240 bash -c \"head -c 3000000000 /dev/zero | '{g}' info -\"");
    let (o, took) = bash(dir, &line);
    fails(&o, 3, &["<stdin>", "more than", "bytes", limit], &tif);
    assert!(took < Duration::from_secs(200), "{took:?}");
}

/// `ulimit -v` of 1 GiB: before, `yes | rasterize -` aborted in the allocator (SIGABRT) and
/// `info -` said "out of memory"; the budgets now stop both at what the limit leaves, named.
#[test]
fn budgets_follow_ulimit_v() {
    let dir = common::tempdir();
    endless_inputs_stop_at(dir.path(), "ulimit -v 1048576", "ulimit -v");
}

/// A memory cgroup (v2, else v1) this test creates, removed on drop; `None` (with a printed
/// skip) where this process may not create one (not root, no memory controller, read-only
/// `/sys/fs/cgroup`).
struct MemoryCgroup {
    dir: PathBuf,
}

impl MemoryCgroup {
    fn create(bytes: u64) -> Option<MemoryCgroup> {
        let mounts = std::fs::read_to_string("/proc/self/mountinfo").unwrap_or_default();
        let name = format!("geofit-limits-test-{}", std::process::id());
        for line in mounts.lines() {
            let Some((left, right)) = line.split_once(" - ") else { continue };
            let (Some(point), mut fs) = (left.split(' ').nth(4), right.split(' ')) else { continue };
            let (fstype, opts) = (fs.next().unwrap_or(""), fs.nth(1).unwrap_or(""));
            let (limit_file, ok) = match fstype {
                "cgroup2" => (
                    "memory.max",
                    std::fs::read_to_string(Path::new(point).join("cgroup.subtree_control"))
                        .is_ok_and(|c| c.split_whitespace().any(|x| x == "memory")),
                ),
                "cgroup" => ("memory.limit_in_bytes", opts.split(',').any(|o| o == "memory")),
                _ => continue,
            };
            if !ok {
                continue;
            }
            let dir = Path::new(point).join(&name);
            if std::fs::create_dir(&dir).is_err() {
                continue;
            }
            let cg = MemoryCgroup { dir };
            if std::fs::write(cg.dir.join(limit_file), bytes.to_string()).is_ok() {
                return Some(cg);
            }
        }
        eprintln!("SKIP: no memory cgroup can be created here (needs root and a writable /sys/fs/cgroup with the memory controller); the ulimit -v test covers the budgets");
        None
    }
}

impl Drop for MemoryCgroup {
    fn drop(&mut self) {
        // the processes have ended; the kernel may take a moment to let the group go
        for _ in 0..50 {
            if std::fs::remove_dir(&self.dir).is_ok() {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

/// Inside a 1 GiB memory cgroup (`docker -m 1g`): before, both inputs grew until the OOM killer
/// ended geofit without a word (SIGKILL); the budgets now stop them at the cgroup's limit.
#[test]
fn budgets_follow_a_memory_cgroup() {
    let Some(cg) = MemoryCgroup::create(1 << 30) else { return };
    let dir = common::tempdir();
    let join = format!("echo $$ > '{}'", s(&cg.dir.join("cgroup.procs")));
    endless_inputs_stop_at(dir.path(), &join, "the memory cgroup's limit");
}

/// A valid popa3d document of one box building, by `citygml2popa3d` from a CityGML box.
fn box_popa3d(dir: &Path) -> (String, PathBuf) {
    let (x0, y0, z0, x1, y1, z1) = (324100.0, 5729100.0, 50.0, 324110.0, 5729108.0, 56.0);
    let c = |x: f64, y: f64, z: f64| [x, y, z];
    let faces: [(&str, [[f64; 3]; 4]); 6] = [
        ("GroundSurface", [c(x0, y0, z0), c(x0, y1, z0), c(x1, y1, z0), c(x1, y0, z0)]),
        ("RoofSurface", [c(x0, y0, z1), c(x1, y0, z1), c(x1, y1, z1), c(x0, y1, z1)]),
        ("WallSurface", [c(x0, y0, z0), c(x1, y0, z0), c(x1, y0, z1), c(x0, y0, z1)]),
        ("WallSurface", [c(x1, y0, z0), c(x1, y1, z0), c(x1, y1, z1), c(x1, y0, z1)]),
        ("WallSurface", [c(x1, y1, z0), c(x0, y1, z0), c(x0, y1, z1), c(x1, y1, z1)]),
        ("WallSurface", [c(x0, y1, z0), c(x0, y0, z0), c(x0, y0, z1), c(x0, y1, z1)]),
    ];
    let (mut solid, mut bounded) = (String::new(), String::new());
    for (k, (kind, pts)) in faces.iter().enumerate() {
        let ring: Vec<String> =
            pts.iter().chain(&pts[..1]).map(|p| format!("{:.3} {:.3} {:.3}", p[0], p[1], p[2])).collect();
        solid.push_str(&format!("<gml:surfaceMember xlink:href=\"#P{k}\"/>\n"));
        bounded.push_str(&format!(
            "<bldg:boundedBy><bldg:{kind} gml:id=\"S{k}\"><bldg:lod2MultiSurface><gml:MultiSurface><gml:surfaceMember>\
             <gml:Polygon gml:id=\"P{k}\"><gml:exterior><gml:LinearRing><gml:posList srsDimension=\"3\">{}</gml:posList>\
             </gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember></gml:MultiSurface></bldg:lod2MultiSurface>\
             </bldg:{kind}></bldg:boundedBy>\n",
            ring.join(" ")
        ));
    }
    let gml = format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<core:CityModel xmlns:core=\"http://www.opengis.net/citygml/1.0\" \
         xmlns:bldg=\"http://www.opengis.net/citygml/building/1.0\" xmlns:gml=\"http://www.opengis.net/gml\" \
         xmlns:xlink=\"http://www.w3.org/1999/xlink\">\n<gml:boundedBy><gml:Envelope srsName=\"urn:ogc:def:crs:EPSG::25832\" srsDimension=\"3\">\
         <gml:lowerCorner>{x0} {y0} {z0}</gml:lowerCorner><gml:upperCorner>{x1} {y1} {z1}</gml:upperCorner></gml:Envelope></gml:boundedBy>\n\
         <core:cityObjectMember><bldg:Building gml:id=\"B0\"><bldg:lod2Solid><gml:Solid><gml:exterior><gml:CompositeSurface>\n\
         {solid}</gml:CompositeSurface></gml:exterior></gml:Solid></bldg:lod2Solid>\n{bounded}</bldg:Building></core:cityObjectMember>\n</core:CityModel>\n"
    );
    let g = dir.join("box.gml");
    std::fs::write(&g, &gml).unwrap();
    let p = dir.join("box.popa3d");
    let o = common::run(&["-q", "citygml2popa3d", s(&g), "-o", s(&p)], None);
    assert_eq!(common::code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
    (gml, p)
}

/// A 1 MB name where the popa3d reader repeats one (the root element, an unexpected element,
/// the version, an unknown entity in an attribute, a polygon id the template lacks): `adjust`
/// and `popa3d2citygml` said it whole (a 100 MB attribute gave a 104,857,695-byte line).
#[test]
fn long_names_in_popa3d_are_quoted() {
    let dir = common::tempdir();
    let d = dir.path();
    let (_, popa) = box_popa3d(d);
    let text = std::fs::read_to_string(&popa).unwrap();
    let huge = "A".repeat(1_000_000);
    let one = |from: &str, to: String| {
        assert!(text.contains(from), "{from}");
        text.replacen(from, &to, 1)
    };
    let cases = [
        ("root", one("<popa3d ", format!("<{huge} ")).replacen("</popa3d>", &format!("</{huge}>"), 1), 3),
        ("element", one("<solids>", format!("<{huge}/><solids>")), 3),
        ("version", one("version=\"1\">", format!("version=\"{huge}\">")), 3),
        ("entity", one("name=\"B0\"", format!("name=\"&{huge};\"")), 3),
        ("polygon", one("polygon=\"P0\"", format!("polygon=\"{huge}\"")), 1),
    ];
    let template = d.join("box.gml");
    for (what, content, code) in cases {
        let input = d.join(format!("{what}.popa3d"));
        std::fs::write(&input, content).unwrap();
        let (out_p, out_g) = (d.join(format!("{what}.out.popa3d")), d.join(format!("{what}.out.gml")));
        if what != "polygon" {
            // the ids a template does not hold are popa3d2citygml's alone: adjust takes them
            let o = common::run(&["-q", "adjust", s(&input), "-o", s(&out_p)], None);
            fails(&o, code, &[&format!("{what}.popa3d"), "…", "bytes)"], &out_p);
        }
        let o = common::run(&["-q", "popa3d2citygml", s(&input), "--template", s(&template), "-o", s(&out_g)], None);
        let name = if what == "polygon" { "box.gml" } else { &format!("{what}.popa3d") };
        fails(&o, code, &[name, "…", "bytes)"], &out_g);
    }
}

/// NUL bytes in a T-mesh (in its CRS, between elements, in an attribute): `eval` failed with
/// exit 4 "FfiNulError" where GDAL got the CRS; now exit 3 with the input and the position.
#[test]
fn nul_bytes_in_a_tmesh_name_the_input() {
    let dir = common::tempdir();
    let d = dir.path();
    let grid = d.join("g.asc");
    std::fs::write(
        &grid,
        "ncols 4\nnrows 4\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3 4\n2 3 4 5\n3 4 5 6\n4 5 6 7\n",
    )
    .unwrap();
    let mesh = d.join("m.tmesh");
    let o = common::run(&["-q", "fit", s(&grid), "--max-error", "0.5", "-o", s(&mesh)], None);
    assert_eq!(common::code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&mesh).unwrap();
    assert!(text.contains("<crs>") && text.contains("<points") && text.contains("degree=\"3\""), "{text}");
    let cases = [
        ("crs", text.replacen("<crs>", "<crs>EPSG:\u{0}25832", 1)),
        ("between", text.replacen("<points", "\u{0}<points", 1)),
        ("attribute", text.replacen("degree=\"3\"", "degree=\"3\u{0}\"", 1)),
    ];
    let out = d.join("e.tif");
    for (what, content) in cases {
        let input = d.join(format!("{what}.tmesh"));
        std::fs::write(&input, content).unwrap();
        let o = common::run(&["-q", "eval", s(&input), "-o", s(&out)], None);
        let e = fails(&o, 3, &[&format!("{what}.tmesh"), "NUL byte", "line "], &out);
        assert!(!e.contains('\u{0}') && !e.contains("FfiNulError"), "{e:?}");
    }
}

/// `heal` on a file whose only building holds a NaN coordinate or an XLink to nothing said
/// "0 of 1 healed" with exit 0; it now refuses the file as `info`/`validate` do (exit 3 for the
/// NaN, exit 1 for the XLink), naming the place, and writes nothing.
#[test]
fn heal_refuses_a_file_it_cannot_heal() {
    let dir = common::tempdir();
    let d = dir.path();
    let (gml, _) = box_popa3d(d);
    let nan = gml.replacen("324100.000 5729100.000 50.000", "NaN 5729100.000 50.000", 1);
    let xlink = gml.replacen("xlink:href=\"#P0\"", "xlink:href=\"#P99\"", 1);
    assert!(nan != gml && xlink != gml);
    let cases =
        [("nan", nan, 3, "non-finite coordinate 'NaN'"), ("xlink", xlink, 1, "xlink:href=\"#P99\" points to nothing")];
    for (what, content, code, why) in cases {
        let input = d.join(format!("{what}.gml"));
        std::fs::write(&input, content).unwrap();
        let out = d.join(format!("{what}.healed.gml"));
        let o = common::run(&["-q", "heal", s(&input), "-o", s(&out)], None);
        fails(&o, code, &[&format!("{what}.gml:"), why, "nothing healed"], &out);
        // the command that reads it elsewhere gives the same exit
        let o = common::run(&["-q", "validate", "--no-xsd", s(&input)], None);
        assert_eq!(common::code(&o), code, "{what}: validate: {}", String::from_utf8_lossy(&o.stderr));
    }
    // the clean box still heals, exit 0
    let out = d.join("box.healed.gml");
    let o = common::run(&["-q", "heal", s(&d.join("box.gml")), "-o", s(&out)], None);
    assert_eq!(common::code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.exists());
}
