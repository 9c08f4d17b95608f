//! Parsers for comma-separated command-line values (`X,Y`, `X,Y,YAW`, `W,H`).

use spomp_core::{Point2, Pose2};

fn numbers(text: &str, expected: usize, what: &str) -> Result<Vec<f64>, String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != expected {
        return Err(format!("expected {what}, got `{text}`"));
    }
    parts
        .iter()
        .map(|p| match p.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(format!("`{p}` is not a finite number (expected {what})")),
        })
        .collect()
}

/// `X,Y` in metres.
pub fn point(text: &str) -> Result<Point2, String> {
    let v = numbers(text, 2, "X,Y in metres")?;
    Ok(Point2::new(v[0], v[1]))
}

/// `X,Y,YAW` in metres and radians.
pub fn pose(text: &str) -> Result<Pose2, String> {
    let v = numbers(text, 3, "X,Y,YAW in metres and radians")?;
    Ok(Pose2::new(v[0], v[1], v[2]))
}

/// `W,H` in metres, both positive.
pub fn size(text: &str) -> Result<(f64, f64), String> {
    let v = numbers(text, 2, "W,H in metres")?;
    if v[0] <= 0.0 || v[1] <= 0.0 {
        return Err(format!("sizes must be positive, got `{text}`"));
    }
    Ok((v[0], v[1]))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn parses_and_rejects() {
        assert_eq!(point("1.5, -2").unwrap(), Point2::new(1.5, -2.0));
        assert_eq!(pose("1,2,0.5").unwrap(), Pose2::new(1.0, 2.0, 0.5));
        assert_eq!(size("120,100").unwrap(), (120.0, 100.0));
        assert!(point("1").is_err());
        assert!(point("1,2,3").is_err());
        assert!(point("a,2").is_err());
        assert!(point("NaN,2").is_err());
        assert!(size("0,5").is_err());
        assert!(pose("1,2").is_err());
    }
}
