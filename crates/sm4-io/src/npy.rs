//! NumPy `.npy` arrays: a reader for 2-D numeric arrays and a writer (`<f8`, C order).
//!
//! # Format (NumPy `numpy.lib.format`, NEP 1)
//!
//! | bytes | content |
//! |---|---|
//! | 6 | magic `\x93NUMPY` |
//! | 2 | format version, major and minor: 1.0, 2.0 or 3.0 |
//! | 2 (v1) or 4 (v2, v3) | header length `HEADER_LEN`, little-endian unsigned |
//! | `HEADER_LEN` | a Python dict literal `{'descr': '<f8', 'fortran_order': False, 'shape': (R, C), }`, space-padded and ending in `\n` so that the data starts on a multiple of 64 (16 in old files) |
//! | rest | the elements, `R·C·itemsize` bytes, C (row-major) or Fortran (column-major) order |
//!
//! The header is ASCII/latin-1 in versions 1 and 2 and UTF-8 in version 3.
//!
//! # What dhct reads
//!
//! Two-dimensional arrays of `f4`, `f8`, `i1`…`i8`, `u1`…`u8` or `b1` (bool, read as 0 and 1)
//! in either byte order and either memory order. Other shapes, structured or object dtypes and half floats are rejected with a
//! typed error. Row 0 of the array is taken as the top row of the image (the NumPy/matplotlib
//! `imshow` convention).
//!
//! An `.npy` file carries no physical scale and no timing, so both are placeholders marked
//! [`ValueSource::Assumed`]: pixel pitch [`ASSUMED_PITCH`] along x and y, pixel period
//! [`ASSUMED_PIXEL_PERIOD`], fast direction right, slow direction down. Supply the real values
//! with [`crate::GeometryOverrides`]. The channel is called [`CHANNEL_NAME`] with an empty
//! (unknown) unit. Read by path ([`crate::read_path`]), a file with the JSON [`Sidecar`]
//! dhct writes beside it (`NAME.json`) gets its geometry, channel name and unit from the
//! sidecar, and is paired with its other pass (`…trace…` ↔ `…retrace…`) when that has a
//! sidecar of the same scan.
//!
//! # Hostile input
//!
//! The header length is bounded by [`MAX_HEADER_LEN`] and by the file length; the element
//! count is computed with overflow checks and compared with the bytes present before anything
//! is allocated.

use std::io::Write;

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPair, ValueSource};
use ndarray::{Array2, ShapeBuilder};

use crate::bytes::{ByteReader, checked_data_len};
use crate::limits::{Budget, ReadLimits};
use crate::{ReadError, ScanFile, WriteError};

const FORMAT: FileFormat = FileFormat::Npy;
const MAGIC: &[u8] = b"\x93NUMPY";

use crate::placeholders::{
    ASSUMED_PITCH, ASSUMED_PIXEL_PERIOD, ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY,
};

/// Name given to the single channel of an `.npy` file.
pub const CHANNEL_NAME: &str = "array";

/// Largest header accepted, in bytes. NumPy itself refuses headers above 10 000 bytes by
/// default; a 2-D numeric array needs well under 200.
pub const MAX_HEADER_LEN: u64 = 65_536;

