//! Mutation corpus for every reader: every scan file in `tests/data`, the Gwyddion, Nanosurf
//! and Nanoscope files of `tests/data/real`, small files written by
//! dhct's own writers (SM4, GSF, NPY, float32 and 16-bit TIFF), and — when the environment
//! variable `DHCT_REAL_DATA` names a directory — the real files there, each cut short at
//! many points, with bytes flipped and with the numbers of its header replaced by hostile
//! ones (0, −1, NaN, 1e300, 2^32−1 ...). Every mutant must give a value or a typed error: no
//! panic, no read slower than [`MAX_READ`], and nothing allocated beyond the test's
//! [`ReadLimits`]. Special files (a FIFO, `/dev/zero`, a directory) are refused at once.

use std::io::Write as _;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanFile, ScanGeometry, ScanPair};
use dhct_sm4_io::{ReadError, ReadLimits, gsf, npy, read_bytes_limited, sm4, tiff_file};
use ndarray::Array2;

/// Slowest acceptable read of one mutant (debug build).
const MAX_READ: Duration = Duration::from_secs(5);

/// Limits of the test: far below the defaults, so a header that claims a huge image is
/// refused by the budget rather than by the machine.
const LIMITS: ReadLimits = ReadLimits {
    max_bytes: 160 << 20,
    max_pixels: 1 << 23,
};

/// A deterministic xorshift generator.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn repository_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Small files from dhct's writers: one per writable reader format.
fn written_files() -> Vec<(String, Vec<u8>)> {
    let (columns, rows) = (24, 16);
    let z = Array2::from_shape_fn((rows, columns), |(r, c)| {
        1e-10 * ((r as f64 * 0.7).sin() + (c as f64 * 0.4).cos())
    });
    let geometry = ScanGeometry::new(
        columns,
        rows,
        5e-11,
        5e-11,
        1e-3,
        ScanDirection::Right,
        ScanDirection::Down,
    )
    .unwrap();
    let trace = ImageChannel::new("Topography", "m", z.clone());
    let retrace = ImageChannel::new("Topography", "m", z.mapv(|v| v + 1e-12));
    let pair = ScanPair::new(geometry.clone(), trace.clone(), Some(retrace)).unwrap();
    let file = ScanFile {
        format: FileFormat::RhkSm4,
        pairs: vec![pair],
        metadata: Default::default(),
    };
    let mut out = Vec::new();
    let mut sm4_bytes = Vec::new();
    sm4::write(&file, &mut sm4_bytes).unwrap();
    out.push(("written.sm4".to_string(), sm4_bytes));
    let mut gsf_bytes = Vec::new();
    gsf::write(&trace, &geometry, &mut gsf_bytes).unwrap();
    out.push(("written.gsf".to_string(), gsf_bytes));
    let mut npy_bytes = Vec::new();
    npy::write(&trace, &mut npy_bytes).unwrap();
    out.push(("written.npy".to_string(), npy_bytes));
    let mut tiff32 = Vec::new();
    tiff_file::write_f32(&trace, &mut tiff32).unwrap();
    out.push(("written_f32.tiff".to_string(), tiff32));
    let mut tiff16 = Vec::new();
    tiff_file::write_u16(&trace, &mut tiff16).unwrap();
    out.push(("written_u16.tiff".to_string(), tiff16));
    out
}

/// Scan files of a directory (not its notes and configs).
fn files_in(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|entries| entries.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    paths.sort();
    paths
        .into_iter()
        .filter(|p| {
            let ext = p
                .extension()
                .map(|e| e.to_string_lossy().to_lowercase())
                .unwrap_or_default();
            p.is_file() && !matches!(ext.as_str(), "md" | "toml" | "json" | "txt")
        })
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(&p).unwrap())
        })
        .collect()
}

