//! NPY reader and writer: hand-built files of every supported dtype and order, round trips,
//! and hostile inputs.

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ValueSource};
use dhct_sm4_io::{ReadError, npy, read_bytes};
use ndarray::Array2;
use proptest::prelude::*;

/// Builds an `.npy` file from a header dict and raw data, padding the header to 64 bytes.
fn npy_file(version: u8, dict: &str, data: &[u8]) -> Vec<u8> {
    let length_size = if version == 1 { 2 } else { 4 };
    let unpadded = 6 + 2 + length_size + dict.len() + 1;
    let padding = (64 - unpadded % 64) % 64;
    let header_len = dict.len() + padding + 1;
    let mut out = b"\x93NUMPY".to_vec();
    out.extend_from_slice(&[version, 0]);
    if version == 1 {
        out.extend_from_slice(&(header_len as u16).to_le_bytes());
    } else {
        out.extend_from_slice(&(header_len as u32).to_le_bytes());
    }
    out.extend_from_slice(dict.as_bytes());
    out.extend(std::iter::repeat_n(b' ', padding));
    out.push(b'\n');
    out.extend_from_slice(data);
    out
}

fn dict(descr: &str, fortran: bool, shape: &str) -> String {
    let order = if fortran { "True" } else { "False" };
    format!("{{'descr': '{descr}', 'fortran_order': {order}, 'shape': {shape}, }}")
}

/// The 2 x 3 test image: value = 10·row + col.
fn expected_2x3() -> Array2<f64> {
    Array2::from_shape_fn((2, 3), |(r, c)| (10 * r + c) as f64)
}

/// Elements of the 2 x 3 test image in C or Fortran order.
fn elements(fortran: bool) -> Vec<f64> {
    let z = expected_2x3();
    if fortran {
        (0..3)
            .flat_map(|c| (0..2).map(move |r| (r, c)))
            .map(|(r, c)| z[[r, c]])
            .collect()
    } else {
        z.iter().copied().collect()
    }
}

fn encode(values: &[f64], descr: &str) -> Vec<u8> {
    let big = descr.starts_with('>');
    let kind = &descr[1..];
    let mut out = Vec::new();
    for &v in values {
        let mut bytes: Vec<u8> = match kind {
            "f8" => v.to_le_bytes().to_vec(),
            "f4" => (v as f32).to_le_bytes().to_vec(),
            "i1" => (v as i8).to_le_bytes().to_vec(),
            "u1" => (v as u8).to_le_bytes().to_vec(),
            "i2" => (v as i16).to_le_bytes().to_vec(),
            "u2" => (v as u16).to_le_bytes().to_vec(),
            "i4" => (v as i32).to_le_bytes().to_vec(),
            "u4" => (v as u32).to_le_bytes().to_vec(),
            "i8" => (v as i64).to_le_bytes().to_vec(),
            "u8" => (v as u64).to_le_bytes().to_vec(),
            other => panic!("test encoder lacks {other}"),
        };
        if big {
            bytes.reverse();
        }
        out.extend_from_slice(&bytes);
    }
    out
}

#[test]
fn reads_every_dtype_in_both_orders_and_all_versions() {
    let descrs = [
        "<f8", ">f8", "<f4", ">f4", "|i1", "|u1", "<i2", ">i2", "<u2", ">u2", "<i4", ">i4", "<u4",
        ">u4", "<i8", ">i8", "<u8", ">u8",
    ];
    for descr in descrs {
        for fortran in [false, true] {
            for version in [1, 2, 3] {
                let data = encode(&elements(fortran), descr);
                let file = npy_file(version, &dict(descr, fortran, "(2, 3)"), &data);
                let scan = npy::read(&file)
                    .unwrap_or_else(|e| panic!("{descr} fortran={fortran} v{version}: {e}"));
                assert_eq!(scan.format, FileFormat::Npy);
                let pair = &scan.pairs[0];
                let z = &pair.trace().unwrap().z;
                assert_eq!(z, &expected_2x3(), "{descr} fortran={fortran} v{version}");
                assert!(z.is_standard_layout());
                let g = pair.geometry();
                assert_eq!((g.columns(), g.rows()), (3, 2));
                assert_eq!(g.scale_source(), ValueSource::Assumed);
                assert_eq!(g.timing_source(), ValueSource::Assumed);
                assert_eq!(g.pitch_x(), dhct_sm4_io::ASSUMED_PITCH);
                assert_eq!(g.pixel_period(), dhct_sm4_io::ASSUMED_PIXEL_PERIOD);
                assert_eq!(g.trace_fast(), ScanDirection::Right);
                assert_eq!(g.slow_direction(), ScanDirection::Down);
            }
        }
    }
}

