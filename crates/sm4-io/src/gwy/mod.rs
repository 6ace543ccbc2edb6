//! Gwyddion native file (`.gwy`) reader.
//!
//! # Format
//!
//! The magic `GWYP` and one serialized `GwyContainer` (see [`object`]). Its components are
//! keyed by paths; the images are the `GwyDataField` objects under `/N/data` (N = 0, 1, …)
//! with the channel title in the string `/N/data/title`. A data field holds `xres`, `yres`
//! (pixels along x and y), `xreal`, `yreal` (physical size), optional `xoff`, `yoff`,
//! `si_unit_xy` and `si_unit_z` (`GwySIUnit` objects whose `unitstr` is the unit without
//! prefix, e.g. `m`) and `data`: `xres · yres` doubles, row by row, the first row at the
//! top, the values in `si_unit_z`. Masks, presentations, graphs, spectra, volume data and
//! the old `GWYO` format (Gwyddion 1) are not images dhct uses and are ignored or refused.
//!
//! # Geometry and pairing
//!
//! Gwyddion keeps every image in display orientation, so the data are used as stored. A
//! `.gwy` file has no scan timing and no scan directions: the pixel period is the
//! placeholder [`ASSUMED_PIXEL_PERIOD`], the trace runs right and the slow direction down,
//! all marked [`ValueSource::Assumed`] with the reason under [`ASSUMED_TIMING_KEY`]. Two
//! fields of equal size whose titles differ only in a direction word (`Z (Forward)` and
//! `Z (Backward)`, `Z-Axis forward` and `Z-Axis backward`, `Height Trace` and
//! `Height Retrace`) become one channel with the forward field as the trace and the backward
//! field as the retrace (its fast direction left); every other field is a channel of its own.
//! The pitch is `xreal / xres`, `yreal / yres` when `si_unit_xy` is metres; any other
//! lateral unit, or a size outside [`PLAUSIBLE_PITCH_M`], gives the placeholder
//! [`ASSUMED_PITCH`] (assumed, reason under [`ASSUMED_SCALE_KEY`]). The offsets `xoff`,
//! `yoff` (Gwyddion's top-left corner) are kept in the metadata only.

pub mod object;

use std::collections::BTreeMap;

use dhct_scan::{FileFormat, ImageChannel, ScanDirection, ScanGeometry, ScanPair, ValueSource};

use crate::limits::{Budget, ReadLimits};
use crate::placeholders::{
    ASSUMED_PITCH, ASSUMED_PIXEL_PERIOD, ASSUMED_SCALE_KEY, ASSUMED_TIMING_KEY, PLAUSIBLE_PITCH_M,
    note, plausible,
};
use crate::{ReadError, ScanFile};
use object::{Object, Value, doubles, parse_object};

const FORMAT: FileFormat = FileFormat::Gwyddion;
/// Magic of Gwyddion 2 files.
pub const MAGIC: &[u8] = b"GWYP";
/// Magic of the old Gwyddion 1 format (refused).
pub const OLD_MAGIC: &[u8] = b"GWYO";

/// One `GwyDataField` found under `/N/data`, checked but not yet decoded.
struct Field<'a> {
    index: u32,
    title: String,
    columns: usize,
    rows: usize,
    width: f64,
    height: f64,
    lateral_unit: String,
    unit: String,
    offset: (f64, f64),
    raw: &'a [u8],
}

/// Reads a `.gwy` file: one [`ScanPair`] per data field or forward/backward pair (see the
/// module docs).
pub fn read(bytes: &[u8]) -> Result<ScanFile, ReadError> {
    read_limited(bytes, &ReadLimits::default())
}

/// [`read`] under `limits` (see [`crate::limits`]).
pub fn read_limited(bytes: &[u8], limits: &ReadLimits) -> Result<ScanFile, ReadError> {
    let mut budget = Budget::new(limits, bytes.len())?;
    if bytes.starts_with(OLD_MAGIC) {
        return Err(ReadError::unsupported(
            FORMAT,
            "this is the old Gwyddion 1 format (magic GWYO); open it in Gwyddion 2 and save it again",
        ));
    }
    let body = bytes
        .strip_prefix(MAGIC)
        .ok_or_else(|| ReadError::wrong_format(FORMAT, "the file does not start with GWYP"))?;
    let (container, _) = parse_object(body)?;
    if container.type_name != "GwyContainer" {
        return Err(ReadError::corrupt(
            FORMAT,
            format!(
                "the top object is a {}, not a GwyContainer",
                container.type_name
            ),
        ));
    }
    let fields = data_fields(&container)?;
    if fields.is_empty() {
        return Err(ReadError::NoImage {
            format: FORMAT,
            reason: "the file holds no GwyDataField image under /N/data".to_string(),
        });
    }
    for field in &fields {
        budget.charge_images(FORMAT, field.columns as u64, field.rows as u64, 1, 0)?;
    }
    let mut metadata = BTreeMap::new();
    note(
        &mut metadata,
        ASSUMED_TIMING_KEY,
        "a .gwy file stores no scan timing or scan directions (trace taken as running right, \
         slow direction down)",
    );
    describe_fields(&fields, &mut metadata);
    let mut pairs = Vec::new();
    let mut used = vec![false; fields.len()];
    for i in 0..fields.len() {
        if used[i] {
            continue;
        }
        used[i] = true;
        let partner = partner_of(&fields, i, &used);
        if let Some(j) = partner {
            used[j] = true;
        }
        pairs.push(build_pair(&fields, i, partner, &mut metadata)?);
    }
    Ok(ScanFile {
        format: FORMAT,
        pairs,
        metadata,
    })
}

