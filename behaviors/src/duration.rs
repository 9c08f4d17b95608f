//! Durations in seconds as nodes read them: checked, so a duration a node is given at tick
//! time (a `wait` bound to an entry) fails the node instead of panicking the robot. The mission
//! language applies the same rule to the literals it loads (`mission::limits`).

use std::time::Duration;

/// The longest duration a node accepts, seconds (about 31.7 years: missions write
/// `wait: { duration_s: 1e9 }` for "until halted"). Far longer than any time limit, and small
/// enough that every time computed from it stays exact in integer nanoseconds.
pub const MAX_DURATION_S: f64 = 1e9;

/// A duration from seconds, checked: finite, non-negative and at most [`MAX_DURATION_S`].
/// The error says what was expected.
pub fn duration_from_secs(secs: f64) -> Result<Duration, String> {
    if secs.is_finite() && (0.0..=MAX_DURATION_S).contains(&secs) {
        Ok(Duration::from_secs_f64(secs))
    } else {
        Err(format!("expected a duration between 0 and 1e9 s (1e9 stands for \"for ever\"), found {}", number(secs)))
    }
}

/// A number as a user would write it: `1e308` rather than 309 digits.
pub fn number(v: f64) -> String {
    if v.is_finite() && v != 0.0 && !(1e-3..1e7).contains(&v.abs()) { format!("{v:e}") } else { format!("{v}") }
}
