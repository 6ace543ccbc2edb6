//! Calendar dates and wall-clock times as seconds since 1970-01-01 00:00:00 (the clock a
//! frame's start time is kept on, [`crate::ScanGeometry::start_time`]).
//!
//! Files record local time without a zone; dhct treats it as UTC. Only differences between
//! frames of one session matter, and those do not depend on the zone.

/// Days since 1970-01-01 of a date in the proleptic Gregorian calendar.
pub fn days_from_civil(year: i64, month: u32, day: u32) -> i64 {
    let year = year - i64::from(month <= 2);
    let era = year.div_euclid(400);
    let yoe = year.rem_euclid(400);
    let m = i64::from(month);
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(day) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// `(year, month, day)` of a day counted from 1970-01-01.
pub fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let year = yoe + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

/// Seconds since 1970-01-01 of a date and a time of day (`seconds` may carry a fraction);
/// `None` when a field is out of its range.
pub fn seconds_from_civil(
    (year, month, day): (i64, u32, u32),
    (hour, minute, seconds): (u32, u32, f64),
) -> Option<f64> {
    let valid = (1..=12).contains(&month)
        && (1..=31).contains(&day)
        && hour < 24
        && minute < 60
        && (0.0..61.0).contains(&seconds);
    valid.then(|| {
        days_from_civil(year, month, day) as f64 * 86_400.0
            + f64::from(hour * 3600 + minute * 60)
            + seconds
    })
}

/// A day-first date (`"DD.MM.YYYY"`, `"DD-MM-YYYY"`) and a time of day (`"HH:MM:SS"`) as
/// seconds since 1970; `None` when either is missing or not a date and time.
pub fn seconds_from_day_first(date: Option<&str>, time: Option<&str>) -> Option<f64> {
    let parts: Vec<i64> = date?
        .trim()
        .split(['.', '-'])
        .map(|p| p.trim().parse().ok())
        .collect::<Option<_>>()?;
    let [day, month, year] = parts.as_slice() else {
        return None;
    };
    let (day, month) = (u32::try_from(*day).ok()?, u32::try_from(*month).ok()?);
    seconds_from_civil((*year, month, day), parse_time_of_day(time?)?)
}

/// `"HH:MM:SS"` (seconds may carry a fraction) as `(hour, minute, seconds)`.
pub fn parse_time_of_day(text: &str) -> Option<(u32, u32, f64)> {
    let parts: Vec<&str> = text.trim().split(':').collect();
    let [h, m, s] = parts.as_slice() else {
        return None;
    };
    let seconds: f64 = s.trim().parse().ok()?;
    Some((h.trim().parse().ok()?, m.trim().parse().ok()?, seconds))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn days_round_trip_and_known_dates() {
        assert_eq!(days_from_civil(1970, 1, 1), 0);
        assert_eq!(days_from_civil(2000, 3, 1), 11_017);
        for days in [-800_000, -1, 0, 59, 60, 11_016, 20_000, 800_000] {
            let (y, m, d) = civil_from_days(days);
            assert_eq!(days_from_civil(y, m, d), days, "{y}-{m}-{d}");
        }
    }

    #[test]
    fn times_parse_and_reject() {
        assert_eq!(parse_time_of_day("12:34:56"), Some((12, 34, 56.0)));
        assert_eq!(parse_time_of_day(" 1:02:03.5 "), Some((1, 2, 3.5)));
        assert_eq!(parse_time_of_day("12:34"), None);
        let t = seconds_from_civil((2023, 6, 3), (12, 0, 0.5)).unwrap();
        assert_eq!(t, 1_685_793_600.5);
        assert_eq!(seconds_from_civil((2023, 13, 3), (0, 0, 0.0)), None);
        assert_eq!(seconds_from_civil((2023, 1, 3), (24, 0, 0.0)), None);
    }
}
