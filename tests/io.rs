//! End-to-end tests of geofit's file outputs and inputs as a GDAL user meets them (issues 13 and
//! 15): no lost data on a full disk or under `ulimit -f`, no output from a failed step, outputs
//! by GDAL driver (COG by default, the input's band type, `-of`/`-co`/`--ot`, refusals before
//! the work), GDAL virtual paths, CRS strings checked like gdalsrsinfo, completions, man page,
//! `--version`. The independent checks are gdalinfo -json, bash -n, man/groff and gdal-config.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn ok(args: &[&str]) -> std::process::Output {
    let o = common::run(args, None);
    assert_eq!(common::code(&o), 0, "geofit {args:?}: {}", stderr(&o));
    o
}

/// Runs geofit and asserts its exit code and that stderr contains every needle.
fn fails(args: &[&str], code: i32, needles: &[&str]) -> String {
    let o = common::run(args, None);
    let e = stderr(&o);
    assert_eq!(common::code(&o), code, "geofit {args:?}: {e}");
    for n in needles {
        assert!(e.contains(n), "geofit {args:?}: expected {n:?} in {e:?}");
    }
    assert!(!e.contains("panicked"), "{e}");
    e
}

/// `n × n` points on a unit grid with pseudo-random heights (a linear congruential sequence, so
/// the raster compresses badly and fits badly): the size of the output is predictable.
fn noisy_points(path: &Path, n: usize) {
    let mut state: u64 = 12345;
    let mut text = String::new();
    for j in 0..n {
        for i in 0..n {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let z = (state >> 11) as f64 / (1u64 << 53) as f64 * 100.0;
            text.push_str(&format!("{}.5 {}.5 {z}\n", i, j));
        }
    }
    std::fs::write(path, text).unwrap();
}

/// `gdalinfo -json` of a raster (the independent reader).
fn gdalinfo(path: &str) -> Value {
    let o = Command::new("gdalinfo").args(["-json", "-mdd", "all", path]).output().expect("gdalinfo");
    assert!(o.status.success(), "gdalinfo {path}: {}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

fn temp_leftovers(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".geofit"))
        .collect()
}

/// Issue 13, finding 1: on a full disk `rasterize -o r.tif` exited 0 and replaced a valid r.tif
/// with a truncated one (GDAL's strip-write errors were not checked). Now: exit 4 naming the
/// file and the cause, the old r.tif byte for byte intact, no temporary left — for the COG
/// default, plain GTiff and an ASCII grid. The disk is a 64 KiB tmpfs mounted in a private mount
/// namespace (`unshare -rm`: root, or an unprivileged user namespace).
#[test]
fn full_disk_keeps_the_old_output() {
    if !common::tool("unshare") {
        return;
    }
    let tmp = common::tempdir();
    let d = tmp.path();
    let small = d.join("small.xyz");
    noisy_points(&small, 4);
    let big = d.join("big.xyz");
    noisy_points(&big, 150); // 22,500 noisy Float64 cells ≈ 170 KiB compressed > 64 KiB
    let probe = Command::new("unshare")
        .args(["-rm", "sh", "-c", "mkdir -p \"$0\" && mount -t tmpfs -o size=64k tmpfs \"$0\""])
        .arg(d.join("probe"))
        .output()
        .unwrap();
    if !probe.status.success() {
        let why = String::from_utf8_lossy(&probe.stderr);
        assert!(!common::in_ci(), "CI runs as root and can mount a tmpfs: {why}");
        eprintln!("SKIP: cannot mount a tmpfs in a private namespace here: {why}");
        return;
    }
    let bin = env!("CARGO_BIN_EXE_geofit");
    for (name, extra) in [("r.tif", ""), ("g.tif", "-of GTiff"), ("r.asc", "")] {
        let mnt = d.join(format!("mnt-{name}"));
        std::fs::create_dir(&mnt).unwrap();
        let script = format!(
            "set -e; mount -t tmpfs -o size=64k tmpfs {m}; \
             {bin} -q rasterize {small} --cell 1 -o {m}/{name} {extra}; cp {m}/{name} {d}/before-{name}; \
             set +e; {bin} -q rasterize {big} --cell 1 -o {m}/{name} {extra} 2> {d}/err-{name}; echo $? > {d}/code-{name}; \
             cp {m}/{name} {d}/after-{name}; ls -A {m} > {d}/ls-{name}",
            m = s(&mnt),
            small = s(&small),
            big = s(&big),
            d = s(d),
        );
        let o = Command::new("unshare").args(["-rm", "sh", "-c", &script]).output().unwrap();
        assert!(o.status.success(), "{name}: {}", String::from_utf8_lossy(&o.stderr));
        let read = |f: &str| std::fs::read_to_string(d.join(format!("{f}-{name}"))).unwrap();
        let err = read("err");
        assert_eq!(read("code").trim(), "4", "{name}: {err}");
        assert!(
            err.contains(name) && (err.contains("No space left on device") || err.contains("disk full")),
            "{name}: {err}"
        );
        assert!(!err.contains(".geofit-raster"), "{name}: the message names the temporary file: {err}");
        assert_eq!(err.lines().count(), 1, "{name}: one line: {err}");
        let before = std::fs::read(d.join(format!("before-{name}"))).unwrap();
        assert_eq!(
            before,
            std::fs::read(d.join(format!("after-{name}"))).unwrap(),
            "{name}: the old output was changed"
        );
        assert!(raster_io::read_raster(&d.join(format!("after-{name}"))).is_ok());
        let listing = read("ls");
        assert!(!listing.contains(".geofit"), "{name}: temporary files left: {listing}");
    }
}

