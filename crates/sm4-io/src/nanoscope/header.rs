//! The text header of a Bruker/Veeco Nanoscope file and its CIAO parameter values.
//!
//! The header is Latin-1 text, one `\Key: value` per line (CR LF), grouped in sections that
//! start with a line `\*Section name` and ending with `\*File list end`. Keys that start with
//! `@` (optionally followed by a group number, `@2:Z scale`) hold CIAO parameters:
//!
//! * `V [soft scale] (hard scale unit/LSB) hard value unit`, a value: `[soft scale]` names
//!   another parameter (`@Sens. Zscan: V 12.75 nm/V`) that converts the hard value's volts
//!   into a physical unit; both bracketed parts are optional;
//! * `S [internal] "external"`, a selection (e.g. the channel name);
//! * `C [parameter] value`, a scale.

use crate::iso28600::parse_number;

/// One `\*Section`: its name and `(key, value)` entries in file order.
#[derive(Debug, Clone)]
pub struct Section {
    /// The name after `\*`, e.g. `Ciao image list`.
    pub name: String,
    /// Entries: key without the leading backslash, value after `: ` (trimmed).
    pub entries: Vec<(String, String)>,
}

impl Section {
    /// The value of `key` (compared ignoring ASCII case and a `@N:` group prefix).
    pub fn get(&self, key: &str) -> Option<&str> {
        self.entries
            .iter()
            .find(|(k, _)| bare_key(k).eq_ignore_ascii_case(bare_key(key)))
            .map(|(_, v)| v.as_str())
    }
}

/// `@2:Z scale` → `Z scale`; `Samps/line` unchanged.
fn bare_key(key: &str) -> &str {
    let key = key.strip_prefix('@').unwrap_or(key);
    match key.split_once(':') {
        Some((group, rest)) if !group.is_empty() && group.bytes().all(|b| b.is_ascii_digit()) => {
            rest
        }
        _ => key,
    }
}

/// Splits the header text (up to `\*File list end`) into sections.
pub fn parse_sections(text: &str) -> Vec<Section> {
    let mut sections: Vec<Section> = Vec::new();
    for line in text.split(['\r', '\n']).filter(|l| !l.is_empty()) {
        let Some(line) = line.strip_prefix('\\').or_else(|| line.strip_prefix('?')) else {
            continue;
        };
        if let Some(name) = line.strip_prefix('*') {
            sections.push(Section {
                name: name.trim().to_string(),
                entries: Vec::new(),
            });
        } else if let Some(section) = sections.last_mut() {
            let (key, value) = line.split_once(':').map_or((line, ""), |(k, v)| (k, v));
            // Group-numbered keys (`@2:Z scale`) keep their first colon in the key.
            let (key, value) = match (key.starts_with('@'), value.split_once(':')) {
                (true, Some((rest, v)))
                    if key[1..].bytes().all(|b| b.is_ascii_digit()) && !key[1..].is_empty() =>
                {
                    (format!("{key}:{rest}"), v)
                }
                _ => (key.to_string(), value),
            };
            section.entries.push((key, value.trim().to_string()));
        }
    }
    sections
}

/// A CIAO `V` value: `V [soft] (hard scale) hard value unit`.
#[derive(Debug, Clone, PartialEq)]
pub struct CiaoValue {
    /// The parameter named in brackets, e.g. `Sens. Zscan`.
    pub soft_scale: Option<String>,
    /// The hard value, e.g. 85.13184.
    pub value: f64,
    /// The hard value's unit, e.g. `V` (may be empty).
    pub unit: String,
}

/// Parses a CIAO value such as `V [Sens. Zscan] (0.006713867 V/LSB) 85.13184 V` or
/// `V 12.75932 nm/V`.
pub fn parse_ciao_value(text: &str) -> Option<CiaoValue> {
    let rest = text.trim().strip_prefix('V')?.trim_start();
    let (soft_scale, rest) = match rest.strip_prefix('[') {
        Some(inner) => {
            let (name, rest) = inner.split_once(']')?;
            (Some(name.trim().to_string()), rest.trim_start())
        }
        None => (None, rest),
    };
    let rest = match rest.strip_prefix('(') {
        Some(inner) => inner.split_once(')')?.1.trim_start(),
        None => rest,
    };
    let mut words = rest.split_whitespace();
    let value = parse_number(words.next()?)?;
    let unit = words.next().unwrap_or("").to_string();
    Some(CiaoValue {
        soft_scale,
        value,
        unit,
    })
}

/// The external name of a CIAO selection: `S [Height] "Height"` → `Height`.
pub fn parse_selection(text: &str) -> Option<String> {
    let rest = text.trim().strip_prefix('S')?.trim_start();
    let quoted = rest.split('"').nth(1).filter(|q| !q.trim().is_empty());
    let bracketed = rest
        .strip_prefix('[')
        .and_then(|r| r.split_once(']'))
        .map(|(inner, _)| inner)
        .filter(|b| !b.trim().is_empty());
    quoted.or(bracketed).map(|s| s.trim().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sections_keys_and_group_prefixes() {
        let text = "\\*File list\r\n\\Version: 0x05120108\r\n\\*Ciao image list\r\n\
                    \\Data offset: 40960\r\n\\@2:Image Data: S [Height] \"Height\"\r\n\
                    \\@Sens. Zscan: V 12.75932 nm/V\r\n\\*File list end\r\n";
        let sections = parse_sections(text);
        assert_eq!(sections.len(), 3);
        let image = &sections[1];
        assert_eq!(image.name, "Ciao image list");
        assert_eq!(image.get("data offset"), Some("40960"));
        assert_eq!(image.get("Image Data"), Some("S [Height] \"Height\""));
        assert_eq!(image.get("@Sens. Zscan"), Some("V 12.75932 nm/V"));
        assert_eq!(image.entries[1].0, "@2:Image Data");
    }

    #[test]
    fn ciao_values_and_selections() {
        assert_eq!(
            parse_ciao_value("V [Sens. Zscan] (0.006713867 V/LSB) 85.13184 V"),
            Some(CiaoValue {
                soft_scale: Some("Sens. Zscan".into()),
                value: 85.13184,
                unit: "V".into()
            })
        );
        assert_eq!(
            parse_ciao_value("V 12.75932 nm/V"),
            Some(CiaoValue {
                soft_scale: None,
                value: 12.75932,
                unit: "nm/V".into()
            })
        );
        assert_eq!(
            parse_ciao_value("V (0.0003051758 V/LSB)       0 V").map(|v| v.value),
            Some(0.0)
        );
        assert_eq!(parse_ciao_value("S [x] \"y\""), None);
        assert_eq!(
            parse_selection("S [Lateral] \"Friction\""),
            Some("Friction".into())
        );
        assert_eq!(parse_selection("S [ZSensor] \"\""), Some("ZSensor".into()));
    }
}
