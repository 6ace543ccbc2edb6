//! The GWY serialization: a tree of typed objects, decoded from a byte slice.
//!
//! # Format (Gwyddion user guide, "Gwyddion Native File Format")
//!
//! A serialized object is its type name (a NUL-terminated string), a little-endian `u32`
//! giving the byte size of its components, then the components. Each component is its name
//! (NUL-terminated), a one-byte type and the value:
//!
//! | type | value |
//! |---|---|
//! | `b`, `c` | one byte (boolean, character) |
//! | `i`, `q` | 32-bit, 64-bit little-endian integer |
//! | `d` | 64-bit little-endian IEEE double |
//! | `s` | NUL-terminated UTF-8 string |
//! | `o` | a nested serialized object |
//! | `C`, `I`, `Q`, `D`, `S`, `O` | an array: `u32` count, then that many values of the lower-case type |
//!
//! Arrays of numbers are kept as byte slices of the input (nothing is copied until a reader
//! decodes the one it needs); every count and size is checked against the bytes that remain
//! before it is used, and objects may nest at most [`MAX_DEPTH`] deep, so a hostile file
//! gives a typed error, never a panic, a deep recursion or a large allocation.

use dhct_scan::FileFormat;

use crate::ReadError;

const FORMAT: FileFormat = FileFormat::Gwyddion;

/// Deepest nesting of objects accepted (real files nest 3 or 4 deep).
pub const MAX_DEPTH: usize = 32;

/// One component value. Numeric arrays are the raw little-endian bytes of the input.
#[derive(Debug, Clone)]
pub enum Value<'a> {
    /// `b`
    Bool(bool),
    /// `c`
    Char(u8),
    /// `i`
    Int32(i32),
    /// `q`
    Int64(i64),
    /// `d`
    Double(f64),
    /// `s`
    String(String),
    /// `o`
    Object(Object<'a>),
    /// `C`, `I`, `Q` or `D`.
    NumberArray {
        /// Bytes per element.
        element_size: usize,
        /// The raw little-endian elements.
        raw: &'a [u8],
    },
    /// `S`: the strings.
    StringArray(Vec<String>),
    /// `O`
    ObjectArray(Vec<Object<'a>>),
}

/// A deserialized object: its type name and its named components in file order.
#[derive(Debug, Clone)]
pub struct Object<'a> {
    /// The GObject type name, e.g. `GwyContainer`, `GwyDataField`.
    pub type_name: String,
    /// Components in file order.
    pub components: Vec<(String, Value<'a>)>,
}

impl<'a> Object<'a> {
    /// The first component called `name`.
    pub fn get(&self, name: &str) -> Option<&Value<'a>> {
        self.components
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v)
    }

    /// The `i` component `name`.
    pub fn int32(&self, name: &str) -> Option<i32> {
        match self.get(name) {
            Some(Value::Int32(v)) => Some(*v),
            _ => None,
        }
    }

    /// The `d` component `name`.
    pub fn double(&self, name: &str) -> Option<f64> {
        match self.get(name) {
            Some(Value::Double(v)) => Some(*v),
            _ => None,
        }
    }

    /// The `s` component `name`.
    pub fn string(&self, name: &str) -> Option<&str> {
        match self.get(name) {
            Some(Value::String(v)) => Some(v),
            _ => None,
        }
    }

    /// The `o` component `name`.
    pub fn object(&self, name: &str) -> Option<&Object<'a>> {
        match self.get(name) {
            Some(Value::Object(v)) => Some(v),
            _ => None,
        }
    }
}

/// Deserializes the object at the start of `bytes` (after the file magic); returns it and
/// the number of bytes it took.
pub fn parse_object(bytes: &[u8]) -> Result<(Object<'_>, usize), ReadError> {
    let mut cursor = Cursor { bytes, position: 0 };
    let object = cursor.object(0)?;
    Ok((object, cursor.position))
}

/// A bounds-checked position in the serialized bytes.
struct Cursor<'a> {
    bytes: &'a [u8],
    position: usize,
}

