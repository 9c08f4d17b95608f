//! Time as data. Skills and nodes never read the system clock: adapters hand them a [`Time`]
//! (the simulator's lockstep clock, a robot's wall clock) so that simulated runs are repeatable
//! and logs can be replayed.

use std::fmt;
use std::ops::{Add, Sub};
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// A point in time, in integer nanoseconds since the start of a run (or any fixed epoch).
///
/// Integer nanoseconds keep lockstep simulation exact: adding 100 ms ten thousand times lands
/// exactly on 1000 s, which floating-point seconds do not.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Time {
    /// Nanoseconds since the epoch of the run.
    pub nanos: i64,
}

impl Time {
    /// The epoch.
    pub const ZERO: Time = Time { nanos: 0 };

    /// A time from nanoseconds.
    pub const fn from_nanos(nanos: i64) -> Self {
        Time { nanos }
    }

    /// A time from milliseconds.
    pub const fn from_millis(millis: i64) -> Self {
        Time { nanos: millis * 1_000_000 }
    }

    /// A time from (possibly fractional) seconds, rounded to the nearest nanosecond.
    pub fn from_secs_f64(secs: f64) -> Self {
        Time { nanos: (secs * 1e9).round() as i64 }
    }

    /// Seconds since the epoch.
    pub fn as_secs_f64(self) -> f64 {
        self.nanos as f64 / 1e9
    }

    /// Time elapsed since `earlier`, saturating at zero.
    pub fn since(self, earlier: Time) -> Duration {
        Duration::from_nanos(self.nanos.saturating_sub(earlier.nanos).max(0) as u64)
    }

    /// Seconds elapsed since `earlier` (negative if `earlier` is later).
    pub fn secs_since(self, earlier: Time) -> f64 {
        (self.nanos - earlier.nanos) as f64 * 1e-9
    }
}

impl Add<Duration> for Time {
    type Output = Time;
    fn add(self, rhs: Duration) -> Time {
        Time { nanos: self.nanos.saturating_add(rhs.as_nanos().min(i64::MAX as u128) as i64) }
    }
}

impl Sub<Time> for Time {
    type Output = Duration;
    fn sub(self, rhs: Time) -> Duration {
        self.since(rhs)
    }
}

impl fmt::Display for Time {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:.3}s", self.as_secs_f64())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lockstep_steps_are_exact() {
        let mut now = Time::ZERO;
        for _ in 0..10_000 {
            now = now + Duration::from_millis(100);
        }
        assert_eq!(now, Time::from_millis(1_000_000));
        assert_eq!(now.as_secs_f64(), 1000.0);
    }

    #[test]
    fn since_saturates() {
        let a = Time::from_millis(5);
        let b = Time::from_millis(9);
        assert_eq!(a.since(b), Duration::ZERO);
        assert_eq!(b.since(a), Duration::from_millis(4));
        assert!((a.secs_since(b) + 0.004).abs() < 1e-12);
    }
}