/// Issue 13, finding 7: `ulimit -f` sent SIGXFSZ, which killed geofit silently and left its
/// `.geofit-*.tmp`. Now the signal is ignored: the write fails with EFBIG, exit 4 with a line
/// naming the file, nothing left — through GDAL (rasterize) and through geofit's own writer
/// (unwarp --points writes XYZ text).
#[test]
fn file_size_limit_is_an_error_not_a_kill() {
    if !common::tool("bash") {
        return;
    }
    let tmp = common::tempdir();
    let d = tmp.path();
    let pts = d.join("pts.xyz");
    noisy_points(&pts, 120);
    let warped = d.join("w.tif");
    let small = d.join("small.xyz");
    noisy_points(&small, 12);
    let r = d.join("small.tif");
    ok(&["-q", "rasterize", s(&small), "--cell", "1", "-o", s(&r)]);
    ok(&["-q", "warp", s(&r), "-o", s(&warped), "--spacing", "3"]);
    let bin = env!("CARGO_BIN_EXE_geofit");
    for (out, cmd) in [
        ("out.tif", format!("{bin} -q rasterize {} --cell 1 -o OUT", s(&pts))),
        ("out.xyz", format!("{bin} -q unwarp {} --points {} -o OUT", s(&warped), s(&pts))),
    ] {
        let target = d.join(out);
        let o = Command::new("bash")
            .arg("-c")
            .arg(format!("ulimit -f 16; exec {}", cmd.replace("OUT", s(&target))))
            .output()
            .unwrap();
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(4), "{out}: killed by a signal or wrong code ({:?}): {e}", o.status);
        assert!(e.contains(out) && e.contains("File too large"), "{out}: {e}");
        assert!(!target.exists(), "{out}: a truncated output was left");
        assert!(temp_leftovers(d).is_empty(), "{out}: {:?}", temp_leftovers(d));
    }
}