/// Reads a 2-D `.npy` array as one trace image with an assumed geometry (see the module docs).
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]): a `u1` array of 1 GiB would become
/// 8 GiB of `f64`, so the decoded size is charged before anything is allocated.
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut budget = Budget::new(limits, bytes.len())?;
    let mut reader = ByteReader::new(bytes, FORMAT);
    let magic = reader.take(MAGIC.len() as u64, "magic string")?;
    if magic != MAGIC {
        return Err(ReadError::wrong_format(
            FORMAT,
            "the file does not start with \\x93NUMPY",
        ));
    }
    let major = reader.u8("format version")?;
    let minor = reader.u8("format version")?;
    let header_len = match (major, minor) {
        (1, 0) => u64::from(reader.u16_le("header length")?),
        (2, 0) | (3, 0) => u64::from(reader.u32_le("header length")?),
        _ => {
            return Err(ReadError::unsupported(
                FORMAT,
                format!("format version {major}.{minor} (only 1.0, 2.0 and 3.0 exist)"),
            ));
        }
    };
    if header_len > MAX_HEADER_LEN {
        return Err(ReadError::corrupt(
            FORMAT,
            format!("header length {header_len} bytes exceeds the limit of {MAX_HEADER_LEN}"),
        ));
    }
    let header_bytes = reader.take(header_len, "array header")?;
    let header_text = if major >= 3 {
        std::str::from_utf8(header_bytes)
            .map_err(|_| ReadError::corrupt(FORMAT, "header is not valid UTF-8"))?
            .to_string()
    } else {
        header_bytes.iter().map(|&b| char::from(b)).collect()
    };
    let header = parse_header(&header_text)?;

    let (rows, columns) = match header.shape.as_slice() {
        [rows, columns] => (*rows, *columns),
        shape => {
            return Err(ReadError::unsupported(
                FORMAT,
                format!(
                    "only 2-D arrays are images; this array has {} dimension(s), shape {:?}",
                    shape.len(),
                    shape
                ),
            ));
        }
    };
    if rows == 0 || columns == 0 {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: format!("the array is empty (shape ({rows}, {columns}))"),
        });
    }
    let data_len = checked_data_len(FORMAT, rows, columns, header.dtype.size)?;
    // The values, then their standard-layout copy for Fortran-order arrays.
    let copies = if header.fortran_order { 2 } else { 1 };
    budget.charge_images(FORMAT, columns, rows, copies, 0)?;
    let data = reader.take(data_len, "array data")?;
    let (rows, columns) = match (usize::try_from(rows), usize::try_from(columns)) {
        (Ok(r), Ok(c)) => (r, c),
        _ => return Err(too_large(rows, columns)),
    };

    let size = header.dtype.size as usize;
    let values: Vec<f64> = data
        .chunks_exact(size)
        .map(|chunk| header.dtype.decode(chunk))
        .collect();
    let shape = (rows, columns).set_f(header.fortran_order);
    let z = Array2::from_shape_vec(shape, values)
        .map_err(|e| ReadError::corrupt(FORMAT, format!("array data does not fit its shape: {e}")))?
        .as_standard_layout()
        .into_owned();

    let geometry =
        assumed_geometry(columns, rows).map_err(|source| ReadError::geometry(FORMAT, source))?;
    let channel = ImageChannel::new(CHANNEL_NAME, "", z);
    let pair = ScanPair::new(geometry, channel, None)
        .map_err(|source| ReadError::geometry(FORMAT, source))?;
    let mut metadata = std::collections::BTreeMap::new();
    metadata.insert("npy dtype".to_string(), header.descr.clone());
    metadata.insert(
        "npy order".to_string(),
        if header.fortran_order { "Fortran" } else { "C" }.to_string(),
    );
    metadata.insert("npy version".to_string(), format!("{major}.{minor}"));
    metadata.insert(ASSUMED_SCALE_KEY.to_string(), "NPY carries no scale".into());
    metadata.insert(
        ASSUMED_TIMING_KEY.to_string(),
        "NPY carries no timing".into(),
    );
    Ok(ScanFile {
        format: FORMAT,
        pairs: vec![pair],
        metadata,
    })
}

/// Writes `channel.z` as a version 1.0 `.npy` file of little-endian `f8` in C order
/// (`numpy.load` gives back an array of shape `(rows, columns)`, row 0 at the top).
/// NaN values are kept. The unit and geometry are not stored: NPY has no place for them (see
/// [`Sidecar`]).
pub fn write<W: Write>(channel: &ImageChannel, w: &mut W) -> Result<(), WriteError> {
    let (rows, columns) = (channel.rows(), channel.columns());
    write_f8(&format!("({rows}, {columns})"), &[&channel.z], w)
}

