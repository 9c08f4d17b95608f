//! A farm hears a robot that reported before the farm listened: a `spomp run` process publishes
//! its status once at time zero and then waits for the farm's clock, so a status lost to
//! discovery's timing was never repeated (with six processes on loopback, ugv3 was "not seen in
//! 60 s" although it had started with the others).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::{Duration, Instant};

use spomp_core::Time;
use spomp_ros_msgs as ros;
use spomp_ros2::FarmLink;
use spomp_ros2::dds::{DdsNode, DdsSettings, latched_qos};

#[test]
fn a_status_published_before_the_farm_listened_still_reaches_it() {
    let settings = DdsSettings {
        domain_id: 150 + (std::process::id() % 40) as u16,
        interfaces: vec![std::net::IpAddr::from([127, 0, 0, 1])],
    };
    let mut robot = DdsNode::new(&settings, "/ugv3", "spomp").expect("robot node");
    let status = robot.publisher::<ros::StringMsg>("/ugv3/team/status", &latched_qos(1)).expect("status publisher");
    let report = r#"{"robot":"ugv3","time_s":0.0,"tree":"running","stop":"none","goals":[]}"#;
    status.publish(ros::StringMsg { data: report.into() }).expect("published");
    // The farm starts listening only now.
    let mut farm = FarmLink::new(&settings, &[("ugv3".into(), None)], false).expect("farm link");
    let deadline = Instant::now() + Duration::from_secs(20);
    while farm.tree_status("ugv3").is_empty() && Instant::now() < deadline {
        farm.poll(Time::ZERO);
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(farm.tree_status("ugv3"), "running");
}