impl<'a> Cursor<'a> {
    fn truncated(&self, what: &str, needed: usize) -> ReadError {
        ReadError::Truncated {
            format: FORMAT,
            what: what.to_string(),
            offset: self.position as u64,
            needed: needed as u64,
            len: self.bytes.len() as u64,
        }
    }

    fn take(&mut self, len: usize, what: &str) -> Result<&'a [u8], ReadError> {
        let end = self
            .position
            .checked_add(len)
            .filter(|end| *end <= self.bytes.len())
            .ok_or_else(|| self.truncated(what, len))?;
        let slice = &self.bytes[self.position..end];
        self.position = end;
        Ok(slice)
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], ReadError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N, what)?);
        Ok(out)
    }

    /// A NUL-terminated string (the NUL is consumed, not returned).
    fn string(&mut self, what: &str) -> Result<String, ReadError> {
        let rest = &self.bytes[self.position..];
        let nul = rest.iter().position(|&b| b == 0).ok_or_else(|| {
            self.truncated(&format!("{what} (no terminating NUL)"), rest.len() + 1)
        })?;
        let text = String::from_utf8_lossy(&rest[..nul]).into_owned();
        self.position += nul + 1;
        Ok(text)
    }

    fn object(&mut self, depth: usize) -> Result<Object<'a>, ReadError> {
        if depth >= MAX_DEPTH {
            return Err(ReadError::corrupt(
                FORMAT,
                format!("objects nest deeper than {MAX_DEPTH} levels"),
            ));
        }
        let type_name = self.string("object type name")?;
        let size = u32::from_le_bytes(self.array(&format!("size of {type_name}"))?) as usize;
        let start = self.position;
        let end = start
            .checked_add(size)
            .filter(|end| *end <= self.bytes.len())
            .ok_or_else(|| self.truncated(&format!("{type_name} components"), size))?;
        // Components are parsed within the object's own extent.
        let mut inner = Cursor {
            bytes: &self.bytes[..end],
            position: start,
        };
        let mut components = Vec::new();
        while inner.position < end {
            let name = inner.string(&format!("component name in {type_name}"))?;
            let value = inner.value(&name, depth)?;
            components.push((name, value));
        }
        self.position = end;
        Ok(Object {
            type_name,
            components,
        })
    }

    fn value(&mut self, name: &str, depth: usize) -> Result<Value<'a>, ReadError> {
        let [kind] = self.array::<1>(&format!("type of {name}"))?;
        let what = |suffix: &str| format!("{name} {suffix}");
        Ok(match kind {
            b'b' => Value::Bool(self.array::<1>(&what("value"))?[0] != 0),
            b'c' => Value::Char(self.array::<1>(&what("value"))?[0]),
            b'i' => Value::Int32(i32::from_le_bytes(self.array(&what("value"))?)),
            b'q' => Value::Int64(i64::from_le_bytes(self.array(&what("value"))?)),
            b'd' => Value::Double(f64::from_le_bytes(self.array(&what("value"))?)),
            b's' => Value::String(self.string(&what("string"))?),
            b'o' => Value::Object(self.object(depth + 1)?),
            b'C' | b'I' | b'Q' | b'D' => {
                let element_size = match kind {
                    b'C' => 1,
                    b'I' => 4,
                    b'Q' | b'D' => 8,
                    _ => unreachable!("matched above"),
                };
                let count = u32::from_le_bytes(self.array(&what("array length"))?) as usize;
                // `count` ≤ 2^32 and `element_size` ≤ 8: no overflow on 64-bit targets.
                let len = count.saturating_mul(element_size);
                let raw = self.take(len, &what(&format!("array of {count} values")))?;
                Value::NumberArray { element_size, raw }
            }
            b'S' => {
                let count = u32::from_le_bytes(self.array(&what("array length"))?) as usize;
                // Each string takes at least its NUL byte: bound the count by what remains.
                self.check_count(count, 1, name)?;
                let mut strings = Vec::with_capacity(count);
                for _ in 0..count {
                    strings.push(self.string(&what("string"))?);
                }
                Value::StringArray(strings)
            }
            b'O' => {
                let count = u32::from_le_bytes(self.array(&what("array length"))?) as usize;
                // Each object takes at least a NUL and its 4-byte size.
                self.check_count(count, 5, name)?;
                let mut objects = Vec::with_capacity(count);
                for _ in 0..count {
                    objects.push(self.object(depth + 1)?);
                }
                Value::ObjectArray(objects)
            }
            other => {
                return Err(ReadError::corrupt(
                    FORMAT,
                    format!("component {name} has unknown type byte {other:#04x}"),
                ));
            }
        })
    }

    /// Fails when `count` items of at least `min_size` bytes cannot fit in what remains.
    fn check_count(&self, count: usize, min_size: usize, name: &str) -> Result<(), ReadError> {
        let remaining = self.bytes.len() - self.position;
        if count.saturating_mul(min_size) > remaining {
            return Err(self.truncated(
                &format!("{name}: array of {count} items"),
                count.saturating_mul(min_size),
            ));
        }
        Ok(())
    }
}