/// Writes images of one size as one `.npy` array of shape `(pages, rows, columns)`
/// (little-endian `f8`, C order; e.g. a displacement field's `dx`, `dy` as `[0]`, `[1]`).
pub fn write_stack<W: Write>(pages: &[&Array2<f64>], w: &mut W) -> Result<(), WriteError> {
    let (rows, columns) = pages.first().map_or((0, 0), |p| p.dim());
    if pages.iter().any(|p| p.dim() != (rows, columns)) {
        return Err(WriteError::Unrepresentable {
            format: FORMAT,
            reason: "the pages of a stack must have one size".into(),
        });
    }
    write_f8(&format!("({}, {rows}, {columns})", pages.len()), pages, w)
}

/// The `.npy` header for `shape` (Python tuple syntax) and the values of `arrays` in order.
fn write_f8<W: Write>(shape: &str, arrays: &[&Array2<f64>], w: &mut W) -> Result<(), WriteError> {
    let values: usize = arrays.iter().map(|a| a.len()).sum();
    let dict = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}");
    // magic (6) + version (2) + length (2) + dict + padding + '\n' must be a multiple of 64.
    let unpadded = MAGIC.len() + 2 + 2 + dict.len() + 1;
    let padding = (64 - unpadded % 64) % 64;
    let header_len = dict.len() + padding + 1;
    let header_len = u16::try_from(header_len).map_err(|_| WriteError::Unrepresentable {
        format: FORMAT,
        reason: format!("header of {header_len} bytes does not fit a version 1.0 file"),
    })?;
    let mut out = Vec::with_capacity(usize::from(header_len) + 10 + values * 8);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&header_len.to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out.extend(std::iter::repeat_n(b' ', padding));
    out.push(b'\n');
    for value in arrays.iter().flat_map(|a| a.iter()) {
        out.extend_from_slice(&value.to_le_bytes());
    }
    w.write_all(&out)?;
    Ok(())
}

/// What a `.npy` written by dhct holds, for the JSON sidecar written beside it
/// (`NAME.json` for `NAME.npy`): NPY itself has no place for a pixel size, unit or
/// direction. Serialise it with any serde format (dhct writes JSON).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Sidecar {
    /// The array layout: `float64`, C order, shape `[rows, columns]`, row 0 the top row.
    pub array: String,
    /// `[rows, columns]`, pixels.
    pub shape: [usize; 2],
    /// Channel name.
    pub channel: String,
    /// The unit of the values (e.g. `m`).
    pub unit: String,
    /// Metres per pixel along x (columns) and y (rows).
    pub pixel_size_m: [f64; 2],
    /// Whether the source file stated the pixel size or it is a placeholder.
    pub pixel_size_source: dhct_scan::ValueSource,
    /// Seconds per pixel along the fast axis.
    pub pixel_period_s: f64,
    /// Whether the source file stated the pixel period or it is a placeholder.
    pub timing_source: dhct_scan::ValueSource,
    /// `trace` or `retrace`.
    pub pass: String,
    /// Fast direction of this pass (`right`, `left`, `down`, `up`).
    pub fast_direction: String,
    /// Slow direction of this pass (`right`, `left`, `down`, `up`).
    pub slow_direction: String,
    /// What was done to the values (empty for raw data).
    pub corrections: Vec<String>,
}

