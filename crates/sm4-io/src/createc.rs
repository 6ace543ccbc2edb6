//! Createc `.dat` image reader (STMAFM software, `[Paramco32]` files).
//!
//! # Format
//!
//! A latin-1 text header of `key=value` lines (CR LF), starting with the line `[Paramco32]`.
//! Many keys carry two names, `Long name / Short name=value` (e.g. `Num.X / Num.X=512`);
//! dhct accepts either. The header ends at a line starting with `DATA`; the bytes right
//! after `DATA` are one zlib stream of little-endian float32 values:
//!
//! * one leading value that is not a pixel (always 0 in the real files);
//! * then `Channels` images of `Num.X × Num.Y` values each, row by row, row 0 at the top,
//!   every line left to right (backward images too: the software stores them in display
//!   order);
//! * then a tail of padding that dhct ignores.
//!
//! `Channelselectval` is a bit set of the recorded signals (bit 0 topography `Z`, bit 1
//! `Current`, higher bits auxiliary inputs). With `k` bits set, `Channels = 2k` means the
//! first `k` images are the forward scans and the next `k` the backward scans of the same
//! signals, in bit order; `Channels = k` means forward scans only. Any other combination is
//! refused as unsupported rather than guessed.
//!
//! The older `[Parameter]` (16-bit) and `[Paramet32]` (uncompressed) variants are recognised
//! but refused: no real file of them has been available to verify the layout.
//!
//! # Calibration (checked on a real file; see `tests/createc.rs`)
//!
//! The values are DAC/ADC counts. With `DAC-Type=<b>bit` and a ±10 V converter, one count is
//! `20 V / 2^b`:
//!
//! * `Z`: metres per count = `20 / 2^b × ZPiezoconst [Å/V] × GainZ × 1e-10`. The header's
//!   rounded `Dacto[A]z` (Å per count at unit gain) must agree within 5 %, else the file is
//!   refused as inconsistent.
//! * `Current`: amperes per count = `20 / 2^b / 10^GainPre` (`Gainpreamp / GainPre 10^`).
//!   On the real file this puts the mean |current| at the `SetPoint` (300 pA).
//! * auxiliary channels stay in counts (unit `DAC`).
//!
//! Lateral: pitch = `Length x[A]` / `Num.X` and `Length y[A]` / `Num.Y` (Å). Timing:
//! `Sec/line:` is the time of one line in one direction (on the real file `Sec/Image:` is
//! twice `Num.Y × Sec/line`); no turnaround is recorded. `Rotation` is the scan angle in
//! degrees. `ScanYDirec=1` is a top-to-bottom (down) scan; any other value is read as up
//! with the rows kept as stored and the timing marked assumed, since no such file was
//! available to confirm the row order.
//!
//! Rows at the end whose values are all exactly 0 in every channel were never acquired (an
//! aborted scan) and become NaN.

use std::collections::BTreeMap;
use std::io::Read;

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPair, ValueSource};

use crate::iso28600::parse_number;
use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{
    ASSUMED_PITCH, ASSUMED_PIXEL_PERIOD, ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY, PLAUSIBLE_PITCH_M,
    PLAUSIBLE_PIXEL_PERIOD_S, PLAUSIBLE_SCAN_ANGLE_RAD, note, plausible,
};
use crate::{ReadError, ScanFile};

const FORMAT: FileFormat = FileFormat::CreatecDat;
/// The first line of the supported, zlib-compressed variant.
const MAGIC: &[u8] = b"[Paramco32]";
/// First lines of the variants that are recognised but not read.
const OLD_MAGICS: [&[u8]; 2] = [b"[Parameter]", b"[Paramet32]"];
/// How far into the file the `DATA` line may start (real headers end before 16 KiB).
const MAX_HEADER: usize = 1 << 20;
/// Largest pixel count per side dhct accepts from a Createc header.
const MAX_SIDE: u64 = 1 << 16;

/// True when `bytes` start like a Createc `.dat` file (any variant).
pub fn looks_like_createc(bytes: &[u8]) -> bool {
    bytes.starts_with(MAGIC) || OLD_MAGICS.iter().any(|m| bytes.starts_with(m))
}

/// The `key=value` header; every key is stored under its full text and under each name of a
/// `Long / Short` pair. The first occurrence of a key wins.
struct Header {
    entries: BTreeMap<String, String>,
}

