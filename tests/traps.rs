//! Traps (issue 41): output paths, file kinds and pipes. Each case builds what a user really
//! sends and checks one of two things: the answer equals an independent computation, or the
//! exit is 2/3 with one stderr line, no file at `-o`, and every input byte-identical after.
//! The other trap suites: `traps_points` (point text), `traps_raster` (units, bands, no-data),
//! `traps_buildings` (geographic CRSs, vertical datums).

mod common;

use std::path::{Path, PathBuf};

use common::{code, run};

/// A 5 × 4 ESRI ASCII grid, metres: a small raster every raster command reads.
const GRID: &str = "ncols 5\nnrows 4\nxllcorner 1000\nyllcorner 2000\ncellsize 10\nNODATA_value -9999\n\
1 2 3 4 5\n2 3 4 5 6\n3 4 5 6 7\n4 5 6 7 8\n";

const GML: &str = "citygml/v2/FZK-Haus-LoD2-KIT-IAI-KHH-B36-V1.gml";

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A refusal (see [`common::refused`]).
#[track_caller]
fn refused(args: &[&str], stdin: Option<&[u8]>, exit: i32, words: &[&str], out: Option<&Path>, untouched: &[&Path]) {
    common::refused(args, stdin, exit, words, out, untouched);
}

#[test]
fn an_output_naming_its_input_is_refused_and_the_input_kept() {
    let dir = common::tempdir();
    let grid = write(dir.path(), "g2.asc", GRID.as_bytes());
    refused(
        &["fit", s(&grid), "--max-error", "5", "-o", s(&grid)],
        None,
        2,
        &["names the input", "g2.asc"],
        None,
        &[&grid],
    );
    // a hard link and a symlink to the input are the same file under another name
    let hard = dir.path().join("hard.tmesh");
    std::fs::hard_link(&grid, &hard).unwrap();
    refused(&["fit", s(&grid), "--max-error", "5", "-o", s(&hard)], None, 2, &["same file"], None, &[&grid, &hard]);
    let link = dir.path().join("link.tmesh");
    std::os::unix::fs::symlink(&grid, &link).unwrap();
    refused(&["fit", s(&grid), "--max-error", "5", "-o", s(&link)], None, 2, &["same file"], None, &[&grid]);
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "the symlink itself stays");
    // another output option naming the input
    refused(&["fit", s(&grid), "--max-error", "5", "--report", s(&grid)], None, 2, &["--report"], None, &[&grid]);
    // two outputs naming one file
    let out = dir.path().join("out.tmesh");
    refused(
        &["fit", s(&grid), "--max-error", "5", "-o", s(&out), "--report", s(&out)],
        None,
        2,
        &["name one file"],
        Some(&out),
        &[&grid],
    );
}

