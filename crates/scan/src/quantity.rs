//! Physical quantities formatted for people, in one place for every crate: the report, the
//! figures, the terminal and the warnings' messages show a value the same way. Proper
//! symbols (Å, nm, µm, °, σ, ±), SI prefixes, no ASCII stand-ins. A value that was not
//! measured (NaN, or infinite) is shown as [`NOT_MEASURED`], never as "NaN".
//!
//! ```
//! use dhct_scan::quantity::{si, value_with_sigma};
//!
//! assert_eq!(si(2.46e-10, "m"), "246 pm");
//! assert_eq!(value_with_sigma(-7.75e-15, 1.4e-14, "m/s^2"), "-8 ± 14 fm/s²");
//! ```

/// How a value that was not measured (not finite) is shown.
pub const NOT_MEASURED: &str = "–";

/// `value` with an SI prefix and up to four decimals (trailing zeros dropped), e.g.
/// `si(2.46e-10, "m")` = `"246 pm"`; units that take no prefix are shown as
/// [`unit_symbol`] gives them.
pub fn si(value: f64, unit: &str) -> String {
    if !value.is_finite() {
        return NOT_MEASURED.into();
    }
    let unit = unit_symbol(unit);
    if value == 0.0 || unit.is_empty() || unit == "°" || unit == "Å" {
        return join(&format!("{value}"), &unit);
    }
    let (scale, prefix) = si_prefix(value);
    let digits = format!("{:.4}", value / scale);
    let digits = digits.trim_end_matches('0').trim_end_matches('.');
    format!("{digits} {prefix}{unit}")
}

/// `value` with an SI prefix, rounded to `digits` significant digits (at least 1):
/// `si_significant(2.585791e-13, "m/s", 3)` = `"259 fm/s"`.
pub fn si_significant(value: f64, unit: &str, digits: usize) -> String {
    let symbol = unit_symbol(unit);
    if value == 0.0 || !value.is_finite() || !prefixable(&symbol) {
        return si(value, unit);
    }
    let (scale, prefix) = si_prefix(value);
    let scaled = value / scale;
    let integer_digits = scaled.abs().log10().floor() as i32 + 1;
    let decimals = (digits.max(1) as i32 - integer_digits).max(0) as usize;
    format!("{scaled:.decimals$} {prefix}{symbol}")
}

/// A length in ångström with `decimals` decimals: `"2.461 Å"`.
pub fn angstrom(metres: f64, decimals: usize) -> String {
    if !metres.is_finite() {
        return NOT_MEASURED.into();
    }
    format!("{:.decimals$} Å", metres * 1e10)
}

/// A length in picometres with one decimal: `"12.3 pm"`.
pub fn picometres(metres: f64) -> String {
    if !metres.is_finite() {
        return NOT_MEASURED.into();
    }
    format!("{:.1} pm", metres * 1e12)
}

/// An angle in degrees: `"60.02°"`.
pub fn degrees(degrees: f64, decimals: usize) -> String {
    if !degrees.is_finite() {
        return NOT_MEASURED.into();
    }
    format!("{degrees:.decimals$}°")
}

/// A length for scale bars and captions: pm below 1 nm, nm below 1 µm, else µm; up to three
/// significant decimals (`"2 nm"`, `"500 pm"`, `"1.5 µm"`).
pub fn length(metres: f64) -> String {
    if !metres.is_finite() {
        return NOT_MEASURED.into();
    }
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
    if !value.is_finite() {
        return NOT_MEASURED.into();
    }
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
        assert_eq!(si_significant(2.585791e-13, "m/s", 3), "259 fm/s");
        assert_eq!(si_significant(7.6999e-12, "m/s", 3), "7.70 pm/s");
    }

    #[test]
    fn a_value_not_measured_is_a_dash_in_every_format() {
        for shown in [
            si(f64::NAN, "m"),
            si_significant(f64::NAN, "m/s", 3),
            angstrom(f64::NAN, 3),
            picometres(f64::INFINITY),
            degrees(f64::NAN, 2),
            length(f64::NAN),
            value_with_sigma(f64::NAN, 1.0, "m"),
        ] {
            assert_eq!(shown, NOT_MEASURED);
        }
    }
}