impl Sidecar {
    /// The sidecar of `channel`, an image of `pass` with `geometry`.
    pub fn new(
        channel: &ImageChannel,
        geometry: &ScanGeometry,
        pass: dhct_scan::ScanPass,
        corrections: Vec<String>,
    ) -> Sidecar {
        let word = |d: dhct_scan::ScanDirection| {
            match d {
                dhct_scan::ScanDirection::Right => "right",
                dhct_scan::ScanDirection::Left => "left",
                dhct_scan::ScanDirection::Down => "down",
                dhct_scan::ScanDirection::Up => "up",
            }
            .to_string()
        };
        let fast = match pass {
            dhct_scan::ScanPass::Trace => geometry.trace_fast(),
            dhct_scan::ScanPass::Retrace => geometry.trace_fast().reversed(),
        };
        Sidecar {
            array: "float64, C order, shape [rows, columns], row 0 = top".into(),
            shape: [channel.rows(), channel.columns()],
            channel: channel.name.clone(),
            unit: channel.unit.clone(),
            pixel_size_m: [geometry.pitch_x(), geometry.pitch_y()],
            pixel_size_source: geometry.scale_source(),
            pixel_period_s: geometry.pixel_period(),
            timing_source: geometry.timing_source(),
            pass: pass.to_string(),
            fast_direction: word(fast),
            slow_direction: word(geometry.slow_direction()),
            corrections,
        }
    }
}

/// The placeholder geometry of formats without scale or timing (see the module docs).
pub(crate) fn assumed_geometry(
    columns: usize,
    rows: usize,
) -> Result<ScanGeometry, dhct_scan::GeometryError> {
    Ok(ScanGeometry::new(
        columns,
        rows,
        ASSUMED_PITCH,
        ASSUMED_PITCH,
        ASSUMED_PIXEL_PERIOD,
        ScanDirection::Right,
        ScanDirection::Down,
    )?
    .with_scale_source(ValueSource::Assumed)
    .with_timing_source(ValueSource::Assumed))
}

fn too_large(rows: u64, columns: u64) -> ReadError {
    ReadError::corrupt(
        FORMAT,
        format!("image size {columns} x {rows} px is too large to be real"),
    )
}

/// The parsed header dict.
#[derive(Debug)]
struct Header {
    descr: String,
    dtype: Dtype,
    fortran_order: bool,
    shape: Vec<u64>,
}

/// A supported element type.
#[derive(Debug, Clone, Copy)]
struct Dtype {
    kind: Kind,
    size: u64,
    little_endian: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Float,
    Signed,
    Unsigned,
    /// NumPy's `bool` (`|b1`): 0 is false, anything else true (read as 1).
    Bool,
}

impl Dtype {
    /// Parses a NumPy type string such as `<f8`, `>i2` or `|u1`.
    fn parse(descr: &str) -> Result<Dtype, ReadError> {
        let unsupported = || {
            ReadError::unsupported(
                FORMAT,
                format!("element type '{descr}' (dhct reads f4, f8, i1-i8, u1-u8, b1)"),
            )
        };
        let mut chars = descr.chars();
        let (order, rest) = match chars.next() {
            Some(c @ ('<' | '>' | '|' | '=')) => (c, chars.as_str()),
            _ => ('=', descr),
        };
        let mut rest_chars = rest.chars();
        let kind = match rest_chars.next() {
            Some('f') => Kind::Float,
            Some('i') => Kind::Signed,
            Some('u') => Kind::Unsigned,
            Some('b') => Kind::Bool,
            _ => return Err(unsupported()),
        };
        let size: u64 = rest_chars.as_str().parse().map_err(|_| unsupported())?;
        let valid = match kind {
            Kind::Float => matches!(size, 4 | 8),
            Kind::Signed | Kind::Unsigned => matches!(size, 1 | 2 | 4 | 8),
            Kind::Bool => size == 1,
        };
        if !valid {
            return Err(unsupported());
        }
        let little_endian = match order {
            '<' => true,
            '>' => false,
            '|' => {
                if size != 1 {
                    return Err(unsupported());
                }
                true
            }
            _ => cfg!(target_endian = "little"),
        };
        Ok(Dtype {
            kind,
            size,
            little_endian,
        })
    }

