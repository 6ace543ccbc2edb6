//! A JPK channel page: its samples, read strip by strip, scaled by its default calibration
//! slot; and the pairing of trace and retrace pages into channels.

use std::collections::BTreeMap;

use crate::ReadError;
use crate::limits::Budget;

use super::directory::*;

impl<'a> Tiff<'a> {
    /// The channel of page `index`: `Ok(Ok(channel))`, `Ok(Err(reason))` for a page that is
    /// not a readable channel (skipped), or `Err` for a file that is broken.
    pub(super) fn channel(
        &self,
        index: usize,
        page: &Page,
        global: &Page,
        budget: &mut Budget,
    ) -> Result<Result<Channel, String>, ReadError> {
        let photometric = self.unsigned(page, tag::PHOTOMETRIC);
        if photometric != Some(1) {
            return Ok(Err(match photometric {
                Some(p) => format!("PhotometricInterpretation {p}, not a grey image"),
                None => "no PhotometricInterpretation".to_string(),
            }));
        }
        let bits = self.unsigned(page, tag::BITS_PER_SAMPLE).unwrap_or(1);
        let sample_format = self.unsigned(page, tag::SAMPLE_FORMAT).unwrap_or(1);
        let sample = match (bits, sample_format) {
            (16, 1) => Sample::U16,
            (16, 2) => Sample::I16,
            (32, 1) => Sample::U32,
            (32, 2) => Sample::I32,
            (32, 3) => Sample::F32,
            _ => {
                return Ok(Err(format!(
                    "{bits}-bit samples of SampleFormat {sample_format} (JPK channels are \
                     16- or 32-bit integers or 32-bit floats)"
                )));
            }
        };
        let compression = self.unsigned(page, tag::COMPRESSION).unwrap_or(1);
        if compression != 1 {
            return Ok(Err(format!("compressed (Compression {compression})")));
        }
        let samples = self.unsigned(page, tag::SAMPLES_PER_PIXEL).unwrap_or(1);
        if samples != 1 {
            return Ok(Err(format!("{samples} samples per pixel")));
        }
        if page.entry(tag::TILE_WIDTH).is_some() || page.entry(tag::TILE_OFFSETS).is_some() {
            return Ok(Err("tiled".to_string()));
        }
        let key = self.text(page, tag::CHANNEL);
        let display = self.text(page, tag::CHANNEL_FANCY_NAME);
        let retrace = self.flag(page, tag::CHANNEL_RETRACE).unwrap_or(false);
        let label = display
            .clone()
            .or_else(|| key.clone())
            .unwrap_or_else(|| format!("page {index}"));
        let scale = match self.default_slot(page) {
            Ok(scale) => scale,
            Err(reason) => return Ok(Err(format!("\"{label}\": {reason}"))),
        };
        let side = |t: u16, name: &str| -> Result<u64, ReadError> {
            match self.unsigned(page, t) {
                Some(n) if (1..=MAX_SIDE).contains(&n) => Ok(n),
                other => Err(ReadError::corrupt(
                    FORMAT,
                    format!(
                        "page {index}: {name} is {}, not 1 to {MAX_SIDE}",
                        other.map_or("missing".to_string(), |n| n.to_string())
                    ),
                )),
            }
        };
        let columns = side(tag::IMAGE_WIDTH, "ImageWidth")?;
        let rows = side(tag::IMAGE_LENGTH, "ImageLength")?;
        budget.charge_images(FORMAT, columns, rows, 1, 0)?;
        let reflect = self
            .flag(page, tag::GRID_REFLECT)
            .or_else(|| self.flag(global, tag::GRID_REFLECT))
            .unwrap_or(false);
        let raw = self.strips(index, page, columns, rows, sample)?;
        let (columns, rows) = (columns as usize, rows as usize);
        let mut values = Vec::new();
        values
            .try_reserve_exact(columns * rows)
            .map_err(|_| ReadError::corrupt(FORMAT, "not enough memory for the image"))?;
        for display_row in 0..rows {
            let stored = if reflect {
                display_row
            } else {
                rows - 1 - display_row
            };
            let line = raw[stored];
            values.extend(
                line.chunks_exact(sample.bytes())
                    .map(|b| sample.decode(b, self.order) * scale.multiply + scale.offset),
            );
        }
        Ok(Ok(Channel {
            page: index,
            key: key.unwrap_or_else(|| label.clone()),
            name: label,
            retrace,
            columns,
            rows,
            reflect,
            slot: scale.slot,
            unit: scale.unit,
            values,
        }))
    }

