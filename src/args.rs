//! Parsers for comma-separated command-line values (`X,Y`, `X,Y,YAW`, `W,H`).

use spomp_behaviors::mission::limits;
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

/// `LAT,LON` in degrees.
pub fn lat_lon(text: &str) -> Result<(f64, f64), String> {
    let v = numbers(text, 2, "LAT,LON in degrees")?;
    if v[0].abs() > 90.0 || v[1].abs() > 180.0 {
        return Err(format!("latitude must be within ±90 and longitude within ±180 degrees, got `{text}`"));
    }
    Ok((v[0], v[1]))
}

/// `W,H` in metres, both positive.
pub fn size(text: &str) -> Result<(f64, f64), String> {
    let v = numbers(text, 2, "W,H in metres")?;
    if v[0] <= 0.0 || v[1] <= 0.0 {
        return Err(format!("sizes must be positive, got `{text}`"));
    }
    Ok((v[0], v[1]))
}

/// `ROBOT@SECONDS` (a kill fault).
pub fn kill(text: &str) -> Result<(String, f64), String> {
    let (robot, at) = text.split_once('@').ok_or_else(|| format!("expected ROBOT@SECONDS, got `{text}`"))?;
    let at_s = at.trim().parse::<f64>().ok().filter(|v| limits::duration_from_secs(*v).is_ok());
    match (robot.trim(), at_s) {
        ("", _) => Err(format!("no robot id in `{text}`")),
        (_, None) => Err(format!("`{at}` is not a time in seconds (expected ROBOT@SECONDS)")),
        (r, Some(t)) => Ok((r.to_string(), t)),
    }
}

/// A time limit in seconds: the rule of the mission's `time_limit_s` (positive, at most 7 days).
pub fn time_limit(text: &str) -> Result<f64, String> {
    let v = text.trim().parse::<f64>().map_err(|_| format!("`{text}` is not a number of seconds"))?;
    limits::check_time_limit(v)?;
    Ok(v)
}

/// Wall-clock seconds: positive and finite.
pub fn wall_seconds(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("expected a positive number of seconds, got `{text}`")),
    }
}

/// A memory budget in megabytes: positive and finite.
pub fn memory_mb(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("expected a positive number of megabytes, got `{text}`")),
    }
}

/// A real-time factor: simulated seconds per wall second, finite, 0.01 to 1000.
pub fn rate(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && (0.01..=1000.0).contains(&v) => Ok(v),
        _ => Err(format!("expected a rate between 0.01 and 1000 (× real time), got `{text}`")),
    }
}

/// A period in seconds: 0 (never) up to the longest mission duration.
pub fn period(text: &str) -> Result<f64, String> {
    let v = text.trim().parse::<f64>().map_err(|_| format!("`{text}` is not a number of seconds"))?;
    limits::duration_from_secs(v)?;
    Ok(v)
}

/// A noise multiplier: finite, between 0 and 100.
pub fn scale(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && (0.0..=100.0).contains(&v) => Ok(v),
        _ => Err(format!("expected a multiplier between 0 and 100, got `{text}`")),
    }
}

/// `FROM..TO` seconds, FROM ≤ TO.
pub fn window(text: &str) -> Result<(f64, f64), String> {
    let (a, b) = text.split_once("..").ok_or_else(|| format!("expected FROM..TO seconds, got `{text}`"))?;
    let parse = |v: &str| v.trim().parse::<f64>().ok().filter(|v| limits::duration_from_secs(*v).is_ok());
    match (parse(a), parse(b)) {
        (Some(a), Some(b)) if a <= b => Ok((a, b)),
        _ => Err(format!("expected FROM..TO with 0 ≤ FROM ≤ TO seconds, got `{text}`")),
    }
}

/// `--skill-latency`: `typical`, or PERCEPTION_S,PLANNER_S (each 0 to 60 seconds).
pub fn skill_latency(text: &str) -> Result<spomp_sim::run::SkillLatency, String> {
    if text.trim() == "typical" {
        return Ok(spomp_sim::run::SkillLatency::TYPICAL);
    }
    let bad = || format!("expected `typical` or PERCEPTION_S,PLANNER_S (0 to 60 s each), got `{text}`");
    let (a, b) = text.split_once(',').ok_or_else(bad)?;
    let parse = |v: &str| v.trim().parse::<f64>().ok().filter(|v| (0.0..=60.0).contains(v));
    match (parse(a), parse(b)) {
        (Some(perception_s), Some(planner_s)) => Ok(spomp_sim::run::SkillLatency { perception_s, planner_s }),
        _ => Err(bad()),
    }
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
        assert_eq!(kill("ugv2@300").unwrap(), ("ugv2".to_string(), 300.0));
        assert_eq!(skill_latency("typical").unwrap(), spomp_sim::run::SkillLatency::TYPICAL);
        assert_eq!(skill_latency("0.1, 2").unwrap().planner_s, 2.0);
        assert!(skill_latency("0.1").is_err());
        assert!(skill_latency("-1,2").is_err());
        assert!(skill_latency("NaN,2").is_err());
        assert!(skill_latency("1,61").is_err());
        assert!(kill("ugv2").is_err());
        assert!(kill("@3").is_err());
        assert!(kill("ugv2@-1").is_err());
        assert_eq!(window("10..20").unwrap(), (10.0, 20.0));
        assert!(window("20..10").is_err());
        assert!(window("x..1").is_err());
        assert_eq!(time_limit("600").unwrap(), 600.0);
        for bad in ["NaN", "-1", "0", "1e12", "inf", "x"] {
            assert!(time_limit(bad).is_err(), "{bad}");
        }
        assert!(kill("ugv2@1e308").is_err());
        assert!(period("0").is_ok() && period("-1").is_err() && period("NaN").is_err());
        assert!(scale("2").is_ok() && scale("-1").is_err() && scale("inf").is_err());
    }
}
