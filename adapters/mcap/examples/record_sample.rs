//! Writes a small MCAP log (poses, commands, a panorama, a scan, node transitions) to the path
//! given as the first argument; CI reads it with the Python `mcap` reader to check the file and
//! its ROS 2 schemas are standard.

use spomp_behaviors::Status;
use spomp_behaviors::trace::TransitionRecord;
use spomp_core::{DepthPanorama, PanoramaGeometry, Pose2, ReachabilityScan, RobotId, SemanticPanorama, Time, Twist2};
use spomp_mcap::{Recorder, RecorderOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: record_sample OUT.mcap")?;
    let mut rec = Recorder::create(std::path::Path::new(&path), RecorderOptions::default())?;
    for i in 0..10 {
        let t = Time::from_millis(100 * i);
        rec.pose("ugv1", t, Pose2::new(i as f64 * 0.1, 0.0, 0.0), 0.0)?;
        rec.command("ugv1", t, Twist2 { v: 1.0, omega: 0.0 })?;
    }
    let g = PanoramaGeometry::default_lidar();
    let depth = DepthPanorama { geometry: g, range_m: vec![5.0; g.len()] };
    let sem = SemanticPanorama { geometry: g, class: vec![0; g.len()] };
    rec.panorama("ugv1", Time::from_millis(1000), &depth, Some(&sem))?;
    rec.reachability(&ReachabilityScan {
        robot: RobotId::new("ugv1"),
        stamp: Time::from_millis(1000),
        pose: Pose2::default(),
        range_m: vec![3.0; 1024],
        obstacle: vec![false; 1024],
    })?;
    rec.path("ugv1", Time::from_millis(1000), &[spomp_core::Point2::new(0.0, 0.0), spomp_core::Point2::new(5.0, 5.0)])?;
    rec.transitions(
        "ugv1",
        &[TransitionRecord {
            tick: 1,
            time: Time::ZERO,
            node_id: 0,
            path: "visitor".into(),
            from: Status::Idle,
            to: Status::Running,
        }],
    )?;
    rec.json("/team/state", Time::from_millis(1000), &serde_json::json!({"event": "claimed", "goal": "ugv1/0"}))?;
    let n = rec.message_count();
    rec.finish()?;
    println!("wrote {n} messages to {path}");
    Ok(())
}