    /// The stored rows of a page (row 0 first), each `columns` samples, read through
    /// StripOffsets, RowsPerStrip and StripByteCounts.
    pub(super) fn strips(
        &self,
        index: usize,
        page: &Page,
        columns: u64,
        rows: u64,
        sample: Sample,
    ) -> Result<Vec<&'a [u8]>, ReadError> {
        let corrupt = |what: String| ReadError::corrupt(FORMAT, format!("page {index}: {what}"));
        let rows_per_strip = match self.unsigned(page, tag::ROWS_PER_STRIP) {
            None => rows,
            Some(0) => return Err(corrupt("RowsPerStrip is 0".to_string())),
            Some(n) => n.min(rows),
        };
        let strips = rows.div_ceil(rows_per_strip);
        let offsets = self
            .unsigned_array(page, tag::STRIP_OFFSETS)
            .ok_or_else(|| corrupt("no usable StripOffsets".to_string()))?;
        if (offsets.len() as u64) < strips {
            return Err(corrupt(format!(
                "{} StripOffsets for {strips} strips of {rows_per_strip} rows",
                offsets.len()
            )));
        }
        let counts = self.unsigned_array(page, tag::STRIP_BYTE_COUNTS);
        let row_bytes = columns * sample.bytes() as u64;
        let mut lines = Vec::with_capacity(rows as usize);
        for strip in 0..strips {
            let first = strip * rows_per_strip;
            let strip_rows = rows_per_strip.min(rows - first);
            let needed = strip_rows * row_bytes;
            if let Some(counts) = &counts {
                match counts.get(strip as usize) {
                    Some(&count) if count >= needed => {}
                    Some(&count) => {
                        return Err(corrupt(format!(
                            "strip {strip} holds {count} bytes, {needed} needed for \
                             {strip_rows} rows of {columns} samples"
                        )));
                    }
                    None => {
                        return Err(corrupt(format!(
                            "{} StripByteCounts for {strips} strips",
                            counts.len()
                        )));
                    }
                }
            }
            let data = self.slice(
                offsets[strip as usize],
                needed,
                &format!("strip {strip} of page {index}"),
            )?;
            lines.extend(data.chunks_exact(row_bytes as usize));
        }
        Ok(lines)
    }

    /// The default calibration slot of a channel page, or why it cannot be used.
    pub(super) fn default_slot(&self, page: &Page) -> Result<Scale, String> {
        let wanted = self
            .text(page, tag::DEFAULT_SLOT)
            .ok_or("no DefaultSlot (0x8081) names its calibration")?;
        let slots = self
            .unsigned(page, tag::NR_OF_SLOTS)
            .map_or(MAX_SLOTS, |n| n.min(u64::from(MAX_SLOTS)) as u16);
        let base = (0..slots)
            .map(|n| tag::SLOT_BASE + tag::SLOT_STRIDE * n)
            .find(|&base| self.text(page, base + tag::SLOT_NAME).as_deref() == Some(&wanted))
            .ok_or_else(|| {
                format!("its default calibration slot \"{wanted}\" is not in the file")
            })?;
        let unit = self
            .text(page, base + tag::SLOT_ENCODER_UNIT)
            .unwrap_or_default();
        let scaling = self.text(page, base + tag::SLOT_SCALING_TYPE);
        let (multiply, offset) = match scaling.as_deref() {
            Some("NullScaling") => (1.0, 0.0),
            Some("LinearScaling") => {
                match (
                    self.real(page, base + tag::SLOT_MULTIPLY),
                    self.real(page, base + tag::SLOT_OFFSET),
                ) {
                    (Some(m), Some(o)) => (m, o),
                    _ => {
                        return Err(format!(
                            "its default calibration slot \"{wanted}\" lacks a finite \
                             multiplier and offset"
                        ));
                    }
                }
            }
            other => {
                return Err(format!(
                    "its default calibration slot \"{wanted}\" has scaling type {}",
                    other.map_or("(none)".to_string(), |s| format!("\"{s}\""))
                ));
            }
        };
        Ok(Scale {
            slot: wanted,
            unit,
            multiply,
            offset,
        })
    }
}

