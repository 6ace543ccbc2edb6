//! The MATRIX parameter file (`<session>_0001.mtrx`): a journal of parameter settings,
//! replayed up to the point where it names the data file being read.
//!
//! After the 12-byte file identifier the file is a sequence of blocks: a 4-byte tag (ASCII,
//! stored reversed: `APEE` is `EEPA`), a little-endian `u32` content length, an 8-byte
//! timestamp (absent for the tags in [`UNTIMED`]) and the content. Strings are a `u32` count
//! of UTF-16 code units and the units themselves. Typed values are a 4-byte type tag
//! (`LOOB` bool as `u32`, `GNOL` `i32`, `BUOD` `f64`, `GRTS` string) and the value.
//!
//! | block | content |
//! |---|---|
//! | `APEE` | the initial value of every parameter: groups of (name, unit, value) |
//! | `DOMP` | one parameter changed: group, name, unit, value |
//! | `YSCC` | a container of further blocks |
//! | `TCID` | the channel dictionary: key → (channel name, unit) |
//! | `REFX` | transfer functions: key → (function name, unit, named parameters) |
//! | `FERB` | a data file was written: its name |
//!
//! (Layout learned from the maintained reader `access2thematrix`; written anew here.)

use std::collections::BTreeMap;

use dhct_scan::FileFormat;

use crate::ReadError;
use crate::bytes::ByteReader;

const FORMAT: FileFormat = FileFormat::OmicronMatrix;
/// The identifier every MATRIX file starts with.
pub const FILE_ID: &[u8] = b"ONTMATRX0101";
/// Block tags stored without a timestamp.
const UNTIMED: [&[u8; 4]; 7] = [
    b"REFX", b"NACS", b"TCID", b"SCHC", b"TSNI", b"SXNC", b"LNEG",
];
/// How deeply `YSCC` containers may nest.
const MAX_DEPTH: usize = 8;

/// A typed parameter value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A boolean (`LOOB`).
    Bool(bool),
    /// A 32-bit integer (`GNOL`).
    Long(i32),
    /// A 64-bit float (`BUOD`).
    Double(f64),
    /// A UTF-16 string (`GRTS`).
    Text(String),
}

impl Value {
    /// The value as a number (booleans as 0 or 1); `None` for text.
    pub fn number(&self) -> Option<f64> {
        match self {
            Value::Bool(b) => Some(f64::from(u8::from(*b))),
            Value::Long(v) => Some(f64::from(*v)),
            Value::Double(v) => Some(*v),
            Value::Text(_) => None,
        }
    }
}

/// A transfer function from stored counts to physical values.
#[derive(Debug, Clone, PartialEq)]
pub struct Transfer {
    /// The function's type, e.g. `TFF_Linear1D`.
    pub name: String,
    /// The unit of the physical values.
    pub unit: String,
    /// Its numeric parameters by name, e.g. `Factor`, `Offset`.
    pub parameters: BTreeMap<String, f64>,
}

/// The parameters in force when a data file was written.
#[derive(Debug, Clone, Default)]
pub struct Parameters {
    /// `Group.Name` → (value, unit), e.g. `XYScanner.Width` → (1e-7, "Meter").
    pub values: BTreeMap<String, (Value, String)>,
    /// Channel dictionary key → (channel name, unit).
    pub channels: BTreeMap<u32, (String, String)>,
    /// Transfer functions by channel dictionary key.
    pub transfers: BTreeMap<u32, Transfer>,
    /// True when the journal named the data file (so these are its parameters).
    pub found_data_file: bool,
}

impl Parameters {
    /// The number stored under `key` (`Group.Name`).
    pub fn number(&self, key: &str) -> Option<f64> {
        self.values.get(key).and_then(|(v, _)| v.number())
    }
}

/// Replays the journal `bytes` until the `FERB` block naming `data_file`.
pub fn replay(bytes: &[u8], data_file: &str) -> Result<Parameters, ReadError> {
    if !bytes.starts_with(FILE_ID) {
        return Err(ReadError::wrong_format(
            FORMAT,
            "the parameter file does not start with ONTMATRX0101",
        ));
    }
    let mut parameters = Parameters::default();
    let mut reader = ByteReader::new(bytes, FORMAT);
    reader.seek(FILE_ID.len() as u64, "parameter file identifier")?;
    read_blocks(&mut reader, bytes.len(), data_file, &mut parameters, 0)?;
    Ok(parameters)
}