    /// Decodes one element; `chunk` has exactly `self.size` bytes.
    fn decode(&self, chunk: &[u8]) -> f64 {
        fn array<const N: usize>(chunk: &[u8], little_endian: bool) -> [u8; N] {
            let mut out = [0u8; N];
            for (dst, src) in out.iter_mut().zip(chunk) {
                *dst = *src;
            }
            if !little_endian {
                out.reverse();
            }
            out
        }
        let le = self.little_endian;
        match (self.kind, self.size) {
            (Kind::Float, 4) => f64::from(f32::from_le_bytes(array(chunk, le))),
            (Kind::Float, _) => f64::from_le_bytes(array(chunk, le)),
            (Kind::Signed, 1) => f64::from(i8::from_le_bytes(array(chunk, le))),
            (Kind::Signed, 2) => f64::from(i16::from_le_bytes(array(chunk, le))),
            (Kind::Signed, 4) => f64::from(i32::from_le_bytes(array(chunk, le))),
            (Kind::Signed, _) => i64::from_le_bytes(array(chunk, le)) as f64,
            (Kind::Unsigned, 1) => f64::from(u8::from_le_bytes(array(chunk, le))),
            (Kind::Unsigned, 2) => f64::from(u16::from_le_bytes(array(chunk, le))),
            (Kind::Unsigned, 4) => f64::from(u32::from_le_bytes(array(chunk, le))),
            (Kind::Unsigned, _) => u64::from_le_bytes(array(chunk, le)) as f64,
            (Kind::Bool, _) => f64::from(u8::from(chunk.iter().any(|&b| b != 0))),
        }
    }
}

/// A value of the header dict.
#[derive(Debug)]
enum Value {
    Str(String),
    Bool(bool),
    Tuple(Vec<u64>),
    /// A list (structured dtype) or anything else dhct does not use.
    Other,
}

/// Parses the Python dict literal of the header.
fn parse_header(text: &str) -> Result<Header, ReadError> {
    let mut parser = DictParser {
        chars: text.chars().collect(),
        position: 0,
    };
    let entries = parser.dict()?;
    let mut descr = None;
    let mut fortran_order = None;
    let mut shape = None;
    for (key, value) in entries {
        match (key.as_str(), value) {
            ("descr", Value::Str(s)) => descr = Some(s),
            ("descr", _) => {
                return Err(ReadError::unsupported(
                    FORMAT,
                    "structured (record) arrays are not images",
                ));
            }
            ("fortran_order", Value::Bool(b)) => fortran_order = Some(b),
            ("shape", Value::Tuple(t)) => shape = Some(t),
            ("fortran_order" | "shape", other) => {
                return Err(ReadError::corrupt(
                    FORMAT,
                    format!("header key '{key}' has an invalid value {other:?}"),
                ));
            }
            _ => {}
        }
    }
    let missing = |key: &str| ReadError::corrupt(FORMAT, format!("header lacks the key '{key}'"));
    let descr = descr.ok_or_else(|| missing("descr"))?;
    let dtype = Dtype::parse(&descr)?;
    Ok(Header {
        descr,
        dtype,
        fortran_order: fortran_order.ok_or_else(|| missing("fortran_order"))?,
        shape: shape.ok_or_else(|| missing("shape"))?,
    })
}

/// A minimal parser for the subset of Python literals NumPy writes in headers.
struct DictParser {
    chars: Vec<char>,
    position: usize,
}

impl DictParser {
    fn error(&self, what: &str) -> ReadError {
        ReadError::corrupt(
            FORMAT,
            format!(
                "header dict is malformed at character {}: {what}",
                self.position
            ),
        )
    }

    fn peek(&self) -> Option<char> {
        self.chars.get(self.position).copied()
    }

    fn skip_space(&mut self) {
        while self.peek().is_some_and(char::is_whitespace) {
            self.position += 1;
        }
    }