#[test]
fn accepts_header_variants_numpy_and_python2_write() {
    // Keys in another order, double quotes, Python 2 long suffix, no trailing comma.
    let data = encode(&elements(false), "<f8");
    let header = "{\"shape\": (2L, 3L), \"fortran_order\": False, \"descr\": \"<f8\"}";
    let scan = npy::read(&npy_file(1, header, &data)).unwrap();
    assert_eq!(scan.pairs[0].trace().unwrap().z, expected_2x3());
}

#[test]
fn round_trip_keeps_values_exactly_including_nan_non_square() {
    let mut z = Array2::from_shape_fn((5, 7), |(r, c)| {
        (r as f64 - 2.5) * 1e-10 + c as f64 * 3.3e-12
    });
    z[[1, 4]] = f64::NAN;
    z[[4, 6]] = -0.0;
    let channel = ImageChannel::new("Topography", "m", z.clone());
    let mut bytes = Vec::new();
    npy::write(&channel, &mut bytes).unwrap();
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    assert_eq!(
        (10 + header_len) % 64,
        0,
        "data must start on a 64-byte boundary"
    );
    assert_eq!(bytes[9 + header_len], b'\n');
    assert_eq!(bytes.len(), 10 + header_len + 5 * 7 * 8);
    let header = std::str::from_utf8(&bytes[10..10 + header_len]).unwrap();
    assert!(header.contains("'descr': '<f8'") && header.contains("'shape': (5, 7)"));

    let scan = read_bytes(&bytes).unwrap();
    let back = &scan.pairs[0].trace().unwrap().z;
    assert_eq!(back.dim(), (5, 7));
    for (a, b) in back.iter().zip(z.iter()) {
        assert_eq!(a.to_bits(), b.to_bits());
    }
}

#[test]
fn rejects_shapes_that_are_not_2d_and_unsupported_dtypes() {
    for shape in ["(6,)", "(1, 2, 3)", "()"] {
        let file = npy_file(1, &dict("<f8", false, shape), &[0u8; 48]);
        assert!(
            matches!(npy::read(&file), Err(ReadError::Unsupported { .. })),
            "shape {shape}"
        );
    }
    for descr in ["<f2", "<c16", "<b2", "<U3", "|O", "<f16", "f"] {
        let file = npy_file(1, &dict(descr, false, "(2, 3)"), &[0u8; 96]);
        assert!(npy::read(&file).is_err(), "dtype {descr}");
    }
    // NumPy bool arrays (e.g. masks) read as 0 and 1.
    let file = npy_file(1, &dict("|b1", false, "(2, 3)"), &[0, 1, 2, 0, 0, 255]);
    let scan = npy::read(&file).expect("bool array");
    let z: Vec<f64> = scan.pairs[0].trace().unwrap().z.iter().copied().collect();
    assert_eq!(z, [0.0, 1.0, 1.0, 0.0, 0.0, 1.0]);
    let structured =
        "{'descr': [('x', '<f8'), ('y', '<f8')], 'fortran_order': False, 'shape': (2, 3), }";
    assert!(matches!(
        npy::read(&npy_file(1, structured, &[0u8; 96])),
        Err(ReadError::Unsupported { .. })
    ));
    let empty = npy_file(1, &dict("<f8", false, "(0, 3)"), &[]);
    assert!(matches!(npy::read(&empty), Err(ReadError::NoImage { .. })));
}

