//! Pacing a run to the wall clock: simulated time advances at real time × a rate, for someone
//! watching (`spomp sim --live`) or for robot processes that live in real time (the ROS 2 robot
//! farm). Unpaced runs go as fast as the CPU allows.

use std::time::{Duration, Instant};

use spomp_core::Time;

/// Holds a run back until the wall clock catches up with simulated time ÷ rate.
#[derive(Debug, Clone)]
pub struct RealTimePacer {
    rate: f64,
    /// Wall instant of simulated time zero, set by the first [`RealTimePacer::wait_until`].
    start: Option<Instant>,
}

impl RealTimePacer {
    /// A pacer running simulated time at `rate` × real time; a rate that is not positive and
    /// finite does not pace at all.
    pub fn new(rate: f64) -> Self {
        RealTimePacer { rate, start: None }
    }

    /// Simulated seconds per wall second.
    pub fn rate(&self) -> f64 {
        self.rate
    }

    /// Sleeps until simulated time `now` is due on the wall clock. The first call sets the
    /// clock so that `now` is due at once (a run may start at any simulated time, and whatever
    /// happened before the first call — setup, waiting for robot processes — is not owed).
    /// A run that falls behind (slower than the rate) does not sleep and is not sped up later
    /// beyond catching up.
    pub fn wait_until(&mut self, now: Time) {
        if !(self.rate.is_finite() && self.rate > 0.0) {
            return;
        }
        let offset = Duration::from_secs_f64((now.as_secs_f64() / self.rate).max(0.0));
        let start = *self.start.get_or_insert_with(|| Instant::now().checked_sub(offset).unwrap_or_else(Instant::now));
        let wait = (start + offset).saturating_duration_since(Instant::now());
        if !wait.is_zero() {
            std::thread::sleep(wait);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bound no sleeping call stays under on any machine, however loaded, while the waits the
    /// tests rule out would be far longer.
    const NO_WAIT: Duration = Duration::from_secs(60);

    #[test]
    fn the_first_call_sets_the_clock_and_later_ones_wait_their_share() {
        let mut slow = RealTimePacer::new(1e-3);
        let t0 = Instant::now();
        slow.wait_until(Time::from_secs_f64(5.0)); // would be 5000 s if it were owed
        assert!(t0.elapsed() < NO_WAIT, "the first call does not wait");
        // Sleeping never returns early: one simulated second at 20× is at least 50 ms.
        let mut fast = RealTimePacer::new(20.0);
        fast.wait_until(Time::from_secs_f64(5.0));
        let t1 = Instant::now();
        fast.wait_until(Time::from_secs_f64(6.0));
        assert!(t1.elapsed() >= Duration::from_millis(49));
        assert_eq!(fast.rate(), 20.0);
    }

    #[test]
    fn a_rate_that_is_not_positive_and_finite_does_not_pace() {
        for rate in [f64::INFINITY, 0.0, -1.0, f64::NAN] {
            let mut pacer = RealTimePacer::new(rate);
            pacer.wait_until(Time::ZERO);
            let t0 = Instant::now();
            pacer.wait_until(Time::from_secs_f64(1e6));
            assert!(t0.elapsed() < NO_WAIT, "rate {rate}");
        }
    }
}
