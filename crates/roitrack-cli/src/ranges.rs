//! Value parsers for the numeric options: each refuses, as the command line is read, a value outside the range that
//! makes physical sense, and clap's error names the option (`invalid value '1e6' for '--duration-s <S>': ...`). The
//! ranges whose reason lives in a library crate (a camera, a tracker option, the simulator) are that crate's
//! constants, so that the library refuses the same values from every front end.

use std::ops::RangeInclusive;

/// Parses a finite number.
fn finite(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(v) => Err(format!("must be a finite number, got {v}")),
        Err(_) => Err(format!("not a number: {text:?}")),
    }
}

/// `v` for a message: plain between 1e-4 and 1e9, else in exponent form.
fn show(v: f64) -> String {
    if v == 0.0 || (1e-4..1e9).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// A number in `range` (both ends included), in `unit`; `why` says what the bounds stand for.
///
/// ```ignore
/// #[arg(long, value_parser = ranges::within(0.0..=1.0, "", "a fraction"))]
/// ```
pub fn within(
    range: RangeInclusive<f64>,
    unit: &'static str,
    why: &'static str,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |text| {
        let v = finite(text)?;
        if range.contains(&v) {
            Ok(v)
        } else {
            Err(format!(
                "must be from {} to {}{unit} ({why}), got {}",
                show(*range.start()),
                show(*range.end()),
                show(v)
            ))
        }
    }
}

/// A number above 0 and at most `max`, in `unit`; `why` says what the bound stands for.
pub fn positive_up_to(
    max: f64,
    unit: &'static str,
    why: &'static str,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |text| {
        let v = finite(text)?;
        if v > 0.0 && v <= max {
            Ok(v)
        } else {
            Err(format!(
                "must be above 0 and at most {}{unit} ({why}), got {}",
                show(max),
                show(v)
            ))
        }
    }
}

/// A whole number in `range`; `why` says what the bounds stand for.
pub fn count(
    range: RangeInclusive<usize>,
    why: &'static str,
) -> impl Fn(&str) -> Result<usize, String> + Clone + Send + Sync + 'static {
    move |text| {
        let v = text
            .trim()
            .parse::<usize>()
            .map_err(|_| format!("not a whole number from 0 up: {text:?}"))?;
        if range.contains(&v) {
            Ok(v)
        } else {
            Err(format!(
                "must be from {} to {} ({why}), got {v}",
                range.start(),
                range.end()
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_outside_their_range_are_refused_saying_the_range() {
        let duration = positive_up_to(86_400.0, " s", "a day");
        assert_eq!(duration("60").unwrap(), 60.0);
        assert_eq!(
            duration("1e6").unwrap_err(),
            "must be above 0 and at most 86400 s (a day), got 1000000"
        );
        assert!(duration("0").is_err() && duration("nan").is_err() && duration("inf").is_err());
        let fraction = within(0.0..=1.0, "", "a fraction");
        assert_eq!(
            fraction("1e300").unwrap_err(),
            "must be from 0 to 1 (a fraction), got 1e300"
        );
        let window = count(4..=100_000, "a window");
        assert_eq!(
            window("4000000000").unwrap_err(),
            "must be from 4 to 100000 (a window), got 4000000000"
        );
        assert!(window("-1").unwrap_err().starts_with("not a whole number"));
    }
}