/// Issue 15: a failed step left its output (`fit` stopping at --max-points wrote the .tmesh,
/// `diff --check` over tolerance wrote the PNGs), so the next `make` saw nothing to do. Now
/// nothing is written unless --keep-partial; a file already there stays as it was; the report
/// is still written.
#[test]
fn failed_steps_write_no_output_unless_keep_partial() {
    let tmp = common::tempdir();
    let d = tmp.path();
    let pts = d.join("pts.xyz");
    noisy_points(&pts, 12);
    let r = d.join("r.tif");
    ok(&["-q", "rasterize", s(&pts), "--cell", "1", "-o", s(&r)]);
    let mesh = d.join("m.tmesh");
    let report = d.join("fit.json");
    let fit = [
        "-q",
        "fit",
        s(&r),
        "--max-error",
        "0.001",
        "--max-points",
        "20",
        "--device",
        "cpu",
        "-o",
        s(&mesh),
        "--report",
        s(&report),
    ];
    fails(&fit, 1, &["control-point cap", "m.tmesh not written", "--keep-partial"]);
    assert!(!mesh.exists(), "a failed fit wrote its mesh");
    let rep: Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert!(rep["stop"].to_string().contains("20"), "the report says where it stopped: {}", rep["stop"]);
    // an older mesh is left alone
    std::fs::write(&mesh, b"older").unwrap();
    fails(&fit, 1, &["not written"]);
    assert_eq!(std::fs::read(&mesh).unwrap(), b"older");
    // --keep-partial (global, before or after the subcommand) writes it, still exit 1
    let mut keep = fit.to_vec();
    keep.push("--keep-partial");
    fails(&keep, 1, &["control-point cap"]);
    let text = std::fs::read_to_string(&mesh).unwrap();
    assert!(text.contains("<") && text.len() > 100, "{text}");

    // diff --check: the statistics are printed, the pictures are not written
    let pts2 = d.join("pts2.xyz");
    let shifted: String = std::fs::read_to_string(&pts)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            format!("{} {} {}\n", v[0], v[1], v[2] + 5.0)
        })
        .collect();
    std::fs::write(&pts2, shifted).unwrap();
    let r2 = d.join("r2.tif");
    ok(&["-q", "rasterize", s(&pts2), "--cell", "1", "-o", s(&r2)]);
    let png = d.join("e.png");
    let hist = d.join("h.png");
    let diff = ["diff", s(&r), s(&r2), "--tolerance", "1", "--check", "--png", s(&png), "--hist", s(&hist)];
    let o = common::run(&diff, None);
    assert_eq!(common::code(&o), 1, "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("cells compared"), "the statistics still go out");
    assert!(!png.exists() && !hist.exists(), "a failed check wrote its pictures");
    let mut keep = vec!["--keep-partial"];
    keep.extend(diff);
    let o = common::run(&keep, None);
    assert_eq!(common::code(&o), 1);
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG") && hist.exists());
    // within tolerance: exit 0 and written as before
    std::fs::remove_file(&png).unwrap();
    ok(&["diff", s(&r), s(&r), "--check", "--png", s(&png)]);
    assert!(png.exists());
    assert!(temp_leftovers(d).is_empty());
}