impl Header {
    fn parse(text: &[u8]) -> Header {
        let mut entries = BTreeMap::new();
        for line in text.split(|b| *b == b'\n') {
            let line: String = line.iter().map(|&b| b as char).collect();
            let Some((key, value)) = line.trim_end_matches(['\r', '\0']).split_once('=') else {
                continue;
            };
            let value = value.trim().to_string();
            let mut names = vec![key.trim()];
            names.extend(key.split(" / ").map(str::trim));
            for name in names.into_iter().filter(|n| !n.is_empty()) {
                entries
                    .entry(name.to_string())
                    .or_insert_with(|| value.clone());
            }
        }
        Header { entries }
    }

    fn get(&self, key: &str) -> Option<&str> {
        self.entries.get(key).map(String::as_str)
    }

    fn number(&self, key: &str) -> Option<f64> {
        self.get(key)
            .and_then(|v| parse_number(&v.replace(',', ".")))
            .filter(|v| v.is_finite())
    }

    fn required(&self, key: &str) -> Result<f64, ReadError> {
        self.number(key).ok_or_else(|| {
            ReadError::corrupt(FORMAT, format!("header lacks a numeric \"{key}\" entry"))
        })
    }

    fn count(&self, key: &str, max: u64) -> Result<usize, ReadError> {
        let value = self.required(key)?;
        if value.fract() != 0.0 || value < 1.0 || value > max as f64 {
            return Err(ReadError::corrupt(
                FORMAT,
                format!("\"{key}\" must be a whole number from 1 to {max}, got {value}"),
            ));
        }
        Ok(value as usize)
    }
}

/// One recorded signal: its name, unit and the factor from counts to that unit.
#[derive(Debug, Clone)]
struct Signal {
    name: String,
    unit: &'static str,
    per_count: f64,
}

/// Reads a Createc `[Paramco32]` `.dat` file: one [`ScanPair`] per recorded signal (see the
/// module docs).
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]).
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut budget = Budget::new(limits, bytes.len())?;
    if let Some(old) = OLD_MAGICS.iter().find(|m| bytes.starts_with(m)) {
        return Err(ReadError::unsupported(
            FORMAT,
            format!(
                "the {} variant (dhct reads [Paramco32] files only)",
                String::from_utf8_lossy(old)
            ),
        ));
    }
    if !bytes.starts_with(MAGIC) {
        return Err(ReadError::wrong_format(
            FORMAT,
            "the file does not start with [Paramco32]",
        ));
    }
    let data_start = find_data_line(bytes)?;
    let header = Header::parse(&bytes[..data_start]);
    let columns = header.count("Num.X", MAX_SIDE)?;
    let rows = header.count("Num.Y", MAX_SIDE)?;
    let channels = header.count("Channels", 64)?;
    let (signals, backward) = signals(&header, channels)?;
    budget.charge_images(FORMAT, columns as u64, rows as u64, channels as u64, 4)?;
    let raw = inflate(&bytes[data_start + 4..], 1 + channels * columns * rows)?;
    let images: Vec<&[u8]> = raw[4..].chunks_exact(columns * rows * 4).collect();
    let (mut metadata, geometry) = describe(&header, columns, rows)?;
    let acquired = acquired_rows(&images, columns, rows);
    if acquired == 0 {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: "every value of every channel is 0 (nothing was acquired)".to_string(),
        });
    }
    if acquired < rows {
        metadata.insert(
            "incomplete scan".to_string(),
            format!("{} of {rows} lines acquired; the rest are NaN", acquired),
        );
    }
    let image = |index: usize, signal: &Signal| {
        let values = images[index]
            .chunks_exact(4)
            .enumerate()
            .map(|(k, v)| {
                if k / columns < acquired {
                    f64::from(f32::from_le_bytes([v[0], v[1], v[2], v[3]])) * signal.per_count
                } else {
                    f64::NAN
                }
            })
            .collect();
        ImageChannel::from_row_major(signal.name.clone(), signal.unit, rows, columns, values)
            .map_err(|source| ReadError::geometry(FORMAT, source))
    };
    let mut pairs = Vec::with_capacity(signals.len());
    for (k, signal) in signals.iter().enumerate() {
        let trace = image(k, signal)?;
        let retrace = if backward {
            Some(image(k + signals.len(), signal)?)
        } else {
            None
        };
        pairs.push(
            ScanPair::new(geometry.clone(), trace, retrace)
                .map_err(|source| ReadError::geometry(FORMAT, source))?,
        );
    }
    Ok(ScanFile {
        format: FORMAT,
        pairs,
        metadata,
    })
}