/// How a sample is stored.
#[derive(Debug, Clone, Copy)]
pub(super) enum Sample {
    U16,
    I16,
    U32,
    I32,
    F32,
}

impl Sample {
    pub(super) fn bytes(self) -> usize {
        match self {
            Sample::U16 | Sample::I16 => 2,
            Sample::U32 | Sample::I32 | Sample::F32 => 4,
        }
    }

    /// The value of one sample's bytes (exactly [`Sample::bytes`] of them).
    pub(super) fn decode(self, b: &[u8], order: Order) -> f64 {
        let two = || match order {
            Order::Big => [b[0], b[1]],
            Order::Little => [b[1], b[0]],
        };
        let four = || match order {
            Order::Big => [b[0], b[1], b[2], b[3]],
            Order::Little => [b[3], b[2], b[1], b[0]],
        };
        match self {
            Sample::U16 => f64::from(u16::from_be_bytes(two())),
            Sample::I16 => f64::from(i16::from_be_bytes(two())),
            Sample::U32 => f64::from(u32::from_be_bytes(four())),
            Sample::I32 => f64::from(i32::from_be_bytes(four())),
            Sample::F32 => f64::from(f32::from_be_bytes(four())),
        }
    }
}

/// A resolved calibration: `z = raw · multiply + offset`, in `unit`.
#[derive(Debug, Clone)]
pub(super) struct Scale {
    pub(super) slot: String,
    pub(super) unit: String,
    pub(super) multiply: f64,
    pub(super) offset: f64,
}

/// One channel page, decoded into display orientation.
#[derive(Debug)]
pub(super) struct Channel {
    pub(super) page: usize,
    /// The internal name (0x8050) that pairs trace and retrace.
    pub(super) key: String,
    /// The display name.
    pub(super) name: String,
    pub(super) retrace: bool,
    pub(super) columns: usize,
    pub(super) rows: usize,
    pub(super) reflect: bool,
    pub(super) slot: String,
    pub(super) unit: String,
    pub(super) values: Vec<f64>,
}

/// The pages of one pair.
#[derive(Debug)]
pub(super) struct Group {
    pub(super) key: String,
    pub(super) name: String,
    pub(super) first_page: usize,
    pub(super) columns: usize,
    pub(super) rows: usize,
    pub(super) reflect: bool,
    pub(super) trace: Option<Channel>,
    pub(super) retrace: Option<Channel>,
}

/// Pairs the channels (see the module docs), names the pairs uniquely and puts the
/// preferred topography first.
pub(super) fn group(channels: Vec<Channel>) -> Vec<Group> {
    let mut groups: Vec<Group> = Vec::new();
    for channel in channels {
        let home = groups.iter_mut().find(|g| {
            g.key == channel.key
                && (g.columns, g.rows, g.reflect)
                    == (channel.columns, channel.rows, channel.reflect)
                && if channel.retrace {
                    g.retrace.is_none()
                } else {
                    g.trace.is_none()
                }
        });
        let group = match home {
            Some(group) => group,
            None => {
                groups.push(Group {
                    key: channel.key.clone(),
                    name: channel.name.clone(),
                    first_page: channel.page,
                    columns: channel.columns,
                    rows: channel.rows,
                    reflect: channel.reflect,
                    trace: None,
                    retrace: None,
                });
                groups.last_mut().expect("just pushed")
            }
        };
        if channel.retrace {
            group.retrace = Some(channel);
        } else {
            group.trace = Some(channel);
        }
    }
    let mut uses: BTreeMap<String, usize> = BTreeMap::new();
    for g in &groups {
        *uses.entry(g.name.clone()).or_default() += 1;
    }
    for g in &mut groups {
        if uses[&g.name] > 1 {
            g.name = format!("{} (page {})", g.name, g.first_page);
        }
    }
    let preferred = groups
        .iter()
        .position(|g| g.key == "measuredHeight")
        .or_else(|| groups.iter().position(|g| g.key == "height"));
    if let Some(k) = preferred {
        let topography = groups.remove(k);
        groups.insert(0, topography);
    }
    groups
}