/// Issue 15: GeoTIFF output was striped Float64 whatever the input. Now: COG by default
/// (gdalinfo's IMAGE_STRUCTURE LAYOUT=COG, DEFLATE), the input's band type kept (Float32 in →
/// Float32 out), `-of`, `-co`, `--ot` as GDAL spells them, and formats that cannot hold the
/// result refused before the work with exit 2 naming the driver.
#[test]
fn outputs_by_driver() {
    if !common::tool("gdalinfo") || !common::tool("gdal_translate") {
        return;
    }
    let tmp = common::tempdir();
    let d = tmp.path();
    let pts = d.join("pts.xyz");
    noisy_points(&pts, 40);
    let p = |n: &str| d.join(n).to_str().unwrap().to_string();
    let structure = |f: &str| gdalinfo(f)["metadata"]["IMAGE_STRUCTURE"].clone();
    let band_type = |f: &str| gdalinfo(f)["bands"][0]["type"].as_str().unwrap().to_string();

    ok(&["-q", "rasterize", s(&pts), "--cell", "1", "-o", &p("cog.tif")]);
    let st = structure(&p("cog.tif"));
    assert_eq!(st["LAYOUT"], "COG", "{st}");
    assert_eq!(st["COMPRESSION"], "DEFLATE", "{st}");
    assert_eq!(band_type(&p("cog.tif")), "Float64");
    // stdout is a COG too
    let o = ok(&["-q", "rasterize", s(&pts), "--cell", "1"]);
    std::fs::write(p("stdout.tif"), &o.stdout).unwrap();
    assert_eq!(structure(&p("stdout.tif"))["LAYOUT"], "COG");
    // -co replaces a default, -of GTiff is a plain GeoTIFF, --ot float32
    ok(&["-q", "rasterize", s(&pts), "--cell", "1", "-o", &p("lzw.tif"), "-co", "COMPRESS=LZW", "-ot", "Float32"]);
    assert_eq!(structure(&p("lzw.tif"))["COMPRESSION"], "LZW");
    assert_eq!(band_type(&p("lzw.tif")), "Float32");
    ok(&["-q", "rasterize", s(&pts), "--cell", "1", "-o", &p("plain.tif"), "-of", "GTiff"]);
    let st = structure(&p("plain.tif"));
    assert!(st.get("LAYOUT").is_none(), "{st}");
    assert_eq!(st["COMPRESSION"], "DEFLATE");

    // the input's band type is kept: Float32 in, Float32 out (warp, unwarp, eval --like)
    let st =
        Command::new("gdal_translate").args(["-q", "-ot", "Float32", &p("cog.tif"), &p("f32.tif")]).status().unwrap();
    assert!(st.success());
    ok(&["-q", "warp", &p("f32.tif"), "-o", &p("w32.tif"), "--spacing", "5"]);
    assert_eq!(band_type(&p("w32.tif")), "Float32");
    assert_eq!(structure(&p("w32.tif"))["LAYOUT"], "COG");
    ok(&["-q", "unwarp", &p("w32.tif"), "-o", &p("u32.tif")]);
    assert_eq!(band_type(&p("u32.tif")), "Float32");
    ok(&["-q", "fit", &p("f32.tif"), "--max-error", "50", "--device", "cpu", "-o", &p("m.tmesh")]);
    ok(&["-q", "eval", &p("m.tmesh"), "--like", &p("f32.tif"), "--device", "cpu", "-o", &p("e32.tif")]);
    assert_eq!(band_type(&p("e32.tif")), "Float32");
    ok(&["-q", "eval", &p("m.tmesh"), "--device", "cpu", "-o", &p("e64.tif")]);
    assert_eq!(band_type(&p("e64.tif")), "Float64");
    // the values read back equal the Float32 ones
    let a = raster_io::read_raster(&d.join("f32.tif")).unwrap();
    let b = raster_io::read_raster(&d.join("u32.tif")).unwrap();
    assert_eq!((a.width, a.height), (b.width, b.height));

    // refused before the work, exit 2, naming the driver and why; nothing written
    let refused: [(&str, Vec<&str>, &[&str]); 6] = [
        ("x.vrt", vec![], &["VRT", "references to other files"]),
        ("x.png", vec![], &["PNG", "cut to integers"]),
        ("x.gpkg", vec![], &["GPKG", "Float64", "--ot float32"]),
        ("y.tif", vec!["-co", "NOSUCH=1"], &["COG has no creation option NOSUCH"]),
        ("y.tif", vec!["-of", "NoSuchDriver"], &["NoSuchDriver", "no such driver"]),
        ("y.tif", vec!["-co", "COMPRESS"], &["expected KEY=VALUE"]),
    ];
    for (out, extra, needles) in refused {
        let mut args = vec!["rasterize", s(&pts), "--cell", "1"];
        let target = p(out);
        args.extend(["-o", target.as_str()]);
        args.extend(extra);
        let e = fails(&args, 2, needles);
        assert!(!e.contains("read "), "refused after reading the input: {e}");
        assert!(!d.join(out).exists());
    }
    // a format that can hold Float32: GeoPackage with --ot float32, read back by gdalinfo
    ok(&["-q", "rasterize", s(&pts), "--cell", "1", "-o", &p("x.gpkg"), "--ot", "float32"]);
    assert_eq!(gdalinfo(&p("x.gpkg"))["driverShortName"], "GPKG");
    // an ASCII grid by -of, whatever the extension
    ok(&["-q", "rasterize", s(&pts), "--cell", "1", "-o", &p("grid.txt"), "-of", "AAIGrid"]);
    assert_eq!(gdalinfo(&p("grid.txt"))["driverShortName"], "AAIGrid");
    assert!(temp_leftovers(d).is_empty());
}