/// Offset of the `DATA` line that ends the header.
fn find_data_line(bytes: &[u8]) -> Result<usize, ReadError> {
    let window = &bytes[..bytes.len().min(MAX_HEADER)];
    window
        .windows(5)
        .position(|w| w == b"\nDATA")
        .map(|i| i + 1)
        .ok_or_else(|| {
            if bytes.len() < MAX_HEADER {
                ReadError::Truncated {
                    format: FORMAT,
                    what: "the DATA line that ends the header".to_string(),
                    offset: bytes.len() as u64,
                    needed: 4,
                    len: bytes.len() as u64,
                }
            } else {
                ReadError::corrupt(FORMAT, "no DATA line in the first MiB")
            }
        })
}

/// The recorded signals in storage order, and whether backward images follow them.
fn signals(header: &Header, channels: usize) -> Result<(Vec<Signal>, bool), ReadError> {
    let select = header.number("Channelselectval").unwrap_or(0.0);
    let bits: Vec<u32> = if select.fract() == 0.0 && (1.0..=f64::from(u32::MAX)).contains(&select) {
        (0..32)
            .filter(|b| (select as u32) & (1 << b) != 0)
            .collect()
    } else {
        Vec::new()
    };
    let backward = match channels {
        n if !bits.is_empty() && n == 2 * bits.len() => true,
        n if !bits.is_empty() && n == bits.len() => false,
        _ => {
            return Err(ReadError::unsupported(
                FORMAT,
                format!(
                    "Channels={channels} does not match Channelselectval={} ({} signal bit(s)): \
                     dhct cannot tell which image is which",
                    header.get("Channelselectval").unwrap_or("missing"),
                    bits.len()
                ),
            ));
        }
    };
    let volts_per_count = || -> Result<f64, ReadError> {
        let dac = header.get("DAC-Type").unwrap_or("");
        let bits: u32 = dac
            .trim()
            .trim_end_matches("bit")
            .parse()
            .ok()
            .filter(|b| (8..=32).contains(b))
            .ok_or_else(|| {
                ReadError::corrupt(FORMAT, format!("DAC-Type \"{dac}\" is not like \"20bit\""))
            })?;
        Ok(20.0 / 2f64.powi(bits as i32))
    };
    let mut signals = Vec::with_capacity(bits.len());
    for bit in bits {
        signals.push(match bit {
            0 => Signal {
                name: "Z".to_string(),
                unit: "m",
                per_count: z_metres_per_count(header, volts_per_count()?)?,
            },
            1 => {
                let gain = header.required("GainPre 10^")?;
                if !(0.0..=15.0).contains(&gain) {
                    return Err(ReadError::corrupt(
                        FORMAT,
                        format!("GainPre 10^={gain} is not a preamplifier gain exponent"),
                    ));
                }
                Signal {
                    name: "Current".to_string(),
                    unit: "A",
                    per_count: volts_per_count()? / 10f64.powf(gain),
                }
            }
            b => Signal {
                name: format!("Aux{}", b - 1),
                unit: "DAC",
                per_count: 1.0,
            },
        });
    }
    Ok((signals, backward))
}

/// Metres of z per count, checked against the header's own `Dacto[A]z`.
fn z_metres_per_count(header: &Header, volts_per_count: f64) -> Result<f64, ReadError> {
    let piezo = header.required("ZPiezoconst")?;
    let gain = header.required("GainZ")?;
    let per_count = volts_per_count * piezo * gain * 1e-10;
    if !(per_count.is_finite() && per_count > 0.0 && per_count < 1e-3) {
        return Err(ReadError::corrupt(
            FORMAT,
            format!("ZPiezoconst={piezo} and GainZ={gain} give no usable z calibration"),
        ));
    }
    if let Some(stated) = header.number("Dacto[A]z") {
        let implied = volts_per_count * piezo;
        if (stated / implied - 1.0).abs() > 0.05 {
            return Err(ReadError::corrupt(
                FORMAT,
                format!(
                    "the header's Dacto[A]z={stated} Å per count disagrees with \
                     ZPiezoconst={piezo} Å/V × {volts_per_count:.4e} V per count = {implied:.4e}"
                ),
            ));
        }
    }
    Ok(per_count)
}

/// Inflates the zlib stream into the bytes of `count` float32 values, reading no further
/// than needed (so a stream that inflates to more cannot exhaust memory).
fn inflate(stream: &[u8], count: usize) -> Result<Vec<u8>, ReadError> {
    let needed = count.checked_mul(4).ok_or_else(|| {
        ReadError::corrupt(FORMAT, "the image size is too large for this machine")
    })?;
    let mut raw = Vec::new();
    raw.try_reserve_exact(needed)
        .map_err(|_| ReadError::corrupt(FORMAT, "not enough memory for the images"))?;
    let mut decoder = flate2::read::ZlibDecoder::new(stream).take(needed as u64);
    decoder.read_to_end(&mut raw).map_err(|e| {
        ReadError::corrupt(
            FORMAT,
            format!("the zlib image data cannot be inflated: {e}"),
        )
    })?;
    if raw.len() < needed {
        return Err(ReadError::Truncated {
            format: FORMAT,
            what: format!("{count} float32 values inflated from the DATA block"),
            offset: 0,
            needed: needed as u64,
            len: raw.len() as u64,
        });
    }
    Ok(raw)
}

