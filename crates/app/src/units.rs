//! Physical quantities: parsing what users type (`2.46A`, `0.246nm`, `2.46e-10`, `1.51ms`,
//! `0.774 s`) and the one place that formats quantities for people (report, figures,
//! terminal): proper symbols (Å, nm, µm, °, σ, ±), SI prefixes, no ASCII stand-ins.

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

/// `value` with an SI prefix and up to four decimals (trailing zeros dropped), e.g.
/// `si(2.46e-10, "m")` = `"246 pm"`; units that take no prefix are shown as
/// [`unit_symbol`] gives them.
pub fn si(value: f64, unit: &str) -> String {
    let unit = unit_symbol(unit);
    if value == 0.0 || !value.is_finite() || unit.is_empty() || unit == "°" || unit == "Å" {
        return join(&format!("{value}"), &unit);
    }
    let (scale, prefix) = si_prefix(value);
    let digits = format!("{:.4}", value / scale);
    let digits = digits.trim_end_matches('0').trim_end_matches('.');
    format!("{digits} {prefix}{unit}")
}

/// A length in ångström with `decimals` decimals: `"2.461 Å"`.
pub fn angstrom(metres: f64, decimals: usize) -> String {
    format!("{:.decimals$} Å", metres * 1e10)
}

/// A length in picometres with one decimal: `"12.3 pm"`.
pub fn picometres(metres: f64) -> String {
    format!("{:.1} pm", metres * 1e12)
}

/// An angle in degrees: `"60.02°"`.
pub fn degrees(degrees: f64, decimals: usize) -> String {
    format!("{degrees:.decimals$}°")
}

/// A length for scale bars and captions: pm below 1 nm, nm below 1 µm, else µm; up to three
/// significant decimals (`"2 nm"`, `"500 pm"`, `"1.5 µm"`).
pub fn length(metres: f64) -> String {
    let (value, unit) = match metres.abs() {
        m if m < 1e-9 => (metres * 1e12, "pm"),
        m if m < 1e-6 => (metres * 1e9, "nm"),
        _ => (metres * 1e6, "µm"),
    };
    let digits = format!("{value:.3}");
    format!(
        "{} {unit}",
        digits.trim_end_matches('0').trim_end_matches('.')
    )
}

/// A unit as people write it (`A` stays ampere): `Angstrom` → `Å`, `um` → `µm`, `us` → `µs`, `deg` → `°`, `^2` →
/// `²`, `^-n` → `⁻ⁿ`, the dimensionless `1` → nothing.
pub fn unit_symbol(unit: &str) -> String {
    match unit.trim() {
        "1" | "" => String::new(),
        "Angstrom" | "angstrom" | "Ang" => "Å".into(),
        "um" => "µm".into(),
        "us" => "µs".into(),
        "deg" | "degrees" => "°".into(),
        other => other
            .replace("^-n", "⁻ⁿ")
            .replace("^-1", "⁻¹")
            .replace("^2", "²")
            .replace("^3", "³"),
    }
}

/// A value ± its 1σ uncertainty: an SI prefix for lengths, times and velocities, the value
/// rounded to the uncertainty's second significant digit; `(fixed)` without uncertainty.
pub fn value_with_sigma(value: f64, sigma: f64, unit: &str) -> String {
    let symbol = unit_symbol(unit);
    let (scale, shown) = if prefixable(&symbol) && value.is_finite() && value != 0.0 {
        let (scale, prefix) = si_prefix(value);
        (scale, format!("{prefix}{symbol}"))
    } else {
        (1.0, symbol)
    };
    let (v, e) = (value / scale, sigma / scale);
    if !e.is_finite() || e <= 0.0 {
        return format!("{} (fixed)", join(&format!("{v:.4}"), &shown));
    }
    let decimals = (1 - e.abs().log10().floor() as i32).clamp(0, 12) as usize;
    join(&format!("{v:.decimals$} ± {e:.decimals$}"), &shown)
}

fn join(number: &str, unit: &str) -> String {
    if unit.is_empty() {
        number.to_string()
    } else {
        format!("{number} {unit}")
    }
}

/// Units whose uncertainties are shown with an SI prefix.
fn prefixable(unit: &str) -> bool {
    matches!(unit, "m" | "m/s" | "m/s²" | "s" | "V" | "A" | "Hz")
}

/// The largest prefix (f … k) not above `|value|`: (its factor, its symbol).
fn si_prefix(value: f64) -> (f64, &'static str) {
    const PREFIXES: [(f64, &str); 7] = [
        (1e-15, "f"),
        (1e-12, "p"),
        (1e-9, "n"),
        (1e-6, "µ"),
        (1e-3, "m"),
        (1.0, ""),
        (1e3, "k"),
    ];
    PREFIXES
        .iter()
        .rev()
        .find(|(scale, _)| value.abs() >= *scale)
        .copied()
        .unwrap_or(PREFIXES[0])
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

    #[test]
    fn quantities_are_formatted_with_proper_symbols() {
        assert_eq!(si(2.46e-10, "m"), "246 pm");
        assert_eq!(si(1.5e-3, "s"), "1.5 ms");
        assert_eq!(si(3.0, "1"), "3");
        assert_eq!(unit_symbol("A"), "A", "ampere");
        assert_eq!(unit_symbol("Angstrom"), "Å");
        assert_eq!(unit_symbol("um"), "µm");
        assert_eq!(unit_symbol("m/s^2"), "m/s²");
        assert_eq!(unit_symbol("s^-n"), "s⁻ⁿ");
        assert_eq!(angstrom(2.4612e-10, 3), "2.461 Å");
        assert_eq!(picometres(1.234e-11), "12.3 pm");
        assert_eq!(degrees(60.0, 2), "60.00°");
        assert_eq!(length(2e-9), "2 nm");
        assert_eq!(length(5e-10), "500 pm");
        assert_eq!(length(1.5e-6), "1.5 µm");
        assert_eq!(
            value_with_sigma(1.234e-12, 5.6e-14, "m/s"),
            "1.234 ± 0.056 pm/s"
        );
        assert_eq!(value_with_sigma(0.5, 0.0, "1"), "0.5000 (fixed)");
        assert_eq!(value_with_sigma(2.0, 0.25, "s^-n"), "2.00 ± 0.25 s⁻ⁿ");
        assert_eq!(si(2e-9, "A"), "2 nA");
    }
}
