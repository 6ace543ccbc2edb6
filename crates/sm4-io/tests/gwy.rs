//! Gwyddion `.gwy` reader: synthetic containers written here, the real files in
//! `tests/data/real` (one saved by the gwyfile project, one converted by Gwyddion 2.62 from
//! a real Nanonis file that dhct also reads directly), and hostile inputs.

use std::path::{Path, PathBuf};

use dhct_scan::{FileFormat, ScanDirection, ScanPass, ValueSource};
use dhct_sm4_io::{ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY, ReadError, gwy, read_bytes, read_path};

/// One serialized component value, as the GWY format writes it.
enum V<'a> {
    Int(i32),
    Double(f64),
    Str(&'a str),
    Obj(Vec<u8>),
    Doubles(Vec<f64>),
}

fn object(type_name: &str, components: &[(&str, V)]) -> Vec<u8> {
    let mut body = Vec::new();
    for (name, value) in components {
        body.extend_from_slice(name.as_bytes());
        body.push(0);
        match value {
            V::Int(v) => {
                body.push(b'i');
                body.extend_from_slice(&v.to_le_bytes());
            }
            V::Double(v) => {
                body.push(b'd');
                body.extend_from_slice(&v.to_le_bytes());
            }
            V::Str(s) => {
                body.push(b's');
                body.extend_from_slice(s.as_bytes());
                body.push(0);
            }
            V::Obj(o) => {
                body.push(b'o');
                body.extend_from_slice(o);
            }
            V::Doubles(values) => {
                body.push(b'D');
                body.extend_from_slice(&(values.len() as u32).to_le_bytes());
                for v in values {
                    body.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
    }
    let mut out = type_name.as_bytes().to_vec();
    out.push(0);
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(&body);
    out
}

fn unit(text: &str) -> V<'_> {
    V::Obj(object("GwySIUnit", &[("unitstr", V::Str(text))]))
}

/// A data field of `columns × rows` whose pixel (r, c) holds `1000 r + c + offset`.
fn field(columns: i32, rows: i32, xy_unit: &str, offset: f64) -> Vec<u8> {
    let data = (0..rows * columns)
        .map(|k| f64::from(1000 * (k / columns) + k % columns) + offset)
        .collect();
    object(
        "GwyDataField",
        &[
            ("xres", V::Int(columns)),
            ("yres", V::Int(rows)),
            ("xreal", V::Double(f64::from(columns) * 2e-10)),
            ("yreal", V::Double(f64::from(rows) * 3e-10)),
            ("si_unit_xy", unit(xy_unit)),
            ("si_unit_z", unit("m")),
            ("data", V::Doubles(data)),
        ],
    )
}

fn file(entries: Vec<(&str, V)>) -> Vec<u8> {
    let mut out = b"GWYP".to_vec();
    out.extend_from_slice(&object("GwyContainer", &entries));
    out
}

#[test]
fn forward_and_backward_fields_pair_and_stay_in_display_orientation() {
    let bytes = file(vec![
        ("/0/data/title", V::Str("Z (Forward)")),
        ("/0/data", V::Obj(field(5, 3, "m", 0.0))),
        ("/1/data/title", V::Str("Z (Backward)")),
        ("/1/data", V::Obj(field(5, 3, "m", 0.5))),
        ("/2/data/title", V::Str("Current (Forward)")),
        ("/2/data", V::Obj(field(5, 3, "m", 7.0))),
        ("/filename", V::Str("x.gwy")),
    ]);
    let scan = read_bytes(&bytes).unwrap();
    assert_eq!(scan.format, FileFormat::Gwyddion);
    assert_eq!(scan.pairs.len(), 2);
    let z = &scan.pairs[0];
    assert_eq!(z.name(), "Z");
    let (trace, retrace) = (z.trace().unwrap(), z.retrace().unwrap());
    assert_eq!((trace.rows(), trace.columns()), (3, 5));
    assert_eq!(trace.z[[2, 4]], 2004.0);
    assert_eq!(retrace.z[[1, 3]], 1003.5);
    let g = z.geometry();
    assert!((g.pitch_x() - 2e-10).abs() < 1e-22 && (g.pitch_y() - 3e-10).abs() < 1e-22);
    assert_eq!(g.scale_source(), ValueSource::Stated);
    assert_eq!(g.timing_source(), ValueSource::Assumed);
    assert_eq!(g.fast_direction(ScanPass::Retrace), ScanDirection::Left);
    assert!(scan.metadata[ASSUMED_TIMING_KEY].contains("no scan timing"));
    let current = &scan.pairs[1];
    assert_eq!(current.name(), "Current (Forward)");
    assert!(current.retrace().is_none());
}

#[test]
fn a_lateral_unit_other_than_metres_gives_an_assumed_scale() {
    let bytes = file(vec![("/0/data", V::Obj(field(4, 4, "", 0.0)))]);
    let scan = read_bytes(&bytes).unwrap();
    assert_eq!(scan.pairs[0].name(), "Channel 0");
    assert_eq!(
        scan.pairs[0].geometry().scale_source(),
        ValueSource::Assumed
    );
    assert!(scan.metadata[ASSUMED_SCALE_KEY].contains("not a plausible size in metres"));
}

#[test]
fn inconsistent_or_missing_images_are_typed_errors() {
    // Data length disagreeing with xres · yres.
    let bad = object(
        "GwyDataField",
        &[
            ("xres", V::Int(4)),
            ("yres", V::Int(4)),
            ("xreal", V::Double(1e-9)),
            ("yreal", V::Double(1e-9)),
            ("data", V::Doubles(vec![0.0; 15])),
        ],
    );
    let error = read_bytes(&file(vec![("/0/data", V::Obj(bad))])).unwrap_err();
    assert!(error.to_string().contains("16 doubles"), "{error}");
    // No data field at all.
    let error = read_bytes(&file(vec![("/0/data/title", V::Str("x"))])).unwrap_err();
    assert!(matches!(error, ReadError::NoImage { .. }), "{error}");
    // The old format and a foreign top object.
    assert!(matches!(
        gwy::read(b"GWYOGwyContainer\0\0\0\0\0"),
        Err(ReadError::Unsupported { .. })
    ));
    let mut foreign = b"GWYP".to_vec();
    foreign.extend_from_slice(&object("GwyGraphModel", &[]));
    assert!(matches!(
        read_bytes(&foreign),
        Err(ReadError::Corrupt { .. })
    ));
    // Every truncation of a valid file is an error, never a panic.
    let bytes = file(vec![("/0/data", V::Obj(field(3, 2, "m", 0.0)))]);
    for cut in 0..bytes.len() {
        assert!(read_bytes(&bytes[..cut]).is_err(), "cut at {cut}");
    }
}

fn real(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/real")
        .join(name)
}

#[test]
fn real_gwyfile_test_file() {
    // Saved by the gwyfile project (tuxu/gwyfile tests/test.gwy): one 128 x 128 field
    // titled "Test", 128 x 128 m, values 0..1e-3 (its own test checks shape and title).
    let scan = read_path(&real("gwyfile_test.gwy")).unwrap();
    assert_eq!(scan.pairs.len(), 1);
    let pair = &scan.pairs[0];
    assert_eq!(pair.name(), "Test");
    let g = pair.geometry();
    assert_eq!((g.columns(), g.rows()), (128, 128));
    // 1 m per pixel is beyond any STM scan: the scale is an assumption, not 1 m.
    assert_eq!(g.scale_source(), ValueSource::Assumed);
    let (low, high) = pair.trace().unwrap().finite_range().unwrap();
    assert!(low >= 0.0 && high <= 1e-3 && high > 9e-4, "{low}..{high}");
}

#[test]
fn real_gwyddion_conversion_matches_the_nanonis_original() {
    // moire_4K_10nm.gwy was written by Gwyddion 2.62 (`--convert-to-gwy`) from
    // moire_4K_10nm.sxm; dhct's SXM reader is checked against the Nanonis file itself.
    let gwy = read_path(&real("moire_4K_10nm.gwy")).unwrap();
    let sxm = read_path(&real("moire_4K_10nm.sxm")).unwrap();
    let names: Vec<&str> = gwy.pairs.iter().map(|p| p.name()).collect();
    assert_eq!(names, ["Z", "Current"]);
    for (a, b) in gwy.pairs.iter().zip(&sxm.pairs) {
        let (ga, gb) = (a.geometry(), b.geometry());
        assert_eq!((ga.columns(), ga.rows()), (gb.columns(), gb.rows()));
        assert!((ga.width() / gb.width() - 1.0).abs() < 1e-9);
        assert!((ga.height() / gb.height() - 1.0).abs() < 1e-9);
        for pass in ScanPass::BOTH {
            let (za, zb) = (&a.image(pass).unwrap().z, &b.image(pass).unwrap().z);
            assert_eq!(a.image(pass).unwrap().unit, b.image(pass).unwrap().unit);
            // Gwyddion stores the float32 values as doubles: equal to the last bit.
            assert!(za == zb, "{} {pass:?} differs from the SXM image", a.name());
        }
    }
}