/// Reads blocks until `end` (or the data file's `FERB`).
fn read_blocks(
    reader: &mut ByteReader<'_>,
    end: usize,
    data_file: &str,
    parameters: &mut Parameters,
    depth: usize,
) -> Result<(), ReadError> {
    if depth > MAX_DEPTH {
        return Err(ReadError::corrupt(
            FORMAT,
            "parameter containers nest too deeply",
        ));
    }
    while reader.position() < end && !parameters.found_data_file {
        let tag: [u8; 4] = reader
            .take(4, "parameter block tag")?
            .try_into()
            .map_err(|_| ReadError::corrupt(FORMAT, "short block tag"))?;
        let len = u64::from(reader.u32_le("parameter block length")?);
        if !UNTIMED.contains(&&tag) {
            reader.take(8, "parameter block timestamp")?;
        }
        let start = reader.position() as u64;
        let content = reader.slice_at(start, len, "parameter block")?;
        let block_end = start + len;
        if block_end > end as u64 {
            return Err(ReadError::corrupt(
                FORMAT,
                "a parameter block overruns its container",
            ));
        }
        let mut inner = ByteReader::new(content, FORMAT);
        match &tag {
            b"APEE" => initial_values(&mut inner, parameters)?,
            b"DOMP" => changed_value(&mut inner, parameters)?,
            b"TCID" => dictionary(&mut inner, parameters)?,
            b"REFX" => transfers(&mut inner, parameters)?,
            b"FERB" => {
                inner.take(4, "data file reference")?;
                if string(&mut inner)? == data_file {
                    parameters.found_data_file = true;
                }
            }
            b"YSCC" => {
                inner.take(4, "container header")?;
                read_blocks(&mut inner, content.len(), data_file, parameters, depth + 1)?;
            }
            _ => {}
        }
        reader.seek(block_end, "next parameter block")?;
    }
    Ok(())
}

fn initial_values(
    reader: &mut ByteReader<'_>,
    parameters: &mut Parameters,
) -> Result<(), ReadError> {
    reader.take(4, "parameter table header")?;
    let groups = reader.u32_le("parameter group count")?;
    for _ in 0..groups {
        let group = string(reader)?;
        let count = reader.u32_le("parameter count")?;
        for _ in 0..count {
            let name = string(reader)?;
            let unit = string(reader)?;
            reader.take(4, "parameter value header")?;
            let value = value(reader)?;
            parameters
                .values
                .insert(format!("{group}.{name}"), (value, unit));
        }
    }
    Ok(())
}

fn changed_value(
    reader: &mut ByteReader<'_>,
    parameters: &mut Parameters,
) -> Result<(), ReadError> {
    reader.take(4, "parameter change header")?;
    let group = string(reader)?;
    let name = string(reader)?;
    let unit = string(reader)?;
    reader.take(4, "parameter value header")?;
    let value = value(reader)?;
    parameters
        .values
        .insert(format!("{group}.{name}"), (value, unit));
    Ok(())
}

fn dictionary(reader: &mut ByteReader<'_>, parameters: &mut Parameters) -> Result<(), ReadError> {
    reader.take(8, "dictionary header")?;
    for _ in 0..reader.u32_le("dictionary entry count")? {
        reader.take(16, "dictionary entry header")?;
        string(reader)?;
        string(reader)?;
    }
    for _ in 0..reader.u32_le("channel count")? {
        reader.take(4, "channel entry header")?;
        let key = reader.u32_le("channel key")?;
        reader.take(8, "channel entry id")?;
        let name = string(reader)?;
        let unit = string(reader)?;
        parameters.channels.insert(key, (name, unit));
    }
    Ok(())
}

fn transfers(reader: &mut ByteReader<'_>, parameters: &mut Parameters) -> Result<(), ReadError> {
    while reader.position() < reader.len() {
        reader.take(4, "transfer function header")?;
        let key = reader.u32_le("transfer function key")?;
        let name = string(reader)?;
        let unit = string(reader)?;
        let mut values = BTreeMap::new();
        for _ in 0..reader.u32_le("transfer parameter count")? {
            let parameter = string(reader)?;
            if let Some(number) = value(reader)?.number() {
                values.insert(parameter, number);
            }
        }
        parameters.transfers.insert(
            key,
            Transfer {
                name,
                unit,
                parameters: values,
            },
        );
    }
    Ok(())
}

/// A UTF-16 string: its length is checked against the block before anything is allocated.
fn string(reader: &mut ByteReader<'_>) -> Result<String, ReadError> {
    let units = u64::from(reader.u32_le("string length")?);
    let bytes = reader.take(units * 2, "string")?;
    let code_units: Vec<u16> = bytes
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect();
    Ok(String::from_utf16_lossy(&code_units))
}

fn value(reader: &mut ByteReader<'_>) -> Result<Value, ReadError> {
    let tag = reader.take(4, "value type")?;
    Ok(match tag {
        b"LOOB" => Value::Bool(reader.u32_le("boolean value")? != 0),
        b"GNOL" => Value::Long(reader.i32_le("integer value")?),
        b"BUOD" => Value::Double(reader.f64_le("real value")?),
        b"GRTS" => Value::Text(string(reader)?),
        other => {
            return Err(ReadError::corrupt(
                FORMAT,
                format!(
                    "unknown parameter value type \"{}\"",
                    String::from_utf8_lossy(other)
                ),
            ));
        }
    })
}