    fn expect(&mut self, c: char) -> Result<(), ReadError> {
        self.skip_space();
        if self.peek() == Some(c) {
            self.position += 1;
            Ok(())
        } else {
            Err(self.error(&format!("expected '{c}'")))
        }
    }

    fn dict(&mut self) -> Result<Vec<(String, Value)>, ReadError> {
        self.expect('{')?;
        let mut entries = Vec::new();
        loop {
            self.skip_space();
            if self.peek() == Some('}') {
                self.position += 1;
                return Ok(entries);
            }
            let key = self.string()?;
            self.expect(':')?;
            let value = self.value()?;
            entries.push((key, value));
            self.skip_space();
            match self.peek() {
                Some(',') => self.position += 1,
                Some('}') => {}
                _ => return Err(self.error("expected ',' or '}'")),
            }
        }
    }

    fn string(&mut self) -> Result<String, ReadError> {
        self.skip_space();
        let quote = match self.peek() {
            Some(q @ ('\'' | '"')) => q,
            _ => return Err(self.error("expected a quoted string")),
        };
        self.position += 1;
        let mut out = String::new();
        loop {
            match self.peek() {
                None => return Err(self.error("unterminated string")),
                Some(c) if c == quote => {
                    self.position += 1;
                    return Ok(out);
                }
                Some(c) => {
                    out.push(c);
                    self.position += 1;
                }
            }
        }
    }

    fn value(&mut self) -> Result<Value, ReadError> {
        self.skip_space();
        match self.peek() {
            Some('\'' | '"') => Ok(Value::Str(self.string()?)),
            Some('(') => self.tuple(),
            Some('[') => {
                self.skip_brackets()?;
                Ok(Value::Other)
            }
            Some(c) if c.is_alphanumeric() => {
                let start = self.position;
                while self.peek().is_some_and(|c| c.is_alphanumeric() || c == '_') {
                    self.position += 1;
                }
                let word: String = self
                    .chars
                    .get(start..self.position)
                    .unwrap_or(&[])
                    .iter()
                    .collect();
                Ok(match word.as_str() {
                    "True" => Value::Bool(true),
                    "False" => Value::Bool(false),
                    _ => Value::Other,
                })
            }
            _ => Err(self.error("expected a value")),
        }
    }

    fn tuple(&mut self) -> Result<Value, ReadError> {
        self.expect('(')?;
        let mut items = Vec::new();
        loop {
            self.skip_space();
            match self.peek() {
                Some(')') => {
                    self.position += 1;
                    return Ok(Value::Tuple(items));
                }
                Some(c) if c.is_ascii_digit() => {
                    let start = self.position;
                    while self.peek().is_some_and(|c| c.is_ascii_digit()) {
                        self.position += 1;
                    }
                    let digits: String = self
                        .chars
                        .get(start..self.position)
                        .unwrap_or(&[])
                        .iter()
                        .collect();
                    let n: u64 = digits
                        .parse()
                        .map_err(|_| self.error("shape dimension does not fit 64 bits"))?;
                    // Python 2 wrote long integers with an `L` suffix.
                    if matches!(self.peek(), Some('L' | 'l')) {
                        self.position += 1;
                    }
                    items.push(n);
                    self.skip_space();
                    match self.peek() {
                        Some(',') => self.position += 1,
                        Some(')') => {}
                        _ => return Err(self.error("expected ',' or ')' in shape")),
                    }
                }
                _ => return Err(self.error("shape must be a tuple of non-negative integers")),
            }
        }
    }

    fn skip_brackets(&mut self) -> Result<(), ReadError> {
        let mut depth = 0usize;
        while let Some(c) = self.peek() {
            self.position += 1;
            match c {
                '[' | '(' => depth += 1,
                ']' | ')' => {
                    depth = depth.saturating_sub(1);
                    if depth == 0 {
                        return Ok(());
                    }
                }
                _ => {}
            }
        }
        Err(self.error("unterminated list"))
    }
}