/// Real files vendored in `tests/data/real` of the formats read from there only, the
/// smallest of each layout (the larger 32-bit NID and the Bruker example add ~4 s and no
/// code path the synthetic hostile tests miss).
fn vendored_real_files() -> Vec<(String, Vec<u8>)> {
    let dir = repository_root().join("tests/data/real");
    [
        "gwyfile_test.gwy",
        "moire_4K_10nm.gwy",
        "nanosurf_afm_7um.nid",
        "nanoscope_d3100_2um.000",
    ]
    .into_iter()
    .map(|name| {
        let bytes = std::fs::read(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        (name.to_string(), bytes)
    })
    .collect()
}

/// The real Createc and WSxM files of `tests/data/real` (the older formats' real files are
/// mutated through `DHCT_REAL_DATA`). The 512 × 512 × 4 Createc file is cropped to its top
/// left 64 × 64 pixels (real header, real values), so its mutants read in seconds.
fn real_files_of_later_readers() -> Vec<(String, Vec<u8>)> {
    files_in(&repository_root().join("tests/data/real"))
        .into_iter()
        .filter(|(name, _)| name.starts_with("createc_") || name.starts_with("wsxm_"))
        .map(|(name, bytes)| {
            if name.starts_with("createc_") {
                (
                    format!("{name} (64 x 64 crop)"),
                    cropped_createc(&bytes, 512, 4, 64),
                )
            } else {
                (name, bytes)
            }
        })
        .collect()
}

/// A `[Paramco32]` file of `channels` images of `side × side` cut down to `crop × crop`.
fn cropped_createc(bytes: &[u8], side: usize, channels: usize, crop: usize) -> Vec<u8> {
    use std::io::Read as _;
    let data = bytes.windows(5).position(|w| w == b"\nDATA").unwrap() + 5;
    let mut values = Vec::new();
    flate2::read::ZlibDecoder::new(&bytes[data..])
        .read_to_end(&mut values)
        .unwrap();
    let mut cropped = values[..4].to_vec();
    for image in 0..channels {
        for row in 0..crop {
            let start = 4 + 4 * (image * side * side + row * side);
            cropped.extend_from_slice(&values[start..start + 4 * crop]);
        }
    }
    // Latin-1 text: one char per byte, so the header's other bytes stay as they are.
    let header: String = bytes[..data].iter().map(|&b| b as char).collect();
    let header = header
        .replace(&format!("Num.X={side}"), &format!("Num.X={crop}"))
        .replace(&format!("Num.Y={side}"), &format!("Num.Y={crop}"));
    let mut out: Vec<u8> = header.chars().map(|c| c as u32 as u8).collect();
    let mut encoder = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    encoder.write_all(&cropped).unwrap();
    out.extend(encoder.finish().unwrap());
    out
}

/// Hostile replacements for a number in a text header.
const NUMBERS: [&str; 8] = [
    "0",
    "-1",
    "nan",
    "1e300",
    "-inf",
    "4294967295",
    "99999999999999999999",
    "0.000000000000000000001",
];

/// Hostile 32-bit words for binary headers.
const WORDS: [u32; 6] = [0, 1, 0xFFFF_FFFF, 0x7FFF_FFFF, 0x7FC0_0000, 0x8000_0000];

/// The mutants of one file: truncations, byte flips, edited header numbers and words.
fn mutants(bytes: &[u8], seed: u64) -> Vec<(String, Vec<u8>)> {
    let mut rng = Rng(seed | 1);
    let mut out = Vec::new();
    let len = bytes.len();
    let head = len.min(4096);
    // Truncations: the first bytes, inside the header, and through the data.
    let mut cuts: Vec<usize> = vec![0, 1, 2, 7, 40, 100, 300, len / 2, len.saturating_sub(1)];
    cuts.extend((0..24).map(|_| rng.below(head)));
    cuts.extend((0..12).map(|_| rng.below(len)));
    for cut in cuts.into_iter().filter(|&c| c < len) {
        out.push((format!("cut at {cut}"), bytes[..cut].to_vec()));
    }
    // Byte flips, mostly in the header.
    for k in 0..120 {
        let at = if k % 4 == 3 {
            rng.below(len)
        } else {
            rng.below(head)
        };
        let mut m = bytes.to_vec();
        m[at] ^= 1 << rng.below(8);
        if k % 3 == 0 {
            m[at] = 0xFF;
        }
        out.push((format!("flip at {at}"), m));
    }
    // Header numbers (text formats): replace digit runs by hostile numbers.
    let text_head = &bytes[..len.min(16384)];
    let mut runs = Vec::new();
    let mut i = 0;
    while i < text_head.len() {
        if text_head[i].is_ascii_digit() {
            let start = i;
            while i < text_head.len()
                && (text_head[i].is_ascii_digit() || matches!(text_head[i], b'.' | b'e' | b'-'))
            {
                i += 1;
            }
            runs.push((start, i));
        }
        i += 1;
    }
    for _ in 0..runs.len().min(96) {
        let (start, end) = runs[rng.below(runs.len())];
        let number = NUMBERS[rng.below(NUMBERS.len())];
        let mut m = bytes[..start].to_vec();
        m.extend_from_slice(number.as_bytes());
        m.extend_from_slice(&bytes[end..]);
        out.push((format!("number at {start} -> {number}"), m));
    }
    // Header words (binary formats): aligned 32-bit fields of the first kilobytes.
    for _ in 0..96 {
        let at = rng.below(head.saturating_sub(4) / 4) * 4;
        if at + 4 > len {
            continue;
        }
        let word = WORDS[rng.below(WORDS.len())];
        let mut m = bytes.to_vec();
        m[at..at + 4].copy_from_slice(&word.to_le_bytes());
        out.push((format!("word at {at} -> {word:#x}"), m));
    }
    out
}

/// Reads every mutant of `bytes`; returns (mutants, errors). Panics name the mutant.
fn read_mutants(name: &str, bytes: &[u8], seed: u64) -> (usize, usize) {
    let list = mutants(bytes, seed);
    let mut errors = 0;
    for (what, mutant) in &list {
        let start = Instant::now();
        let result = catch_unwind(AssertUnwindSafe(|| read_bytes_limited(mutant, &LIMITS)));
        let elapsed = start.elapsed();
        match result {
            Err(_) => panic!("{name}, {what}: the reader panicked"),
            Ok(Err(_)) => errors += 1,
            Ok(Ok(file)) => {
                for pair in &file.pairs {
                    let g = pair.geometry();
                    assert!(
                        g.pitch_x().is_finite() && g.pixel_period().is_finite(),
                        "{name}, {what}: non-finite geometry accepted"
                    );
                }
            }
        }
        assert!(
            elapsed < MAX_READ,
            "{name}, {what}: the read took {elapsed:?}"
        );
    }
    (list.len(), errors)
}

#[test]
fn every_reader_survives_its_mutation_corpus() {
    let start = Instant::now();
    let mut corpus = written_files();
    corpus.extend(files_in(&repository_root().join("tests/data")));
    corpus.extend(vendored_real_files());
    corpus.extend(real_files_of_later_readers());
    match std::env::var_os("DHCT_REAL_DATA") {
        Some(dir) => {
            let real = files_in(Path::new(&dir));
            assert!(!real.is_empty(), "DHCT_REAL_DATA is set but holds no files");
            corpus.extend(real);
        }
        None => eprintln!("note: DHCT_REAL_DATA is not set; the real files are not mutated"),
    }
    let mut total = 0;
    for (k, (name, bytes)) in corpus.iter().enumerate() {
        let format = dhct_sm4_io::detect_format(bytes);
        assert!(
            format.is_some(),
            "{name}: the unmutated file is not recognised"
        );
        let file_start = Instant::now();
        let (count, errors) = read_mutants(name, bytes, 0x9E37_79B9 + k as u64);
        eprintln!(
            "{name} ({format:?}): {count} mutants, {errors} errors, {:?}",
            file_start.elapsed()
        );
        total += count;
    }
    eprintln!(
        "{total} mutants of {} files in {:?}",
        corpus.len(),
        start.elapsed()
    );
    assert!(
        total >= 300 * corpus.len(),
        "the corpus is smaller than planned: {total}"
    );
}

#[test]
fn the_matrix_reader_survives_mutations_of_either_file_of_its_pair() {
    let dir = repository_root().join("tests/data/real");
    let data_name = "20201111--4_1.Z_mtrx";
    let data = std::fs::read(dir.join(data_name)).unwrap();
    let parameters = std::fs::read(dir.join("20201111_0001.mtrx")).unwrap();
    let read = |data: &[u8], parameters: &[u8]| {
        dhct_sm4_io::matrix::read_pair(data, data_name, parameters, &LIMITS)
    };
    assert!(read(&data, &parameters).is_ok());
    let mut total = 0;
    for (which, k) in [("data", 0u64), ("parameters", 1)] {
        let original = if k == 0 { &data } else { &parameters };
        for (what, mutant) in mutants(original, 0x5EED + k) {
            let start = Instant::now();
            let result = catch_unwind(AssertUnwindSafe(|| {
                if k == 0 {
                    read(&mutant, &parameters)
                } else {
                    read(&data, &mutant)
                }
            }));
            assert!(
                result.is_ok(),
                "MATRIX {which}, {what}: the reader panicked"
            );
            if let Ok(Ok(file)) = result {
                for pair in &file.pairs {
                    assert!(pair.geometry().pitch_x().is_finite(), "{which}, {what}");
                }
            }
            assert!(
                start.elapsed() < MAX_READ,
                "MATRIX {which}, {what}: too slow"
            );
            total += 1;
        }
    }
    assert!(total >= 600, "{total} mutants");
}

#[test]
fn the_png_picture_reader_survives_its_mutation_corpus() {
    use dhct_sm4_io::png_file::{Picture, read_picture, write_picture};
    let (columns, rows) = (24, 16);
    let grey: Vec<f64> = (0..columns * rows).map(|k| (k % 7) as f64 / 6.0).collect();
    let alpha: Vec<f64> = (0..columns * rows).map(|k| (k % 2) as f64).collect();
    for (k, with_alpha) in [false, true].into_iter().enumerate() {
        let picture = Picture {
            columns,
            rows,
            grey: grey.clone(),
            alpha: with_alpha.then(|| alpha.clone()),
            bit_depth: 8,
        };
        let mut bytes = Vec::new();
        write_picture(&picture, with_alpha, with_alpha, &mut bytes).unwrap();
        for (what, mutant) in mutants(&bytes, 77 + k as u64) {
            let start = Instant::now();
            let result = catch_unwind(AssertUnwindSafe(|| read_picture(&mutant, &LIMITS)));
            assert!(result.is_ok(), "PNG {what}: the reader panicked");
            assert!(start.elapsed() < MAX_READ, "PNG {what}: too slow");
        }
    }
}

#[test]
fn headers_claiming_huge_images_hit_the_budget_before_allocating() {
    // An NPY header claiming 2^30 u1 pixels in a file that holds them would need 8 GiB of
    // f64; a smaller claim within the file still counts its f64 copy.
    let header = "{'descr': '|u1', 'fortran_order': False, 'shape': (4096, 4096), }";
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    let padded = format!("{header:<118}\n");
    bytes.extend_from_slice(&(padded.len() as u16).to_le_bytes());
    bytes.extend_from_slice(padded.as_bytes());
    bytes.extend(std::iter::repeat_n(0u8, 4096 * 4096));
    let tight = ReadLimits {
        max_bytes: 64 << 20,
        max_pixels: 1 << 28,
    };
    let error = read_bytes_limited(&bytes, &tight).unwrap_err();
    assert!(
        matches!(error, ReadError::OverBudget { unit: "bytes", .. }),
        "{error}"
    );
    let few_pixels = ReadLimits {
        max_bytes: 1 << 30,
        max_pixels: 1 << 20,
    };
    let error = read_bytes_limited(&bytes, &few_pixels).unwrap_err();
    assert!(error.to_string().contains("pixels"), "{error}");
    assert!(read_bytes_limited(&bytes, &ReadLimits::default()).is_ok());
}

#[test]
fn a_tiff_bomb_is_refused_before_decoding() {
    // A deflate-compressed 8-bit image of 12288 x 12288 zeros: ~150 KB on disk, 151 MB
    // decoded and 1.2 GB as f64.
    use tiff::encoder::{Compression, DeflateLevel, TiffEncoder, colortype};
    let side = 12288u32;
    let mut bytes = std::io::Cursor::new(Vec::new());
    {
        let mut encoder = TiffEncoder::new(&mut bytes)
            .unwrap()
            .with_compression(Compression::Deflate(DeflateLevel::default()));
        let image = encoder.new_image::<colortype::Gray8>(side, side).unwrap();
        image
            .write_data(&vec![0u8; side as usize * side as usize])
            .unwrap();
    }
    let bytes = bytes.into_inner();
    assert!(bytes.len() < 4 << 20, "{} bytes", bytes.len());
    let start = Instant::now();
    let error = read_bytes_limited(&bytes, &ReadLimits::default()).unwrap_err();
    assert!(start.elapsed() < MAX_READ);
    let message = error.to_string();
    assert!(
        message.contains("bytes") || message.contains("memory"),
        "{message}"
    );
}

/// Runs `f` on another thread and fails instead of hanging if it takes over 10 s.
fn within_ten_seconds<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    let (send, receive) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = send.send(f());
    });
    receive
        .recv_timeout(Duration::from_secs(10))
        .expect("the read blocked for over 10 s")
}

