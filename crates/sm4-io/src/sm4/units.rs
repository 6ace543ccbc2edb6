//! Unit strings of SM4 pages (x/y/z units) and their conversion to SI base units.

/// Base units dhct recognises after an optional SI prefix.
const BASES: [&str; 9] = ["m", "A", "V", "s", "Hz", "N", "W", "K", "Pa"];

/// Splits a unit such as `"nm"` into the factor to its base unit and the base: `(1e-9, "m")`.
/// Unknown units come back unchanged with factor 1 (`"Vrms"` → `(1, "Vrms")`).
pub(crate) fn si_unit(unit: &str) -> (f64, String) {
    let unit = unit.trim();
    if BASES.contains(&unit) {
        return (1.0, unit.to_string());
    }
    let mut chars = unit.chars();
    if let Some(prefix) = chars.next() {
        let rest = chars.as_str();
        if let (Some(factor), true) = (prefix_factor(prefix), BASES.contains(&rest)) {
            return (factor, rest.to_string());
        }
    }
    (1.0, unit.to_string())
}

/// Factor from a lateral unit to metres, or `None` if the unit is not a length.
pub(crate) fn length_factor(unit: &str) -> Option<f64> {
    match si_unit(unit) {
        (factor, base) if base == "m" => Some(factor),
        _ => None,
    }
}

fn prefix_factor(prefix: char) -> Option<f64> {
    Some(match prefix {
        'f' => 1e-15,
        'p' => 1e-12,
        'n' => 1e-9,
        'u' | 'µ' | 'μ' => 1e-6,
        'm' => 1e-3,
        'k' => 1e3,
        'M' => 1e6,
        'G' => 1e9,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefixes_are_split_off() {
        assert_eq!(si_unit("m"), (1.0, "m".to_string()));
        assert_eq!(si_unit(" nm "), (1e-9, "m".to_string()));
        assert_eq!(si_unit("pA"), (1e-12, "A".to_string()));
        assert_eq!(si_unit("mV"), (1e-3, "V".to_string()));
        assert_eq!(si_unit("µm"), (1e-6, "m".to_string()));
        assert_eq!(si_unit("Vrms"), (1.0, "Vrms".to_string()));
        assert_eq!(si_unit(""), (1.0, String::new()));
        assert_eq!(length_factor("Å"), None);
        assert_eq!(length_factor("nm"), Some(1e-9));
        assert_eq!(length_factor("V"), None);
    }
}
