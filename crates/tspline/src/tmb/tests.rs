//! Unit tests of the binary T-mesh: round trips against the XML, the tree forms, damaged files.

use super::*;
use crate::eval::{GridSpec, PbSpline};

fn sample_file(degree: Degree, xy: bool) -> TMeshFile {
    let mut m = TMesh::grid(degree, -8.0, -4.0, 8.0, 5, 3);
    let mut g = |s: f64, t: f64| (s, t, 0.0);
    let c = m.leaves_in(Rect::new(4.5, 1.0, 4.5, 1.0))[0];
    let kids = m.split(c, &mut g);
    m.split(kids[2], &mut g);
    m.repair(1.0, &mut g);
    for (i, p) in m.points.iter_mut().enumerate() {
        p.z = (p.s * 0.37).sin() * 10.0 + p.t * 0.01 + i as f64 * 1e-9;
        if xy {
            p.x = p.s + 0.25 * (p.t * 0.1).cos();
            p.w = 1.0 + (i % 3) as f64 * 0.125;
        }
    }
    TMeshFile {
        mesh: m,
        georef: Georef { x0: 500015.0, y0: 2150015.5, dx: 2.0, dy: -2.0, crs: "EPSG:32605".into() },
        mask: Some(DataMask { width: 7, height: 5, bits: (0..35).map(|i| i % 5 != 1).collect() }),
        warp: xy.then(|| r#"{"version":1}"#.to_string()),
    }
}

/// The uncompressed body of a version-2 file (zstd, by the `zstd` crate's own decoder).
fn body_of(b: &[u8]) -> Vec<u8> {
    assert_eq!(b[8], VERSION);
    zstd::stream::decode_all(&b[17..b.len() - 4]).unwrap()
}

/// `f` as version 1 wrote it (zlib body), built from the version-2 body of a lossless file.
fn as_version_1(f: &TMeshFile) -> Vec<u8> {
    let body = body_of(&bytes(f, true));
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    z.write_all(&body).unwrap();
    let mut crc = flate2::Crc::new();
    crc.update(&body);
    let mut out = MAGIC.to_vec();
    out.push(1);
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    out.extend_from_slice(&z.finish().unwrap());
    out.extend_from_slice(&crc.sum().to_le_bytes());
    out
}

fn bytes(f: &TMeshFile, binary: bool) -> Vec<u8> {
    let mut buf = Vec::new();
    if binary {
        write(f, &mut buf).unwrap()
    } else {
        crate::format::write(f, &mut buf).unwrap()
    }
    buf
}

/// .tmb and .tmesh of one mesh read back to the same mesh (up to numbering) and evaluate to
/// the same bits on a grid that crosses every cell, and as the mesh itself; the quadtree form is taken for a refined grid and the
/// explicit one for a merged mesh with a gap.
#[test]
fn round_trip_equals_the_xml_bit_for_bit() {
    for degree in [Degree::Linear, Degree::Cubic] {
        for xy in [false, true] {
            let f = sample_file(degree, xy);
            let b = bytes(&f, true);
            assert_eq!(b[..8], MAGIC[..]);
            let fb = crate::format::read(&b).unwrap();
            let fx = crate::format::read(&bytes(&f, false)).unwrap();
            let cx = canonical(&fx.mesh);
            assert_eq!(fb.mesh.points, cx.points);
            let (cb, cc): (Vec<_>, Vec<_>) =
                (fb.mesh.cells.iter().map(|c| c.corners).collect(), cx.cells.iter().map(|c| c.corners).collect());
            assert_eq!(cb, cc);
            assert_eq!(
                (fb.georef.clone(), fb.mask.clone(), fb.warp.clone()),
                (fx.georef.clone(), fx.mask.clone(), fx.warp.clone())
            );
            let g = GridSpec { s0: -8.0, t0: -4.0, ds: 0.25, dt: 0.25, ns: 161, nt: 97 };
            let (zb, zx) =
                (PbSpline::build(&fb.mesh).eval_grid(&g, true), PbSpline::build(&fx.mesh).eval_grid(&g, true));
            let zm = PbSpline::build(&f.mesh).eval_grid(&g, true);
            assert!(zb.iter().zip(&zx).all(|(a, b)| a.to_bits() == b.to_bits()));
            assert!(zb.iter().zip(&zm).all(|(a, b)| a.to_bits() == b.to_bits()));
            // and point by point (the reference path)
            let (pb_b, pb_m) = (PbSpline::build(&fb.mesh), PbSpline::build(&f.mesh));
            for q in 0..2000 {
                let (s, t) =
                    (-8.0 + 40.0 * ((q * 37) % 1000) as f64 / 1000.0, -4.0 + 24.0 * ((q * 91) % 1000) as f64 / 1000.0);
                assert_eq!(pb_b.point(s, t)[2].to_bits(), pb_m.point(s, t)[2].to_bits());
            }
            // the quadtree form: far fewer bytes than the XML
            assert!(b.len() * 3 < bytes(&f, false).len(), "{degree:?}: {} vs {}", b.len(), bytes(&f, false).len());
            // writing the read-back file again gives the same bytes
            assert_eq!(bytes(&fb, true), b);
        }
    }
    let a = TMesh::grid(Degree::Cubic, 0.0, 0.0, 4.0, 5, 4);
    let mut c = TMesh::grid(Degree::Cubic, 24.0, 4.0, 3.0, 3, 3);
    c.points.iter_mut().for_each(|p| p.z = 1.0 + 0.1 * p.s);
    let f = TMeshFile { mesh: a.merge(&c).unwrap(), georef: Georef::identity(), mask: None, warp: None };
    let b = bytes(&f, true);
    let body_flags = body_of(&b)[1];
    assert_eq!(body_flags & QUADTREE, 0, "a mesh with a gap takes the explicit form");
    let back = read(&b).unwrap();
    assert_eq!(back.mesh.points, canonical(&f.mesh).points);
}

/// A mesh of anisotropic 2-splits (rectangles, docs/decisions.md#anisotropic-splits-issue-19)
/// is not a quadtree: it takes the 2-/4-split tree form (fewer bytes than the explicit one)
/// and reads back to the XML's mesh, which evaluates to the same bits; every truncation or
/// flipped byte of it is a format error or the same mesh.
#[test]
fn anisotropic_mesh_takes_the_kdtree_form() {
    let mut m = crate::testing::aniso_mesh(Degree::Cubic, 7, 3);
    for p in &mut m.points {
        p.z = (p.s * 0.21).sin() * 5.0 + 0.1 * p.t;
    }
    let f = TMeshFile { mesh: m, georef: Georef::identity(), mask: None, warp: None };
    let b = bytes(&f, true);
    assert_eq!(body_of(&b)[1] & (QUADTREE | KDTREE), KDTREE);
    let fb = read(&b).unwrap();
    let fx = crate::format::read(&bytes(&f, false)).unwrap();
    assert_eq!(fb.mesh.points, canonical(&fx.mesh).points);
    let g = GridSpec { s0: -16.0, t0: 0.0, ds: 0.5, dt: 0.5, ns: 161, nt: 129 };
    let (zb, zx) = (PbSpline::build(&fb.mesh).eval_grid(&g, true), PbSpline::build(&fx.mesh).eval_grid(&g, true));
    assert!(zb.iter().zip(&zx).all(|(a, b)| a.to_bits() == b.to_bits()));
    assert_eq!(bytes(&fb, true), b);
    // the structure takes under a byte per leaf (the explicit form at least four)
    let leaves: Vec<Rect> = canonical(&f.mesh).cells.iter().map(|c| c.rect).collect();
    let (.., head) = kdtree(&leaves).unwrap();
    assert!(head.len() < leaves.len(), "{} bytes for {} leaves", head.len(), leaves.len());
    for n in 0..b.len() {
        assert!(read(&b[..n]).is_err(), "truncated to {n} bytes");
    }
    for i in 0..b.len() {
        let mut d = b.clone();
        d[i] ^= 0x40;
        if let Ok(g) = read(&d) {
            assert_eq!(g.mesh.points, fb.mesh.points, "byte {i}");
        }
    }
}

/// Every truncation and a flipped byte anywhere give a Format error, never a panic or a
/// different mesh (a flip in the deflate stream's unused padding bits changes nothing).
#[test]
fn damaged_files_are_errors() {
    let b = bytes(&sample_file(Degree::Cubic, true), true);
    let good = read(&b).unwrap();
    for n in 0..b.len() {
        assert!(read(&b[..n]).is_err(), "truncated to {n} bytes");
    }
    for i in 0..b.len() {
        let mut d = b.clone();
        d[i] ^= 0x40;
        match crate::format::read(&d) {
            Err(TsplineError::Format { .. }) => {}
            Err(e) => panic!("byte {i}: not a format error: {e}"),
            Ok(f) => {
                assert_eq!(f.mesh.points, good.mesh.points, "byte {i} flipped: a different mesh read without error");
                assert_eq!((f.georef, f.mask, f.warp), (good.georef.clone(), good.mask.clone(), good.warp.clone()));
            }
        }
    }
}

/// Quantised heights: every control point and the surface move by at most q (partition of
/// unity), the structure, mask and warp stay exact, the file is smaller; a version-1 file (zlib,
/// lossless) still reads to the same mesh, and version 1 with the QUANT flag is refused.
#[test]
fn quantised_write_moves_the_surface_by_at_most_q() {
    for xy in [false, true] {
        let f = sample_file(Degree::Cubic, xy);
        let q = 0.01;
        let mut b = Vec::new();
        write_with(&f, &WriteOptions { quantum: Some(q) }, &mut b).unwrap();
        let fq = read(&b).unwrap();
        let fl = read(&bytes(&f, true)).unwrap();
        assert_eq!(body_of(&b)[1] & QUANT, QUANT);
        assert!(b.len() < bytes(&f, true).len(), "{} vs {}", b.len(), bytes(&f, true).len());
        assert_eq!(
            (fq.georef.clone(), fq.mask.clone(), fq.warp.clone()),
            (fl.georef.clone(), fl.mask.clone(), fl.warp.clone())
        );
        let dz = fq.mesh.points.iter().zip(&fl.mesh.points).map(|(a, b)| (a.z - b.z).abs()).fold(0.0, f64::max);
        assert!(dz <= q * (1.0 + 1e-12) && dz > 0.5 * q, "control points moved by {dz}");
        assert!(fq
            .mesh
            .points
            .iter()
            .zip(&fl.mesh.points)
            .all(|(a, b)| (a.s, a.t, a.x, a.y, a.w) == (b.s, b.t, b.x, b.y, b.w)));
        let g = GridSpec { s0: -8.0, t0: -4.0, ds: 0.125, dt: 0.125, ns: 321, nt: 193 };
        let (zq, zl) = (PbSpline::build(&fq.mesh).eval_grid(&g, true), PbSpline::build(&fl.mesh).eval_grid(&g, true));
        let ds = zq
            .iter()
            .zip(&zl)
            .filter(|(a, b)| a.is_finite() && b.is_finite())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(ds <= q * (1.0 + 1e-9), "surface moved by {ds} > {q}");
        // version 1 reads, to the lossless mesh
        let v1 = read(&as_version_1(&f)).unwrap();
        assert_eq!(v1.mesh.points, fl.mesh.points);
        // version 1 never had quantised heights
        let mut body = body_of(&b);
        let mut bad = MAGIC.to_vec();
        bad.push(1);
        bad.extend_from_slice(&(body.len() as u64).to_le_bytes());
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        z.write_all(&body).unwrap();
        bad.extend_from_slice(&z.finish().unwrap());
        let mut crc = flate2::Crc::new();
        crc.update(&body);
        bad.extend_from_slice(&crc.sum().to_le_bytes());
        assert!(matches!(read(&bad), Err(TsplineError::Format { .. })));
        body.clear();
    }
    let f = sample_file(Degree::Cubic, false);
    assert!(write_with(&f, &WriteOptions { quantum: Some(1e-300) }, &mut Vec::new()).is_err());
}
