//! A bounds-checked cursor over a byte slice, for the binary readers.
//!
//! Every read checks the remaining length first and reports [`ReadError::Truncated`] naming
//! what was being read, so a hostile or cut file can never cause a panic or an allocation
//! larger than the file itself.

use dhct_scan::FileFormat;

use crate::ReadError;

/// A little- or big-endian reader over `bytes`, starting at `position`.
#[derive(Debug, Clone)]
pub struct ByteReader<'a> {
    bytes: &'a [u8],
    position: usize,
    format: FileFormat,
}

impl<'a> ByteReader<'a> {
    /// A reader at offset 0; errors name `format`.
    pub fn new(bytes: &'a [u8], format: FileFormat) -> ByteReader<'a> {
        ByteReader {
            bytes,
            position: 0,
            format,
        }
    }

    /// Current offset in bytes.
    pub fn position(&self) -> usize {
        self.position
    }

    /// Total length of the underlying slice.
    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    /// True when the underlying slice is empty.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// Moves to `offset`; fails if it lies beyond the end.
    pub fn seek(&mut self, offset: u64, what: &str) -> Result<(), ReadError> {
        self.check(offset, 0, what)?;
        self.position = offset as usize;
        Ok(())
    }

    /// The `len` bytes at `offset` (independent of the cursor).
    pub fn slice_at(&self, offset: u64, len: u64, what: &str) -> Result<&'a [u8], ReadError> {
        self.check(offset, len, what)?;
        Ok(&self.bytes[offset as usize..(offset + len) as usize])
    }

    /// The next `len` bytes; advances the cursor.
    pub fn take(&mut self, len: u64, what: &str) -> Result<&'a [u8], ReadError> {
        let slice = self.slice_at(self.position as u64, len, what)?;
        self.position += len as usize;
        Ok(slice)
    }

    fn check(&self, offset: u64, len: u64, what: &str) -> Result<(), ReadError> {
        let file_len = self.bytes.len() as u64;
        match offset.checked_add(len) {
            Some(end) if end <= file_len => Ok(()),
            _ => Err(ReadError::Truncated {
                format: self.format,
                what: what.to_string(),
                offset,
                needed: len,
                len: file_len,
            }),
        }
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], ReadError> {
        let slice = self.take(N as u64, what)?;
        let mut out = [0u8; N];
        out.copy_from_slice(slice);
        Ok(out)
    }

    /// The next byte; `what` names it in a truncation error.
    pub fn u8(&mut self, what: &str) -> Result<u8, ReadError> {
        Ok(self.array::<1>(what)?[0])
    }
    /// The next little-endian `u16`.
    pub fn u16_le(&mut self, what: &str) -> Result<u16, ReadError> {
        Ok(u16::from_le_bytes(self.array(what)?))
    }
    /// The next little-endian `u32`.
    pub fn u32_le(&mut self, what: &str) -> Result<u32, ReadError> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }
    /// The next little-endian `i32`.
    pub fn i32_le(&mut self, what: &str) -> Result<i32, ReadError> {
        Ok(i32::from_le_bytes(self.array(what)?))
    }
    /// The next little-endian `u64`.
    pub fn u64_le(&mut self, what: &str) -> Result<u64, ReadError> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }
    /// The next little-endian `f32`.
    pub fn f32_le(&mut self, what: &str) -> Result<f32, ReadError> {
        Ok(f32::from_le_bytes(self.array(what)?))
    }
    /// The next little-endian `f64`.
    pub fn f64_le(&mut self, what: &str) -> Result<f64, ReadError> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }
    /// The next big-endian `u16`.
    pub fn u16_be(&mut self, what: &str) -> Result<u16, ReadError> {
        Ok(u16::from_be_bytes(self.array(what)?))
    }
    /// The next big-endian `u32`.
    pub fn u32_be(&mut self, what: &str) -> Result<u32, ReadError> {
        Ok(u32::from_be_bytes(self.array(what)?))
    }
    /// The next big-endian `f32`.
    pub fn f32_be(&mut self, what: &str) -> Result<f32, ReadError> {
        Ok(f32::from_be_bytes(self.array(what)?))
    }
}

/// `rows · columns · bytes_per_value` without overflow, or a typed error naming the sizes.
pub fn checked_data_len(
    format: FileFormat,
    rows: u64,
    columns: u64,
    bytes_per_value: u64,
) -> Result<u64, ReadError> {
    rows.checked_mul(columns)
        .and_then(|n| n.checked_mul(bytes_per_value))
        .ok_or_else(|| {
            ReadError::corrupt(
                format,
                format!("image size {columns} x {rows} px is too large to be real"),
            )
        })
}