#[test]
fn special_files_are_refused_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("pipe.sm4");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|s| s.success()) {
        let path = fifo.clone();
        let error = within_ten_seconds(move || dhct_sm4_io::read_path(&path))
            .expect_err("a FIFO is not a scan");
        let message = error.to_string();
        assert!(
            message.contains("named pipe") && message.contains("pipe.sm4"),
            "{message}"
        );
    } else {
        eprintln!("note: mkfifo is not available; the FIFO case was not run");
    }
    for device in ["/dev/zero", "/dev/urandom"] {
        if Path::new(device).exists() {
            let error = within_ten_seconds(move || dhct_sm4_io::read_path(Path::new(device)))
                .expect_err("a device is not a scan");
            assert!(error.to_string().contains("device"), "{error}");
        }
    }
    let error = dhct_sm4_io::read_path(dir.path()).unwrap_err();
    assert!(error.to_string().contains("directory"), "{error}");
    // A regular file larger than the limit is refused before it is read.
    let big = dir.path().join("big.npy");
    let mut file = std::fs::File::create(&big).unwrap();
    file.write_all(&[0u8; 4096]).unwrap();
    let tiny = ReadLimits {
        max_bytes: 1000,
        max_pixels: 1 << 20,
    };
    let error = dhct_sm4_io::read_path_limited(&big, &tiny).unwrap_err();
    assert!(
        matches!(error, ReadError::FileTooLarge { bytes: 4096, .. }),
        "{error}"
    );
}