/// Issue 15: `/vsigzip/` and `/vsizip/` paths were rejected as "No such file" by a Rust-side
/// existence check. Now every command reading a raster reads what GDAL reads.
#[test]
fn gdal_virtual_paths_are_read() {
    if !common::tool("gzip") || !common::tool("python3") {
        return;
    }
    let tmp = common::tempdir();
    let d = tmp.path();
    let pts = d.join("pts.xyz");
    noisy_points(&pts, 10);
    let r = d.join("r.tif");
    ok(&["-q", "rasterize", s(&pts), "--cell", "1", "-o", s(&r)]);
    let gz: PathBuf = d.join("r.tif.gz");
    let st = Command::new("sh").arg("-c").arg(format!("gzip -c {} > {}", s(&r), s(&gz))).status().unwrap();
    assert!(st.success());
    let zip = d.join("r.zip");
    let st = common::python()
        .args([
            "-c",
            "import sys, zipfile; zipfile.ZipFile(sys.argv[1], 'w').write(sys.argv[2], 'in/r.tif')",
            s(&zip),
            s(&r),
        ])
        .status()
        .unwrap();
    assert!(st.success());
    let vgz = format!("/vsigzip/{}", s(&gz));
    let vzip = format!("/vsizip/{}/in/r.tif", s(&zip));
    for v in [&vgz, &vzip] {
        let o = ok(&["diff", v, s(&r), "--json"]);
        let rep: Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(rep["cells_compared"], 100, "{v}: {rep}");
        assert_eq!(rep["max_abs"], 0.0, "{v}: {rep}");
    }
    let w = d.join("w.tif");
    ok(&["-q", "warp", &vgz, "-o", s(&w), "--spacing", "3"]);
    let info: Value = serde_json::from_slice(&ok(&["info", &vgz, "--json"]).stdout).unwrap();
    assert_eq!(
        (info["kind"].as_str(), info["width"].as_u64(), info["valid_count"].as_u64()),
        (Some("raster"), Some(10), Some(100)),
        "{info}"
    );
    ok(&["-q", "fit", &vzip, "--max-error", "100", "--device", "cpu", "-o", s(&d.join("m.tmesh"))]);
    // a virtual path to nothing: exit 3 with GDAL's reason, not a Rust-side guess
    fails(&["diff", &format!("/vsigzip/{}/missing.gz", s(d)), s(&r)], 3, &["missing.gz"]);
    // writing to a virtual path is refused before the work
    fails(&["rasterize", s(&pts), "--cell", "1", "-o", &format!("/vsigzip/{}/o.tif.gz", s(d))], 2, &["virtual path"]);
}