/// The data fields under `/N/data`, in the order of N.
fn data_fields<'a>(container: &'a Object<'a>) -> Result<Vec<Field<'a>>, ReadError> {
    let mut fields = Vec::new();
    for (key, value) in &container.components {
        let Some(index) = key
            .strip_prefix('/')
            .and_then(|k| k.strip_suffix("/data"))
            .and_then(|n| n.parse::<u32>().ok())
        else {
            continue;
        };
        let Value::Object(object) = value else {
            continue;
        };
        if object.type_name != "GwyDataField" {
            continue;
        }
        let title = match container.get(&format!("/{index}/data/title")) {
            Some(Value::String(t)) if !t.trim().is_empty() => t.trim().to_string(),
            _ => format!("Channel {index}"),
        };
        fields.push(check_field(index, title, object)?);
    }
    fields.sort_by_key(|f| f.index);
    Ok(fields)
}

/// Checks one `GwyDataField`'s sizes against its data before anything is decoded.
fn check_field<'a>(index: u32, title: String, object: &Object<'a>) -> Result<Field<'a>, ReadError> {
    let corrupt = |what: String| ReadError::corrupt(FORMAT, format!("/{index}/data: {what}"));
    let size = |name: &str| match object.int32(name) {
        Some(n) if n > 0 => Ok(n as usize),
        other => Err(corrupt(format!(
            "{name} must be a positive integer, got {other:?}"
        ))),
    };
    let (columns, rows) = (size("xres")?, size("yres")?);
    let real = |name: &str| object.double(name).unwrap_or(f64::NAN);
    let unit = |name: &str| {
        object
            .object(name)
            .and_then(|u| u.string("unitstr"))
            .unwrap_or("")
            .trim()
            .to_string()
    };
    let raw = match object.get("data") {
        Some(Value::NumberArray {
            element_size: 8,
            raw,
        }) => *raw,
        _ => return Err(corrupt("no data array of doubles".to_string())),
    };
    let expected = (columns as u64)
        .checked_mul(rows as u64)
        .and_then(|n| n.checked_mul(8));
    if expected != Some(raw.len() as u64) {
        return Err(corrupt(format!(
            "{columns} x {rows} px need {} doubles but the data array holds {}",
            columns as u64 * rows as u64,
            raw.len() / 8
        )));
    }
    Ok(Field {
        index,
        title,
        columns,
        rows,
        width: real("xreal"),
        height: real("yreal"),
        lateral_unit: unit("si_unit_xy"),
        unit: unit("si_unit_z"),
        offset: (
            object.double("xoff").unwrap_or(0.0),
            object.double("yoff").unwrap_or(0.0),
        ),
        raw,
    })
}

/// Which pass a title names and the title without that word: `Z (Backward)` →
/// (`Z`, backward).
fn split_direction(title: &str) -> Option<(String, bool)> {
    const WORDS: [(&str, bool); 6] = [
        ("forward", false),
        ("backward", true),
        ("retrace", true),
        ("trace", false),
        ("fwd", false),
        ("bwd", true),
    ];
    let lower = title.to_lowercase();
    let trimmed = lower.trim_end_matches([')', ']', ' ']);
    for (word, backward) in WORDS {
        if let Some(stem) = trimmed.strip_suffix(word) {
            let stem_len = stem.trim_end_matches(['(', '[', ' ', '-', '_']).len();
            if stem_len == 0 {
                return None;
            }
            // Titles are mostly ASCII; cut the original at the same char count.
            let base: String = title
                .chars()
                .take(stem[..stem_len].chars().count())
                .collect();
            return Some((base, backward));
        }
    }
    None
}

