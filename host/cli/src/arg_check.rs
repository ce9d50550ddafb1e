//! Value parsers for flags whose range clap's types do not express: a count of zero or a
//! non-finite number is refused when the command line is read, with the flag named, instead of
//! running a command that does nothing or fills its output with NaN.

/// A count of at least one (steps, repeats, environments, threads, "every k-th").
pub fn count(s: &str) -> Result<usize, String> {
    let v: usize = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a whole number"))?;
    if v == 0 {
        return Err("must be at least 1".into());
    }
    Ok(v)
}

/// A finite number above zero (a duration, a length).
pub fn positive(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if v <= 0.0 {
        return Err(format!("must be greater than 0 (got {v})"));
    }
    Ok(v)
}

/// A finite number at or above zero (a weight of a loss term).
pub fn non_negative(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if v < 0.0 {
        return Err(format!("must be 0 or more (got {v})"));
    }
    Ok(v)
}

/// A number at or above zero, or `inf` (a time that may be unbounded).
pub fn non_negative_or_inf(s: &str) -> Result<f64, String> {
    if matches!(s.trim(), "inf" | "infinity") {
        return Ok(f64::INFINITY);
    }
    non_negative(s).map_err(|e| format!("{e}; or inf"))
}

/// A number in [0, 1] (a fraction).
pub fn fraction(s: &str) -> Result<f64, String> {
    let v = number(s)?;
    if !(0.0..=1.0).contains(&v) {
        return Err(format!("must lie between 0 and 1 (got {v})"));
    }
    Ok(v)
}

/// A finite number (an angle, an offset).
pub fn finite(s: &str) -> Result<f64, String> {
    number(s)
}

/// A finite number.
fn number(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number"))?;
    if !v.is_finite() {
        return Err(format!("must be a finite number (got {v})"));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_and_numbers_are_checked() {
        assert_eq!(count("3"), Ok(3));
        assert!(count("0").unwrap_err().contains("at least 1"));
        assert!(count("-1").is_err() && count("1.5").is_err());
        assert_eq!(positive("0.25"), Ok(0.25));
        for bad in ["0", "-1", "nan", "inf", "x"] {
            assert!(positive(bad).is_err(), "{bad}");
        }
        assert_eq!(non_negative("0"), Ok(0.0));
        for bad in ["-0.5", "NaN", "-inf"] {
            assert!(non_negative(bad).is_err(), "{bad}");
        }
        assert_eq!(finite("-2.5"), Ok(-2.5));
        assert!(finite("nan").is_err() && finite("inf").is_err());
    }
}