/// Issue 15: `--t-srs foo` was accepted (PROJ read it as a Bessel longlat), and the README's
/// lon/lat soundings at `--cell 25` made a 1×2 grid with exit 0. Now CRS strings are read as
/// gdalsrsinfo reads them (exit 2 naming the string), degrees with a metre-sized cell are a
/// usage error with a hint, and `--s-srs`/`--t-srs` grid the soundings in metres.
#[test]
fn crs_strings_and_cell_units() {
    let tmp = common::tempdir();
    let d = tmp.path();
    let out = d.join("o.tif");
    let o = s(&out);
    let pts = d.join("p.xyz");
    std::fs::write(&pts, "0 0 1\n10 0 2\n0 10 3\n10 10 4\n").unwrap();
    // gdalsrsinfo refuses `foo`; so do we, for rasterize and export
    if common::tool("gdalsrsinfo") {
        let g = Command::new("gdalsrsinfo").arg("foo").output().unwrap();
        assert!(!g.status.success(), "gdalsrsinfo accepts foo?");
    }
    fails(
        &["rasterize", s(&pts), "--cell", "1", "-o", o, "--t-srs", "foo", "--s-srs", "EPSG:25832"],
        2,
        &["--t-srs", "'foo'"],
    );
    fails(
        &["rasterize", s(&pts), "--cell", "1", "-o", o, "--s-srs", "EPSG:99999999"],
        2,
        &["--s-srs", "'EPSG:99999999'"],
    );
    fails(&["rasterize", s(&pts), "--cell", "1", "-o", o, "--t-srs", "EPSG:25832"], 2, &["--s-srs"]);
    if let Some(gml) = common::fixture("citygml/ogc-building/CityGMLv2/Building_LOD2-EPSG25832.gml") {
        fails(&["export", s(&gml), "-o", s(&d.join("x.glb")), "--t-srs", "foo"], 2, &["--t-srs", "'foo'"]);
    }
    let Some(ship) = common::fixture("terrain/gmt_ship_03.txt") else { return };
    // lon/lat degrees (no CRS declared) at a metre-sized cell
    fails(
        &["rasterize", s(&ship), "--cell", "25", "-o", o],
        2,
        &["--cell 25", "degrees", "1×2", "--t-srs", "declare their CRS with --s-srs"],
    );
    fails(&["rasterize", s(&ship), "--cell", "25", "-o", o, "--s-srs", "EPSG:4326"], 2, &["geographic CRS"]);
    assert!(!out.exists());
    // local coordinates in the same numeric range are not taken for degrees: GMT's Table 5.11
    // (52 points, 0…6.3 units) at --cell 1 is a 7×7 grid
    if let Some(table) = common::fixture("terrain/gmt_Table_5_11.txt") {
        ok(&["-q", "rasterize", s(&table), "--cell", "1", "-o", o]);
    }
    // a projected --s-srs says they are not degrees
    ok(&["-q", "rasterize", s(&ship), "--cell", "25", "-o", o, "--s-srs", "EPSG:32725"]);
    // in degrees it is fine; in metres through --t-srs (UTM 25S covers 36°–30° W)
    ok(&["-q", "rasterize", s(&ship), "--cell", "0.05", "-o", o]);
    ok(&["-q", "rasterize", s(&ship), "--cell", "5000", "-o", o, "--s-srs", "EPSG:4326", "--t-srs", "EPSG:32725"]);
    if !common::tool("gdalinfo") || !common::tool("gdaltransform") {
        return;
    }
    let info = gdalinfo(o);
    let wkt = info["coordinateSystem"]["wkt"].as_str().unwrap();
    assert!(wkt.contains("UTM zone 25S"), "{wkt}");
    // the first sounding, transformed by gdaltransform, lies inside the grid
    let t = Command::new("sh")
        .arg("-c")
        .arg("echo 326.12501 -8.68370 | gdaltransform -s_srs EPSG:4326 -t_srs EPSG:32725")
        .output()
        .unwrap();
    let xy: Vec<f64> =
        String::from_utf8_lossy(&t.stdout).split_whitespace().take(2).map(|v| v.parse().unwrap()).collect();
    let gt: Vec<f64> = info["geoTransform"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let size: Vec<f64> = info["size"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!(xy[0] >= gt[0] && xy[0] <= gt[0] + size[0] * gt[1], "{xy:?} {gt:?} {size:?}");
    assert!(xy[1] <= gt[3] && xy[1] >= gt[3] + size[1] * gt[5], "{xy:?} {gt:?} {size:?}");
    assert!(size[0] > 50.0 && size[1] > 50.0, "a real grid now: {size:?}");
}

/// Issue 15: shell completions and a man page generated from the CLI definition; --version names
/// the GDAL and PROJ it runs on.
#[test]
fn completions_man_page_and_version() {
    if common::tool("bash") {
        let o = ok(&["completions", "bash"]);
        let tmp = common::tempdir();
        let f = tmp.path().join("geofit.bash");
        std::fs::write(&f, &o.stdout).unwrap();
        let st = Command::new("bash").args(["-n", s(&f)]).output().unwrap();
        assert!(st.status.success(), "bash -n: {}", String::from_utf8_lossy(&st.stderr));
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            text.contains("rasterize") && text.contains("--max-error") && text.contains("--keep-partial"),
            "incomplete"
        );
        // the completion works: COMPREPLY for `geofit ras<TAB>`
        let st = Command::new("bash")
            .arg("-c")
            .arg(format!("source {}; COMP_WORDS=(geofit ras); COMP_CWORD=1; COMP_LINE='geofit ras'; COMP_POINT=10; _geofit geofit ras geofit; echo \"${{COMPREPLY[@]}}\"", s(&f)))
            .output()
            .unwrap();
        assert!(String::from_utf8_lossy(&st.stdout).contains("rasterize"), "{}", String::from_utf8_lossy(&st.stderr));
    }
    for shell in ["zsh", "fish", "elvish", "powershell"] {
        assert!(!ok(&["completions", shell]).stdout.is_empty());
    }
    fails(&["completions", "tcsh"], 2, &["tcsh"]);
    let page = ok(&["man"]).stdout;
    let roff = String::from_utf8_lossy(&page);
    assert!(roff.starts_with(".ie") || roff.contains(".TH geofit"), "{}", &roff[..roff.len().min(200)]);
    let fit = String::from_utf8_lossy(&ok(&["man", "fit"]).stdout).into_owned();
    assert!(fit.contains(".TH geofit-fit") && fit.contains("max\\-error"), "{}", &fit[..fit.len().min(400)]);
    fails(&["man", "nosuch"], 2, &["nosuch", "rasterize"]);
    if common::tool("groff") {
        let mut child = Command::new("groff")
            .args(["-man", "-Tutf8"])
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        use std::io::Write;
        child.stdin.take().unwrap().write_all(fit.as_bytes()).unwrap();
        let o = child.wait_with_output().unwrap();
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success() && text.contains("max") && text.contains("error") && text.contains("geofit"),
            "{text}"
        );
    }
    let v = String::from_utf8_lossy(&ok(&["--version"]).stdout).into_owned();
    assert!(v.starts_with(&format!("geofit {}", env!("CARGO_PKG_VERSION"))), "{v}");
    if common::tool("gdal-config") {
        let g = Command::new("gdal-config").arg("--version").output().unwrap();
        let gv = String::from_utf8_lossy(&g.stdout).trim().to_string();
        assert!(v.contains(&format!("GDAL {gv}")), "{v} vs gdal-config {gv}");
    }
    if common::tool("pkg-config") {
        let p = Command::new("pkg-config").args(["--modversion", "proj"]).output().unwrap();
        let pv = String::from_utf8_lossy(&p.stdout).trim().to_string();
        assert!(pv.is_empty() || v.contains(&format!("PROJ {pv}")), "{v} vs PROJ {pv}");
    }
    assert!(v.contains("OpenCL: "), "{v}");
}

