//! Physical quantities: parsing what users type (`2.46A`, `0.246nm`, `2.46e-10`, `1.51ms`,
//! `0.774 s`); formatting for people is `dhct_scan::quantity`, re-exported here.

pub use dhct_scan::quantity::{
    angstrom, degrees, length, picometres, si, si_significant, unit_symbol, value_with_sigma,
};

/// Parses a length; a bare number is metres. Units: m, mm, um/µm, nm, A/Å, pm.
pub fn parse_length(text: &str) -> Result<f64, String> {
    parse_with_units(
        text,
        &[
            ("pm", 1e-12),
            ("nm", 1e-9),
            ("um", 1e-6),
            ("µm", 1e-6),
            ("mm", 1e-3),
            ("Å", 1e-10),
            ("A", 1e-10),
            ("m", 1.0),
        ],
        "length",
        "2.46A, 0.246nm or 2.46e-10",
    )
}

/// Parses a time; a bare number is seconds. Units: s, ms, us/µs, ns.
pub fn parse_time(text: &str) -> Result<f64, String> {
    parse_with_units(
        text,
        &[
            ("ns", 1e-9),
            ("us", 1e-6),
            ("µs", 1e-6),
            ("ms", 1e-3),
            ("s", 1.0),
        ],
        "time",
        "1.51ms, 0.774s or 0.774",
    )
}

fn parse_with_units(
    text: &str,
    units: &[(&str, f64)],
    what: &str,
    example: &str,
) -> Result<f64, String> {
    let trimmed = text.trim();
    let (number, factor) = units
        .iter()
        .find_map(|(suffix, factor)| {
            trimmed
                .strip_suffix(suffix)
                .map(|number| (number.trim(), *factor))
        })
        .unwrap_or((trimmed, 1.0));
    let value: f64 = number
        .parse()
        .map_err(|_| format!("'{text}' is not a {what} (try e.g. {example})"))?;
    let value = value * factor;
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(format!("{what} must be positive and finite, got '{text}'"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_and_times_with_and_without_units() {
        assert_eq!(parse_length("2.46e-10").unwrap(), 2.46e-10);
        assert!((parse_length("2.46A").unwrap() - 2.46e-10).abs() < 1e-22);
        assert!((parse_length("2.46 Å").unwrap() - 2.46e-10).abs() < 1e-22);
        assert!((parse_length("0.246nm").unwrap() - 2.46e-10).abs() < 1e-22);
        assert!((parse_length("246pm").unwrap() - 2.46e-10).abs() < 1e-22);
        assert!((parse_time("1.51ms").unwrap() - 1.51e-3).abs() < 1e-15);
        assert_eq!(parse_time("0.774 s").unwrap(), 0.774);
        assert!(parse_length("-1nm").is_err());
        assert!(parse_length("nan").is_err());
        assert!(parse_time("fast").unwrap_err().contains("not a time"));
    }
}