/// Decodes a `D` array's raw bytes into doubles.
pub fn doubles(raw: &[u8]) -> impl Iterator<Item = f64> + '_ {
    raw.chunks_exact(8).map(|chunk| {
        let mut b = [0u8; 8];
        b.copy_from_slice(chunk);
        f64::from_le_bytes(b)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn object(name: &str, components: &[u8]) -> Vec<u8> {
        let mut out = name.as_bytes().to_vec();
        out.push(0);
        out.extend_from_slice(&(components.len() as u32).to_le_bytes());
        out.extend_from_slice(components);
        out
    }

    #[test]
    fn parses_nested_objects_and_arrays() {
        let mut unit = b"unitstr\0sm\0".to_vec();
        unit = object("GwySIUnit", &unit);
        let mut field = b"xres\0i".to_vec();
        field.extend_from_slice(&2i32.to_le_bytes());
        field.extend_from_slice(b"si_unit_z\0o");
        field.extend_from_slice(&unit);
        field.extend_from_slice(b"data\0D");
        field.extend_from_slice(&2u32.to_le_bytes());
        field.extend_from_slice(&1.5f64.to_le_bytes());
        field.extend_from_slice(&(-2.0f64).to_le_bytes());
        let bytes = object("GwyDataField", &field);
        let (parsed, used) = parse_object(&bytes).unwrap();
        assert_eq!(used, bytes.len());
        assert_eq!(parsed.type_name, "GwyDataField");
        assert_eq!(parsed.int32("xres"), Some(2));
        assert_eq!(
            parsed.object("si_unit_z").and_then(|u| u.string("unitstr")),
            Some("m")
        );
        let Some(Value::NumberArray { raw, .. }) = parsed.get("data") else {
            panic!("no data array");
        };
        assert_eq!(doubles(raw).collect::<Vec<_>>(), vec![1.5, -2.0]);
    }

    #[test]
    fn hostile_sizes_and_nesting_are_typed_errors() {
        // An array claiming 2^32-1 doubles in a tiny object.
        let mut field = b"data\0D".to_vec();
        field.extend_from_slice(&u32::MAX.to_le_bytes());
        let bytes = object("GwyDataField", &field);
        assert!(matches!(
            parse_object(&bytes),
            Err(ReadError::Truncated { .. })
        ));
        // An object size beyond the end.
        let mut bytes = object("GwyContainer", b"");
        bytes[13..17].copy_from_slice(&1000u32.to_le_bytes());
        assert!(parse_object(&bytes).is_err());
        // Objects nested deeper than MAX_DEPTH.
        let mut nested = object("X", b"");
        for _ in 0..MAX_DEPTH + 2 {
            let mut component = b"o\0o".to_vec();
            component.extend_from_slice(&nested);
            nested = object("X", &component);
        }
        let error = parse_object(&nested).unwrap_err();
        assert!(error.to_string().contains("nest"), "{error}");
        // An unknown type byte.
        let bytes = object("X", b"a\0z");
        assert!(parse_object(&bytes).is_err());
    }
}