/// Whether `path` (dots between keys, `[]` for every array element, `*` for every map value)
/// names something in `v`: at least one element for arrays and maps, and nothing below a null.
fn key_resolves(v: &Value, path: &[&str]) -> bool {
    let Some((head, rest)) = path.split_first() else { return true };
    match (*head, v) {
        (_, Value::Null) => true,
        ("*", Value::Object(m)) => m.is_empty() || m.values().any(|x| key_resolves(x, rest)),
        (k, Value::Object(m)) => {
            let (name, each) = k.strip_suffix("[]").map_or((k, false), |n| (n, true));
            match m.get(name) {
                Some(Value::Array(a)) if each => a.is_empty() || a.iter().any(|x| key_resolves(x, rest)),
                Some(x) if !each => key_resolves(x, rest),
                _ => false,
            }
        }
        _ => false,
    }
}

/// A JSON report's `schema` is `geofit-…/N` and each of its `units` keys names a quantity the
/// report holds (so a renamed field cannot leave a stale unit behind).
fn check_schema_and_units(what: &str, r: &Value, schema: &str) {
    assert_eq!(r["schema"], schema, "{what}: {r}");
    let units = r["units"].as_object().unwrap_or_else(|| panic!("{what}: no units object"));
    for (key, unit) in units {
        assert!(unit.as_str().is_some_and(|u| !u.is_empty()), "{what}: unit of {key}");
        assert!(
            key_resolves(r, &key.split('.').collect::<Vec<_>>()),
            "{what}: units name {key}, which the report lacks"
        );
    }
}

/// Issue 15: JSON reports carried no units and no schema/version key. Now every report a
/// command writes (`--report`, `--json`) starts with `schema` and `units`; checked for the
/// terrain, buildings and info/validate reports on shipped and generated data.
#[test]
fn json_reports_carry_schema_and_units() {
    let (Some(dem), Some(gml)) = (
        common::fixture("terrain/giswqs-lidar_dem.tif"),
        common::fixture("citygml/v2/FZK-Haus-LoD2-KIT-IAI-KHH-B36-V1.gml"),
    ) else {
        return;
    };
    if !common::tool("gdal_translate") {
        return;
    }
    let tmp = common::tempdir();
    let d = tmp.path();
    let read = |p: &Path| -> Value { serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap() };
    let stdout_json = |args: &[&str]| -> Value { serde_json::from_slice(&ok(args).stdout).unwrap() };
    let small = d.join("small.tif");
    let st = Command::new("gdal_translate")
        .args(["-q", "-srcwin", "0", "0", "40", "40", s(&dem), s(&small)])
        .status()
        .unwrap();
    assert!(st.success());
    let (tm, rep) = (d.join("s.tmb"), d.join("fit.json"));
    ok(&["-q", "fit", s(&small), "--max-error", "0.5", "-o", s(&tm), "--report", s(&rep)]);
    check_schema_and_units("fit", &read(&rep), "geofit-fit-report/1");
    let fitted = d.join("f.tif");
    ok(&["-q", "eval", s(&tm), "--like", s(&small), "-o", s(&fitted)]);
    let diff = stdout_json(&["-q", "diff", s(&small), s(&fitted), "--json", "--z-unit", "ft"]);
    check_schema_and_units("diff", &diff, "geofit-diff-report/1");
    assert_eq!(diff["units"]["max_abs"], "ft", "--z-unit names the height unit");
    let pts = d.join("p.xyz");
    noisy_points(&pts, 12);
    let rrep = d.join("rasterize.json");
    ok(&["-q", "rasterize", s(&pts), "--cell", "1", "-o", s(&d.join("r.tif")), "--report", s(&rrep)]);
    check_schema_and_units("rasterize", &read(&rrep), "geofit-rasterize-report/1");
    for (what, input) in
        [("info raster", s(&small)), ("info points", s(&pts)), ("info citygml", s(&gml)), ("info tmesh", s(&tm))]
    {
        check_schema_and_units(what, &stdout_json(&["-q", "info", "--json", input]), "geofit-info/1");
    }
    check_schema_and_units("validate", &stdout_json(&["-q", "validate", "--json", s(&gml)]), "geofit-validate/1");
    let (hrep, erep) = (d.join("heal.json"), d.join("export.json"));
    ok(&["-q", "heal", s(&gml), "-o", s(&d.join("h.gml")), "--report", s(&hrep)]);
    check_schema_and_units("heal", &read(&hrep), "geofit-heal-report/1");
    ok(&["-q", "export", s(&gml), "-o", s(&d.join("h.glb")), "--report", s(&erep)]);
    check_schema_and_units("export", &read(&erep), "geofit-export-report/1");
    let (p1, p2, crep, arep, brep) =
        (d.join("a.popa3d"), d.join("b.popa3d"), d.join("c.json"), d.join("a.json"), d.join("b.json"));
    ok(&["-q", "citygml2popa3d", s(&gml), "-o", s(&p1), "--report", s(&crep)]);
    check_schema_and_units("citygml2popa3d", &read(&crep), "geofit-citygml2popa3d-report/1");
    ok(&["-q", "adjust", s(&p1), "-o", s(&p2), "--report", s(&arep)]);
    check_schema_and_units("adjust", &read(&arep), "geofit-adjust-report/1");
    ok(&["-q", "popa3d2citygml", s(&p2), "--template", s(&gml), "-o", s(&d.join("back.gml")), "--report", s(&brep)]);
    check_schema_and_units("popa3d2citygml", &read(&brep), "geofit-popa3d2citygml-report/1");
    // the checker itself: a unit naming a missing key is caught
    let bad: Value = serde_json::json!({ "schema": "geofit-x/1", "units": { "gone": "m" }, "here": 1.0 });
    assert!(!key_resolves(&bad, &["gone"]) && key_resolves(&bad, &["here"]));
}

