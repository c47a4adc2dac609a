//! Heights stored to the error budget in `.tmb` (issue 37), checked against truth outside
//! geofit: `tests/scripts/tmb_decode_eval.py` decodes the files from docs/tmb-format.md and
//! evaluates the T-spline in numpy; the rasters are analytic or read by GDAL's tools.

mod common;

use std::path::Path;

use common::{code, fixture, python, repo_root, run, tempdir, tool};

/// The numpy decoder/evaluator: (exit code, its JSON line).
fn decode_eval(args: &[&str]) -> (i32, serde_json::Value) {
    let out = python().arg(repo_root().join("tests/scripts/tmb_decode_eval.py")).args(args).output().expect("python");
    let text = String::from_utf8_lossy(&out.stdout);
    let v = serde_json::from_str(text.trim())
        .unwrap_or_else(|e| panic!("{e}: {text} {}", String::from_utf8_lossy(&out.stderr)));
    (out.status.code().unwrap_or(-1), v)
}

fn tools() -> bool {
    tool("gdalinfo") && tool("zstd")
}

/// z = 40 sin(x/13) cos(y/9) + 0.02 x y on 90 × 70 cells of 1 m, as an ESRI ASCII grid.
fn analytic_grid(dir: &Path) -> std::path::PathBuf {
    let (w, h) = (90, 70);
    let mut s = format!("ncols {w}\nnrows {h}\nxllcorner 1000\nyllcorner 2000\ncellsize 1\nNODATA_value -9999\n");
    for r in 0..h {
        let y = (h - 1 - r) as f64 + 0.5;
        let row: Vec<String> = (0..w)
            .map(|c| {
                let x = c as f64 + 0.5;
                format!("{:.17}", 40.0 * (x / 13.0).sin() * (y / 9.0).cos() + 0.02 * x * y)
            })
            .collect();
        s.push_str(&row.join(" "));
        s.push('\n');
    }
    let p = dir.join("analytic.asc");
    std::fs::write(&p, s).unwrap();
    p
}

