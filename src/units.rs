//! Units on the command line (PROTOCOL.md, "Units and flags"): SI sizes and rates,
//! durations in ms, s or min, rationals for frame rates.

/// `500ms`, `4s`, `2min` or a bare number of seconds → seconds.
pub fn parse_duration(s: &str) -> Result<f64, String> {
    let t = s.trim();
    let (num, scale) = if let Some(n) = t.strip_suffix("ms") {
        (n, 1e-3)
    } else if let Some(n) = t.strip_suffix("min") {
        (n, 60.0)
    } else if let Some(n) = t.strip_suffix('s') {
        (n, 1.0)
    } else {
        (t, 1.0)
    };
    match num.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v * scale),
        _ => Err(format!("duration {s:?} (expected e.g. 300ms, 4s, 2min)")),
    }
}

/// `24/1`, `1/6` or `24` → (num, den).
pub fn parse_rate(s: &str) -> Result<(u32, u32), String> {
    vbim_bake::scene::parse_rate(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations() {
        assert_eq!(parse_duration("300ms").unwrap(), 0.3);
        assert_eq!(parse_duration("4s").unwrap(), 4.0);
        assert_eq!(parse_duration("2min").unwrap(), 120.0);
        assert!(parse_duration("-1s").is_err());
        assert!(parse_duration("fast").is_err());
    }
}