/// Issue 15: `-o` into a missing directory failed with exit 4 ("internal") after all the work,
/// naming a temporary file. Now every file output (`-o`, `--report`, `--png`, `--hist`,
/// `--outliers-csv`, `--vtk`) of every subcommand is checked before the work: exit 2 naming
/// the option and the missing directory, nothing written anywhere.
#[test]
fn output_paths_are_checked_before_the_work() {
    let tmp = common::tempdir();
    let d = tmp.path();
    let pts = d.join("p.xyz");
    noisy_points(&pts, 6);
    let r = d.join("r.tif");
    ok(&["-q", "rasterize", s(&pts), "--cell", "1", "-o", s(&r)]);
    let missing = d.join("no/such/dir");
    let m = |name: &str| missing.join(name).to_str().unwrap().to_string();
    let (tm, png, rep, csv, vtk, out) = (m("x.tmb"), m("e.png"), m("r.json"), m("o.csv"), m("f.vtk"), d.join("ok.tmb"));
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["fit", s(&r), "--max-error", "1", "-o", &tm], "-o"),
        (vec!["fit", s(&r), "--max-error", "1", "-o", s(&out), "--report", &rep], "--report"),
        (vec!["fit", s(&r), "--max-error", "1", "-o", s(&out), "--outliers-csv", &csv], "--outliers-csv"),
        (vec!["diff", s(&r), s(&r), "--png", &png], "--png"),
        (vec!["diff", s(&r), s(&r), "--hist", &png], "--hist"),
        (vec!["implicit", "interpolate", s(&pts), "-o", s(&out), "--vtk", &vtk], "--vtk"),
        (vec!["rasterize", s(&pts), "--cell", "1", "-o", &tm], "-o"),
    ];
    for (args, flag) in cases {
        let e = fails(&args, 2, &[&format!("{flag} {}", missing.display()), "does not exist"]);
        assert_eq!(e.trim().lines().count(), 1, "{args:?}: {e}");
    }
    assert!(!out.exists() && temp_leftovers(d).is_empty(), "nothing written");
    fails(&["fit", s(&r), "--max-error", "1", "-o", s(d)], 2, &["is a directory"]);
    // the statistics go to stdout: a picture there would be mixed into them
    fails(&["diff", s(&r), s(&r), "--png", "-"], 2, &["--png -: stdout carries the statistics"]);
}