fn fit(args: &[&str]) -> serde_json::Value {
    let o = run(args, None);
    assert_eq!(code(&o), 0, "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    let rep = args.iter().position(|a| *a == "--report").map(|i| args[i + 1]).expect("--report");
    serde_json::from_slice(&std::fs::read(rep).unwrap()).unwrap()
}

fn heights(file: &Path) -> (Option<f64>, Vec<f64>) {
    let (rc, v) = decode_eval(&[file.to_str().unwrap(), "--dump"]);
    assert_eq!(rc, 0, "{v}");
    let z = v["z"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    (v["step"].as_f64(), z)
}

/// The bound on an analytic surface: the quantised file of a fit at E is the lossless file of
/// the fit at E·(1 − 0.3) (the same mesh) with every height moved by at most q = 0.3·E to a
/// multiple of 2q, and both surfaces, evaluated in numpy, stay within E of the analytic data;
/// the quantised file is the smaller.
#[test]
fn quantised_heights_move_by_at_most_q_and_the_file_stays_within_e() {
    if !tools() {
        return;
    }
    let dir = tempdir();
    let r = analytic_grid(dir.path());
    let (rs, e) = (r.to_str().unwrap(), 0.2f64);
    let q_file = dir.path().join("q.tmb");
    let l_file = dir.path().join("l.tmb");
    let (qr, lr) = (dir.path().join("q.json"), dir.path().join("l.json"));
    let rep = fit(&[
        "fit",
        rs,
        "--max-error",
        &e.to_string(),
        "--storage-share",
        "0.3",
        "-o",
        q_file.to_str().unwrap(),
        "--report",
        qr.to_str().unwrap(),
        "--device",
        "cpu",
    ]);
    let e_fit = e * (1.0 - 0.3);
    fit(&[
        "fit",
        rs,
        "--max-error",
        &format!("{e_fit:?}"),
        "--lossless",
        "-o",
        l_file.to_str().unwrap(),
        "--report",
        lr.to_str().unwrap(),
        "--device",
        "cpu",
    ]);
    let q = rep["output"]["quantum"].as_f64().expect("a quantised file");
    assert!((q - 0.3 * e).abs() < 1e-15, "{q}");
    let ((step, zq), (lstep, zl)) = (heights(&q_file), heights(&l_file));
    assert_eq!((step, lstep), (Some(2.0 * q), None));
    assert_eq!(zq.len(), zl.len(), "the same mesh");
    let worst = zq.iter().zip(&zl).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(worst <= q * (1.0 + 1e-9) && worst > 0.5 * q, "heights moved by {worst}, q = {q}");
    assert!(zq.iter().all(|z| ((z / (2.0 * q)) - (z / (2.0 * q)).round()).abs() < 1e-6));
    for (f, tol) in [(&q_file, e), (&l_file, e_fit)] {
        let (rc, v) = decode_eval(&[f.to_str().unwrap(), rs, &tol.to_string()]);
        assert_eq!(rc, 0, "{}: {v}", f.display());
        assert!(v["max_abs_error"].as_f64().unwrap() <= tol);
    }
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    assert!(size(&q_file) < size(&l_file), "{} vs {}", size(&q_file), size(&l_file));
    // the report's own check of the decoded file agrees
    assert!(rep["output"]["decoded_max_abs_error"].as_f64().unwrap() <= e);
    assert!(rep["output"]["lerc_zstd_bytes"].as_u64().unwrap() > 0);
}

/// A real fixture (the 1 m LiDAR DEM) at 0.5 m: the file as written, decoded and evaluated in
/// numpy at every valid cell that GDAL reads, is within 0.5 m; `fit` says the LERC size on stderr.
#[test]
fn decoded_file_of_a_real_fixture_is_within_e() {
    let Some(dem) = fixture("terrain/giswqs-lidar_dem.tif") else { return };
    if !tools() {
        return;
    }
    let dir = tempdir();
    let out = dir.path().join("lidar.tmb");
    let o = run(
        &["fit", dem.to_str().unwrap(), "--max-error", "0.5", "-o", out.to_str().unwrap(), "--device", "cpu"],
        None,
    );
    assert_eq!(code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.lines().any(|l| l.contains("LERC_ZSTD") && l.contains("bytes")), "{err}");
    let (rc, v) = decode_eval(&[out.to_str().unwrap(), dem.to_str().unwrap(), "0.5"]);
    assert_eq!(rc, 0, "{v}");
    assert_eq!(v["quantised"], true);
    assert_eq!(v["valid_cells"], 160000);
    assert!(v["max_abs_error"].as_f64().unwrap() <= 0.5, "{v}");
}

/// `--lossless`: the heights are the f64 bits of the XML `.tmesh` of the same fit, decoded
/// independently; and a version-1 file (zlib body, made from it by the script) evaluates to
/// the same raster as the version-2 file.
#[test]
fn lossless_is_exact_and_version_1_files_read() {
    if !tools() {
        return;
    }
    let dir = tempdir();
    let r = analytic_grid(dir.path());
    let rs = r.to_str().unwrap();
    let (tmb, xml) = (dir.path().join("a.tmb"), dir.path().join("a.tmesh"));
    for out in [&tmb, &xml] {
        let o =
            run(&["fit", rs, "--max-error", "0.2", "--lossless", "-o", out.to_str().unwrap(), "--device", "cpu"], None);
        assert_eq!(code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
    }
    let (step, z) = heights(&tmb);
    assert_eq!(step, None);
    // the XML's points "s t x y z w", ordered by (t, s) as the binary form orders them
    let text = std::fs::read_to_string(&xml).unwrap();
    let body = text.split("<points").nth(1).unwrap().split_once('>').unwrap().1.split("</points>").next().unwrap();
    let mut pts: Vec<[f64; 6]> = body
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3], v[4], v[5]]
        })
        .collect();
    pts.sort_by(|a, b| a[1].total_cmp(&b[1]).then(a[0].total_cmp(&b[0])));
    assert_eq!(pts.len(), z.len());
    assert!(pts.iter().zip(&z).all(|(p, z)| p[4].to_bits() == z.to_bits()), "lossless heights differ");
    // version 1
    let v1 = dir.path().join("v1.tmb");
    let (rc, v) = decode_eval(&[tmb.to_str().unwrap(), "--to-v1", v1.to_str().unwrap()]);
    assert_eq!(rc, 0, "{v}");
    assert_eq!(std::fs::read(&v1).unwrap()[8], 1);
    let mut evals = Vec::new();
    for (f, name) in [(&tmb, "e2.asc"), (&v1, "e1.asc")] {
        let out = dir.path().join(name);
        let o = run(&["eval", f.to_str().unwrap(), "--like", rs, "-o", out.to_str().unwrap(), "--device", "cpu"], None);
        assert_eq!(code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
        evals.push(std::fs::read(&out).unwrap());
    }
    assert!(evals[0] == evals[1], "version 1 and 2 of one mesh evaluate differently");
}

/// A corrupt or truncated `.tmb` is exit 3 with one stderr line naming the file.
#[test]
fn damaged_files_exit_3_with_one_line() {
    let dir = tempdir();
    let r = analytic_grid(dir.path());
    let good = dir.path().join("g.tmb");
    let o =
        run(&["fit", r.to_str().unwrap(), "--max-error", "0.5", "-o", good.to_str().unwrap(), "--device", "cpu"], None);
    assert_eq!(code(&o), 0, "{}", String::from_utf8_lossy(&o.stderr));
    let b = std::fs::read(&good).unwrap();
    let mut flipped = b.clone();
    let mid = b.len() / 2;
    flipped[mid] ^= 0x5a;
    let mut bad_version = b.clone();
    bad_version[8] = 9;
    for (name, data) in [
        ("trunc.tmb", b[..b.len() - 7].to_vec()),
        ("flip.tmb", flipped),
        ("v9.tmb", bad_version),
        ("head.tmb", b[..12].to_vec()),
    ] {
        let p = dir.path().join(name);
        std::fs::write(&p, data).unwrap();
        let out = dir.path().join("x.asc");
        let o = run(&["eval", p.to_str().unwrap(), "--like", r.to_str().unwrap(), "-o", out.to_str().unwrap()], None);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(code(&o), 3, "{name}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{name}: {err}");
        assert!(err.contains(name), "{name}: {err}");
        assert!(!out.exists());
    }
}