/// Rows from the top up to the last row holding a non-zero value (±0.0 counts as zero) in
/// any image of little-endian float32 bytes.
fn acquired_rows(images: &[&[u8]], columns: usize, rows: usize) -> usize {
    let line = columns * 4;
    let non_zero = |b: &[u8]| b[0] != 0 || b[1] != 0 || b[2] != 0 || b[3] & 0x7F != 0;
    (0..rows)
        .rev()
        .find(|&r| {
            images.iter().any(|image| {
                image[r * line..(r + 1) * line]
                    .chunks_exact(4)
                    .any(non_zero)
            })
        })
        .map_or(0, |r| r + 1)
}

/// Metadata and geometry from the header.
fn describe(
    header: &Header,
    columns: usize,
    rows: usize,
) -> Result<(BTreeMap<String, String>, ScanGeometry), ReadError> {
    let mut metadata = BTreeMap::new();
    let lengths = (header.number("Length x[A]"), header.number("Length y[A]"));
    let (pitch_x, pitch_y, scale_source) = match lengths {
        (Some(x), Some(y))
            if plausible(x.abs() * 1e-10 / columns as f64, &PLAUSIBLE_PITCH_M)
                && plausible(y.abs() * 1e-10 / rows as f64, &PLAUSIBLE_PITCH_M) =>
        {
            let pitch = (
                x.abs() * 1e-10 / columns as f64,
                y.abs() * 1e-10 / rows as f64,
            );
            (pitch.0, pitch.1, ValueSource::Stated)
        }
        _ => {
            note(
                &mut metadata,
                ASSUMED_SCALE_KEY,
                "no usable Length x[A] / Length y[A] in the header",
            );
            (ASSUMED_PITCH, ASSUMED_PITCH, ValueSource::Assumed)
        }
    };
    let scan_down = header.number("ScanYDirec").is_none_or(|d| d == 1.0);
    let line_time = header
        .number("Sec/line:")
        .filter(|t| plausible(t / columns as f64, &PLAUSIBLE_PIXEL_PERIOD_S));
    let mut timing_source = ValueSource::Stated;
    let line_time = line_time.unwrap_or_else(|| {
        note(
            &mut metadata,
            ASSUMED_TIMING_KEY,
            "no usable Sec/line: in the header",
        );
        timing_source = ValueSource::Assumed;
        ASSUMED_PIXEL_PERIOD * columns as f64
    });
    if !scan_down {
        note(
            &mut metadata,
            ASSUMED_TIMING_KEY,
            "ScanYDirec is not 1: read as an upward scan with the rows as stored (unverified)",
        );
        timing_source = ValueSource::Assumed;
    }
    let geometry_error = |source| ReadError::geometry(FORMAT, source);
    let slow = if scan_down {
        ScanDirection::Down
    } else {
        ScanDirection::Up
    };
    let mut geometry = ScanGeometry::from_line_time(
        columns,
        rows,
        pitch_x,
        pitch_y,
        line_time,
        ScanDirection::Right,
        slow,
    )
    .map_err(geometry_error)?
    .with_scale_source(scale_source)
    .with_timing_source(timing_source);
    if let Some(angle) = header.number("Rotation")
        && plausible(angle.to_radians(), &PLAUSIBLE_SCAN_ANGLE_RAD)
    {
        geometry = geometry
            .with_scan_angle(angle.to_radians())
            .map_err(geometry_error)?;
    }
    for (label, key, unit) in [
        ("title", "Titel", ""),
        ("bias", "Biasvolt[mV]", " mV"),
        ("setpoint current", "SetPoint", " A"),
        ("scan time per line", "Sec/line:", " s"),
        ("scan time per image", "Sec/Image:", " s"),
        ("scan length x", "Length x[A]", " Å"),
        ("scan length y", "Length y[A]", " Å"),
        ("scan rotation", "Rotation", " deg"),
        ("DAC type", "DAC-Type", ""),
        ("temperature (T_AUXADC6)", "T_AUXADC6[K]", " K"),
    ] {
        if let Some(value) = header.get(key).filter(|v| !v.is_empty()) {
            metadata.insert(label.to_string(), format!("{value}{unit}"));
        }
    }
    Ok((metadata, geometry))
}