#[test]
fn hostile_sizes_fail_without_allocating() {
    let huge = npy_file(
        1,
        &dict("<f8", false, "(2147483648, 2147483648)"),
        &[0u8; 64],
    );
    assert!(npy::read(&huge).is_err());
    let overflow = npy_file(
        1,
        &dict("<f8", false, "(18446744073709551615, 18446744073709551615)"),
        &[],
    );
    assert!(npy::read(&overflow).is_err());
    let too_big = npy_file(1, &dict("<f8", false, "(99999999999999999999, 2)"), &[]);
    assert!(npy::read(&too_big).is_err());

    // Header length beyond the file and beyond the limit.
    let mut file = b"\x93NUMPY\x02\x00".to_vec();
    file.extend_from_slice(&u32::MAX.to_le_bytes());
    file.extend_from_slice(b"{'descr': '<f8'");
    assert!(npy::read(&file).is_err());
    let mut file = b"\x93NUMPY\x02\x00".to_vec();
    file.extend_from_slice(&200_000u32.to_le_bytes());
    file.extend(std::iter::repeat_n(b' ', 200_000));
    assert!(matches!(npy::read(&file), Err(ReadError::Corrupt { .. })));

    // Unknown version, missing keys, garbage dict.
    let mut v9 = npy_file(1, &dict("<f8", false, "(2, 3)"), &[0u8; 48]);
    v9[6] = 9;
    assert!(matches!(npy::read(&v9), Err(ReadError::Unsupported { .. })));
    for header in [
        "{}",
        "{'descr': '<f8', 'shape': (2, 3)}",
        "not a dict",
        "{'descr': '<f8'",
        "{'shape': (2, x)}",
    ] {
        assert!(
            npy::read(&npy_file(1, header, &[0u8; 48])).is_err(),
            "{header}"
        );
    }
}

#[test]
fn truncation_at_every_cut_point_is_an_error() {
    let channel = ImageChannel::new(
        "z",
        "m",
        Array2::from_shape_fn((3, 4), |(r, c)| (r * 4 + c) as f64),
    );
    let mut bytes = Vec::new();
    npy::write(&channel, &mut bytes).unwrap();
    for cut in 0..bytes.len() {
        assert!(npy::read(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    assert!(npy::read(&bytes).is_ok());
}

#[test]
fn random_bytes_are_rejected() {
    let mut state = 0x2545F4914F6CDD1Du64;
    for len in [0usize, 1, 5, 10, 64, 200, 1000] {
        for _ in 0..20 {
            let mut bytes: Vec<u8> = (0..len)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    state as u8
                })
                .collect();
            assert!(npy::read(&bytes).is_err());
            if bytes.len() >= 8 {
                bytes[..8].copy_from_slice(b"\x93NUMPY\x01\x00");
                let _ = npy::read(&bytes);
            }
        }
    }
}

fn small_valid_file() -> Vec<u8> {
    let z = Array2::from_shape_fn((3, 5), |(r, c)| r as f64 - c as f64 * 0.5);
    let mut bytes = Vec::new();
    npy::write(&ImageChannel::new("z", "m", z), &mut bytes).unwrap();
    bytes
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn mutated_files_never_panic(
        edits in prop::collection::vec((0usize..400, any::<u8>()), 1..8),
        cut in 0usize..400,
    ) {
        let mut bytes = small_valid_file();
        for (position, value) in edits {
            let len = bytes.len();
            bytes[position % len] = value;
        }
        let cut = cut.min(bytes.len());
        for candidate in [&bytes[..], &bytes[..cut]] {
            if let Ok(scan) = npy::read(candidate) {
                let z = &scan.pairs[0].trace().unwrap().z;
                prop_assert!(z.len() <= candidate.len());
            }
        }
    }
}

#[test]
fn a_stack_is_one_three_dimensional_array_in_page_order() {
    let a = Array2::from_shape_fn((2, 3), |(r, c)| (r * 3 + c) as f64);
    let b = a.mapv(|v| -v);
    let mut bytes = Vec::new();
    npy::write_stack(&[&a, &b], &mut bytes).unwrap();
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + header_len]).unwrap();
    assert!(header.contains("'shape': (2, 2, 3)"), "{header}");
    let data: Vec<f64> = bytes[10 + header_len..]
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert_eq!(data, [0., 1., 2., 3., 4., 5., -0., -1., -2., -3., -4., -5.]);
    assert!((10 + header_len).is_multiple_of(64));
    let odd = Array2::<f64>::zeros((3, 2));
    assert!(npy::write_stack(&[&a, &odd], &mut Vec::new()).is_err());
}
