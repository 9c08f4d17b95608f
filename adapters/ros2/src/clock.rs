//! Robot time and ROS time.
//!
//! A robot's [`Time`] counts from the start of its run (mission times, time limits and leases
//! are relative to it); ROS stamps count from the Unix epoch (wall clock) or from a simulator's
//! start (`/clock`). A [`TimeBase`] holds the ROS time of robot time zero.

use std::time::{SystemTime, UNIX_EPOCH};

use spomp_core::Time;
use spomp_ros_msgs::RosTime;

/// The ROS time at which robot time is zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimeBase {
    epoch_nanos: i64,
}

impl TimeBase {
    /// Robot time equals ROS time (a simulator's `/clock`, which starts at zero with the mission).
    pub const SIMULATED: TimeBase = TimeBase { epoch_nanos: 0 };

    /// Robot time zero is now on the wall clock.
    pub fn wall_now() -> Self {
        TimeBase { epoch_nanos: wall_nanos() }
    }

    /// Robot time zero at `epoch_nanos` of ROS time.
    pub fn at(epoch_nanos: i64) -> Self {
        TimeBase { epoch_nanos }
    }

    /// ROS time of robot time zero, nanoseconds.
    pub fn epoch_nanos(&self) -> i64 {
        self.epoch_nanos
    }

    /// Robot time of a ROS stamp.
    pub fn to_robot(&self, stamp: RosTime) -> Time {
        Time::from_nanos(ros_nanos(stamp).saturating_sub(self.epoch_nanos))
    }

    /// ROS stamp of a robot time.
    pub fn to_ros(&self, t: Time) -> RosTime {
        RosTime::from(Time::from_nanos(t.nanos.saturating_add(self.epoch_nanos)))
    }
}

/// Nanoseconds of a ROS stamp.
pub fn ros_nanos(stamp: RosTime) -> i64 {
    i64::from(stamp.sec) * 1_000_000_000 + i64::from(stamp.nanosec)
}

/// Wall-clock nanoseconds since the Unix epoch.
pub fn wall_nanos() -> i64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robot_and_ros_time_round_trip_around_the_epoch() {
        let base = TimeBase::at(1_700_000_000_123_456_789);
        let t = Time::from_nanos(2_500_000_000);
        let ros = base.to_ros(t);
        assert_eq!(ros, RosTime { sec: 1_700_000_002, nanosec: 623_456_789 });
        assert_eq!(base.to_robot(ros), t);
        assert_eq!(TimeBase::SIMULATED.to_robot(RosTime { sec: 3, nanosec: 5 }), Time::from_nanos(3_000_000_005));
    }
}