#[test]
fn a_template_named_as_output_is_refused() {
    let Some(gml) = common::fixture(GML) else { return };
    let dir = common::tempdir();
    let copy = write(dir.path(), "house.gml", &std::fs::read(&gml).unwrap());
    let popa = dir.path().join("house.popa3d");
    let o = run(&["citygml2popa3d", s(&copy), "-o", s(&popa)], None);
    assert_eq!(code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
    refused(
        &["popa3d2citygml", s(&popa), "--template", s(&copy), "-o", s(&copy)],
        None,
        2,
        &["(template)", "names the input"],
        None,
        &[&copy, &popa],
    );
}

#[test]
fn an_output_extension_of_another_format_is_refused() {
    let dir = common::tempdir();
    let grid = write(dir.path(), "g.asc", GRID.as_bytes());
    for ext in ["tif", "glb", "asc"] {
        let out = dir.path().join(format!("x.{ext}"));
        refused(
            &["fit", s(&grid), "--max-error", "5", "-o", s(&out)],
            None,
            2,
            &["T-mesh", ".tmesh", ".tmb"],
            Some(&out),
            &[&grid],
        );
    }
    let Some(gml) = common::fixture(GML) else { return };
    let glb = dir.path().join("h.glb");
    refused(&["heal", s(&gml), "-o", s(&glb)], None, 2, &["CityGML", ".gml"], Some(&glb), &[&gml]);
    let p = dir.path().join("p.gml");
    refused(&["citygml2popa3d", s(&gml), "-o", s(&p)], None, 2, &["popa3d", ".popa3d"], Some(&p), &[&gml]);
}

#[test]
fn the_right_extension_or_none_still_writes() {
    let dir = common::tempdir();
    let grid = write(dir.path(), "g.asc", GRID.as_bytes());
    for name in ["ok.tmesh", "ok.TMB", "noext"] {
        let out = dir.path().join(name);
        let o = run(&["fit", s(&grid), "--max-error", "5", "-o", s(&out)], None);
        assert_eq!(code(&o), 0, "{name}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(out.exists(), "{name} written");
    }
    // a device is no input's replacement, and stays a device: as root, the rename of the
    // atomic writers replaced the node with a regular file. Root makes its own null device
    // here, so a regression cannot take the host's /dev/null with it.
    let own_null = dir.path().join("null");
    let made = std::process::Command::new("mknod")
        .args(["-m", "666", s(&own_null), "c", "1", "3"])
        .status()
        .is_ok_and(|st| st.success());
    let null = if made { own_null } else { PathBuf::from("/dev/null") };
    let pts = write(dir.path(), "p.xyz", b"0 0 1\n1 0 2\n0 1 3\n1 1 4\n");
    let runs: [&[&str]; 2] = [
        &["fit", s(&grid), "--max-error", "5", "-o", s(&null), "--report", s(&null)],
        &["rasterize", s(&pts), "--cell", "0.5", "-of", "GTiff", "-o", s(&null)],
    ];
    // /dev/stdout is the stream, whatever stdout leads to (a file here): the link stays. Run
    // in a private mount namespace with its own /dev where root can make one.
    let to_file = dir.path().join("stdout.tmesh");
    let fit = format!("geofit -q fit '{}' --max-error 5 -o /dev/stdout > '{}'", s(&grid), s(&to_file));
    let private = format!("mount -t tmpfs none /dev && ln -s /proc/self/fd/1 /dev/stdout && mknod -m 666 /dev/null c 1 3 && {fit} && test -L /dev/stdout");
    let in_namespace =
        made && std::process::Command::new("unshare").args(["-m", "true"]).status().is_ok_and(|st| st.success());
    let o = if in_namespace {
        common::bash_with_geofit(dir.path())
            .args(["-c", &format!("unshare -m bash -c \"{private}\"")])
            .output()
            .unwrap()
    } else {
        common::bash_with_geofit(dir.path()).args(["-c", &format!("{fit} && test -L /dev/stdout")]).output().unwrap()
    };
    assert!(o.status.success(), "/dev/stdout kept as a link: {}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::read_to_string(&to_file).unwrap().contains("<tmesh"), "the mesh reached stdout's file");
    use std::os::unix::fs::FileTypeExt;
    for args in runs {
        let o = run(args, None);
        assert_eq!(code(&o), 0, "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(
            std::fs::metadata(&null).unwrap().file_type().is_char_device(),
            "{args:?}: {} is still a device",
            null.display()
        );
    }
}

#[test]
fn a_file_of_another_kind_names_the_command_that_reads_it() {
    let Some(gml) = common::fixture(GML) else { return };
    let dir = common::tempdir();
    let grid = write(dir.path(), "grid.asc", GRID.as_bytes());
    let out = dir.path().join("out.tif");
    // a raster given to eval, which reads T-meshes
    refused(
        &["eval", s(&grid), "-o", s(&out)],
        None,
        3,
        &["ESRI ASCII grid raster", "T-mesh", "fit"],
        Some(&out),
        &[&grid],
    );
    // CityGML given to rasterize, which reads points
    refused(
        &["rasterize", s(&gml), "--cell", "1", "-o", s(&out)],
        None,
        3,
        &["CityGML", "point text", "validate"],
        Some(&out),
        &[&gml],
    );
    // CityGML given to fit
    let tm = dir.path().join("x.tmesh");
    refused(&["fit", s(&gml), "--max-error", "1", "-o", s(&tm)], None, 3, &["CityGML", "raster"], Some(&tm), &[&gml]);
    // a popa3d model given to validate
    let popa = dir.path().join("h.popa3d");
    assert_eq!(code(&run(&["citygml2popa3d", s(&gml), "-o", s(&popa)], None)), 0);
    refused(&["validate", s(&popa)], None, 3, &["popa3d model", "adjust"], None, &[&popa]);
}

#[test]
fn directories_empty_files_and_devices_are_named() {
    let dir = common::tempdir();
    let out = dir.path().join("x.tmesh");
    let sub = dir.path().join("survey");
    std::fs::create_dir(&sub).unwrap();
    refused(&["fit", s(&sub), "--max-error", "1", "-o", s(&out)], None, 3, &["is a directory"], Some(&out), &[]);
    let empty = write(dir.path(), "empty.tif", b"");
    refused(
        &["fit", s(&empty), "--max-error", "1", "-o", s(&out)],
        None,
        3,
        &["empty (0 bytes)", "earlier step"],
        Some(&out),
        &[&empty],
    );
    // README: `geofit info /dev/zero` ends with exit 3, at once, not after gigabytes
    let started = std::time::Instant::now();
    refused(&["info", "/dev/zero"], None, 3, &["/dev/zero", "not a data file"], None, &[]);
    assert!(started.elapsed().as_secs() < 10, "info /dev/zero took {:?}", started.elapsed());
}

#[test]
fn cityjson_gzip_and_glb_inputs_say_what_to_do() {
    let dir = common::tempdir();
    let out = dir.path().join("h.gml");
    let cj = write(
        dir.path(),
        "x.city.json",
        br#"{"type": "CityJSON", "version": "2.0", "CityObjects": {}, "vertices": []}"#,
    );
    // CityJSON is read since issue 38: a document without buildings is data heal cannot use
    // (exit 1, one line naming the file), and nothing is written
    let o = common::run(&["heal", s(&cj), "-o", s(&out)], None);
    assert_eq!(common::code(&o), 1, "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("x.city.json") && !out.exists());
    let Some(gml) = common::fixture(GML) else { return };
    let gz = dir.path().join("house.gml.gz");
    let o = std::process::Command::new("sh")
        .arg("-c")
        .arg(format!("gzip -c '{}' > '{}'", gml.display(), gz.display()))
        .status()
        .unwrap();
    assert!(o.success());
    refused(&["heal", s(&gz), "-o", s(&out)], None, 3, &["gzip", "gunzip -c"], Some(&out), &[&gz]);
    let glb = write(dir.path(), "m.glb", b"glTF\x02\0\0\0\x0c\0\0\0");
    refused(&["validate", s(&glb)], None, 3, &["glTF", "does not read it"], None, &[&glb]);
}

#[test]
fn an_empty_stdin_says_the_previous_stage_wrote_nothing() {
    for args in
        [&["adjust", "-"][..], &["heal", "-"], &["validate", "-"], &["eval", "-"], &["fit", "-", "--max-error", "1"]]
    {
        refused(args, Some(b""), 3, &["no input (the previous stage wrote nothing)"], None, &[]);
    }
    // a failed first stage: the pipe's status is the first failure, and the next stage says why
    let Some(_) = common::fixture(GML) else { return };
    let dir = common::tempdir();
    let o = common::bash_with_geofit(dir.path())
        .args(["-c", "set -o pipefail; geofit citygml2popa3d missing.gml | geofit adjust - -o a.popa3d"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{err}");
    assert!(err.contains("missing.gml") && err.contains("the previous stage wrote nothing"), "{err}");
    assert!(!dir.path().join("a.popa3d").exists());
}

#[test]
fn crlf_and_bom_citygml_reads_as_the_original() {
    let Some(gml) = common::fixture(GML) else { return };
    let dir = common::tempdir();
    let text = std::fs::read_to_string(&gml).unwrap();
    let windows = format!("\u{feff}{}", text.replace("\r\n", "\n").replace('\n', "\r\n"));
    let crlf = write(dir.path(), "house-crlf.gml", windows.as_bytes());
    let info = |p: &Path| {
        let o = run(&["info", s(p), "--json"], None);
        assert_eq!(code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
        let mut v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        v.as_object_mut().unwrap().remove("file");
        v
    };
    assert_eq!(info(&crlf), info(&gml), "the same counts, envelope and CRS");
    let findings = |p: &Path| {
        let o = run(&["validate", s(p), "--json", "--no-xsd"], None);
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        (code(&o), v["findings"].as_array().map(|f| f.iter().map(|x| x["code"].clone()).collect::<Vec<_>>()))
    };
    assert_eq!(findings(&crlf), findings(&gml), "the same validation codes");
}

#[test]
fn each_kind_given_to_the_wrong_command_names_the_right_one() {
    let Some(gml) = common::fixture(GML) else { return };
    let dir = common::tempdir();
    let grid = write(dir.path(), "g.asc", GRID.as_bytes());
    let tmesh = dir.path().join("g.tmesh");
    assert_eq!(code(&run(&["fit", s(&grid), "--max-error", "5", "-o", s(&tmesh)], None)), 0);
    let popa = dir.path().join("h.popa3d");
    assert_eq!(code(&run(&["citygml2popa3d", s(&gml), "-o", s(&popa)], None)), 0);
    // a popa3d model saved under a CityGML name, a LAS header, a raster under a points name
    let popa_as_gml = write(dir.path(), "model.gml", &std::fs::read(&popa).unwrap());
    let las = write(dir.path(), "cloud.las", b"LASF\0\0\0\0\x01\x02");
    let grid_as_xyz = write(dir.path(), "grid.xyz", GRID.as_bytes());
    let (tif, gml_out, popa_out, tm_out) =
        (dir.path().join("o.tif"), dir.path().join("o.gml"), dir.path().join("o.popa3d"), dir.path().join("o.tmesh"));
    let glb = dir.path().join("o.glb");
    let cases: &[(&[&str], &[&str], &Path)] = &[
        (
            &["heal", s(&popa_as_gml), "-o", s(&gml_out)],
            &["popa3d model", "adjust, observe, popa3d2citygml"],
            &popa_as_gml,
        ),
        (&["adjust", s(&gml), "-o", s(&popa_out)], &["CityGML", "citygml2popa3d"], &gml),
        (&["fit", s(&tmesh), "--max-error", "1", "-o", s(&tm_out)], &["T-mesh", "eval, surface"], &tmesh),
        (&["fit", s(&las), "--max-error", "1", "-o", s(&tm_out)], &["LAS/LAZ", "rasterize"], &las),
        (&["rasterize", s(&grid_as_xyz), "--cell", "1", "-o", s(&tif)], &["ESRI ASCII grid", "fit"], &grid_as_xyz),
        (&["surface", s(&grid), "-o", s(&glb)], &["raster", "T-mesh"], &grid),
        (&["obj2popa3d", s(&gml), "-o", s(&popa_out)], &["CityGML", "OBJ"], &gml),
        (&["popa3d2citygml", s(&popa), "--template", s(&tmesh), "-o", s(&gml_out)], &["T-mesh", "CityGML"], &tmesh),
    ];
    for (args, words, input) in cases {
        refused(args, None, 3, words, None, &[input]);
    }
    for out in [&tif, &gml_out, &popa_out, &tm_out, &glb] {
        assert!(!out.exists(), "{} written", out.display());
    }
}

#[test]
fn windows_mtllib_paths_and_crlf_in_an_obj_sketch_change_nothing() {
    let sketch = common::repo_root().join("fixtures/popa3d/rooms.obj");
    let dir = common::tempdir();
    let text = std::fs::read_to_string(&sketch).unwrap();
    let windows = format!("mtllib C:\\Users\\survey\\rooms.mtl\r\n{}", text.replace('\n', "\r\n"));
    let win = write(dir.path(), "rooms.obj", windows.as_bytes());
    let model = |p: &Path| {
        let out = dir.path().join("m.popa3d");
        let o = run(&["-q", "obj2popa3d", s(p), "-o", s(&out)], None);
        assert_eq!(code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
        let text = std::fs::read_to_string(&out).unwrap();
        // the <source file="..."> line names the input; every other line must agree
        text.lines().filter(|l| !l.contains("<source ")).map(str::to_string).collect::<Vec<_>>()
    };
    assert_eq!(model(&win), model(&sketch));
}

/// An output replacing a file keeps that file's mode (a 0600 file stays private), and a new one
/// follows the umask (0600 under 077), where every output used to be 0644.
#[test]
fn outputs_keep_the_replaced_mode_and_follow_the_umask() {
    use std::os::unix::fs::PermissionsExt;
    let dir = common::tempdir();
    let grid = write(dir.path(), "g.asc", GRID.as_bytes());
    let private = write(dir.path(), "private.tmesh", b"old");
    std::fs::set_permissions(&private, std::fs::Permissions::from_mode(0o600)).unwrap();
    let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    let o = run(&["-q", "fit", s(&grid), "--max-error", "5", "-o", s(&private)], None);
    assert_eq!(code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
    assert_ne!(std::fs::read(&private).unwrap(), b"old");
    assert_eq!(mode(&private), 0o600, "the replaced file's mode");
    for (umask, want) in [("077", 0o600), ("022", 0o644), ("002", 0o664)] {
        let out = dir.path().join(format!("new-{umask}.tmesh"));
        let o = common::bash_with_geofit(dir.path())
            .args(["-c", &format!("umask {umask}; geofit -q fit '{}' --max-error 5 -o '{}'", s(&grid), s(&out))])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert_eq!(mode(&out), want, "umask {umask}");
    }
}

/// Points in a CRS of US survey feet: `--cell 10` could be feet or metres, so it needs
/// `--cell-unit`; `m` converts (10 m = 32.8083 US ft, checked in gdalinfo's pixel size) and
/// `crs` keeps the CRS's feet.
#[test]
fn a_cell_on_points_in_feet_states_its_unit() {
    if !common::tool("gdalinfo") {
        return;
    }
    let dir = common::tempdir();
    let pts = write(
        dir.path(),
        "ft.xyz",
        b"x y z\n2000000 1000000 10\n2000300 1000000 11\n2000000 1000300 12\n2000300 1000300 13\n",
    );
    let tif = dir.path().join("ft.tif");
    let base = ["-q", "rasterize", s(&pts), "--s-srs", "EPSG:2240", "--cell", "10", "--method", "tin", "-o", s(&tif)];
    refused(&base, None, 2, &["US survey foot", "--cell-unit crs", "--cell-unit m"], Some(&tif), &[&pts]);
    let pixel = |unit: &str| {
        let o = run(&[&base[..], &["--cell-unit", unit]].concat(), None);
        assert_eq!(code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
        let info = std::process::Command::new("gdalinfo").args(["-json", s(&tif)]).output().unwrap();
        let v: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
        v["geoTransform"][1].as_f64().unwrap()
    };
    assert!((pixel("m") - 10.0 / 0.3048006096012192).abs() < 1e-6);
    assert_eq!(pixel("crs"), 10.0);
    // in a CRS of metres --cell is metres, as ever
    let utm = ["rasterize", s(&pts), "--s-srs", "EPSG:25832", "--cell", "10", "--method", "tin", "-o", s(&tif)];
    assert_eq!(code(&run(&utm, None)), 0);
}