/// The unused field that pairs with field `i` (same stem, opposite pass, same size).
fn partner_of(fields: &[Field], i: usize, used: &[bool]) -> Option<usize> {
    let (stem, backward) = split_direction(&fields[i].title)?;
    let a = &fields[i];
    (0..fields.len()).find(|&j| {
        let b = &fields[j];
        !used[j]
            && split_direction(&b.title)
                .is_some_and(|(s, back)| s.eq_ignore_ascii_case(&stem) && back != backward)
            && (a.columns, a.rows) == (b.columns, b.rows)
            && a.width == b.width
            && a.height == b.height
            && a.lateral_unit == b.lateral_unit
    })
}

/// The pair of field `i` and its optional partner (either may be the backward one).
fn build_pair(
    fields: &[Field],
    i: usize,
    partner: Option<usize>,
    metadata: &mut BTreeMap<String, String>,
) -> Result<ScanPair, ReadError> {
    let first = &fields[i];
    let first_is_backward =
        partner.is_some() && split_direction(&first.title).is_some_and(|(_, backward)| backward);
    let (trace, retrace) = match (partner, first_is_backward) {
        (Some(j), false) => (Some(first), Some(&fields[j])),
        (Some(j), true) => (Some(&fields[j]), Some(first)),
        (None, _) => (Some(first), None),
    };
    let name = match partner {
        Some(_) => split_direction(&first.title).map_or(first.title.clone(), |(s, _)| s),
        None => first.title.clone(),
    };
    let geometry = field_geometry(first, metadata)?;
    let decode = |field: Option<&Field>| {
        field
            .map(|f| {
                let values: Vec<f64> = doubles(f.raw).collect();
                ImageChannel::from_row_major(
                    name.clone(),
                    f.unit.clone(),
                    f.rows,
                    f.columns,
                    values,
                )
                .map_err(|source| ReadError::geometry(FORMAT, source))
            })
            .transpose()
    };
    ScanPair::from_parts(geometry, decode(trace)?, decode(retrace)?)
        .map_err(|source| ReadError::geometry(FORMAT, source))
}

/// The geometry of a field: pitch from its size, timing and directions assumed.
fn field_geometry(
    field: &Field,
    metadata: &mut BTreeMap<String, String>,
) -> Result<ScanGeometry, ReadError> {
    let pitch = (
        field.width / field.columns as f64,
        field.height / field.rows as f64,
    );
    let stated = field.lateral_unit == "m"
        && plausible(pitch.0, &PLAUSIBLE_PITCH_M)
        && plausible(pitch.1, &PLAUSIBLE_PITCH_M);
    let (pitch_x, pitch_y, scale_source) = if stated {
        (pitch.0, pitch.1, ValueSource::Stated)
    } else {
        note(
            metadata,
            ASSUMED_SCALE_KEY,
            format!(
                "\"{}\" is {:e} x {:e} in unit \"{}\", not a plausible size in metres",
                field.title, field.width, field.height, field.lateral_unit
            ),
        );
        (ASSUMED_PITCH, ASSUMED_PITCH, ValueSource::Assumed)
    };
    Ok(ScanGeometry::new(
        field.columns,
        field.rows,
        pitch_x,
        pitch_y,
        ASSUMED_PIXEL_PERIOD,
        ScanDirection::Right,
        ScanDirection::Down,
    )
    .map_err(|source| ReadError::geometry(FORMAT, source))?
    .with_scale_source(scale_source)
    .with_timing_source(ValueSource::Assumed))
}

/// Lists the fields (title, size, unit, offset) in the metadata.
fn describe_fields(fields: &[Field], metadata: &mut BTreeMap<String, String>) {
    let list = fields
        .iter()
        .map(|f| {
            format!(
                "/{}: \"{}\" {} x {} px, {:e} x {:e} {}, offset ({:e}, {:e}), values in \"{}\"",
                f.index,
                f.title,
                f.columns,
                f.rows,
                f.width,
                f.height,
                f.lateral_unit,
                f.offset.0,
                f.offset.1,
                f.unit
            )
        })
        .collect::<Vec<_>>()
        .join("; ");
    metadata.insert("gwyddion data fields".to_string(), list);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn direction_words_split_off_the_title() {
        assert_eq!(
            split_direction("Z (Backward)"),
            Some(("Z".to_string(), true))
        );
        assert_eq!(
            split_direction("Z-Axis forward"),
            Some(("Z-Axis".to_string(), false))
        );
        assert_eq!(
            split_direction("Height Retrace"),
            Some(("Height".to_string(), true))
        );
        assert_eq!(
            split_direction("Height Trace"),
            Some(("Height".to_string(), false))
        );
        assert_eq!(split_direction("Topography"), None);
        assert_eq!(split_direction("Forward"), None);
    }
}
