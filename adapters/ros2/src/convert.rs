//! Between spomp's types and the ROS 2 messages of [`spomp_ros_msgs`] (the recorder's own).
//!
//! Frames follow REP-105, named by the robot's [`RobotFrames`] (`crate::frames`: `map`,
//! `<prefix>odom`, `<prefix>base_link`, `<prefix>lidar` by default); units follow REP-103
//! (metres, radians, x forward / east, z up).

use std::sync::Arc;

use spomp_core::{
    ClassId, DepthPanorama, FlightCommand, Odometry, PanoramaGeometry, Point2, Pose2, PoseEstimate, ReachabilityScan,
    SemanticPanorama, Time, Twist2, UNKNOWN_CLASS,
};
use spomp_ros_msgs as ros;
use spomp_ros_msgs::{DepthEncoding, RobotFrames};

use spomp_teamstate::GoalView;

use crate::clock::TimeBase;

/// Why a message could not be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConvertError {
    /// An image whose encoding is not the one its topic carries.
    #[error("{topic}: expected encoding {expected}, found `{found}`")]
    Encoding {
        /// Topic role.
        topic: &'static str,
        /// Accepted encodings.
        expected: &'static str,
        /// What arrived.
        found: String,
    },
    /// An image whose size, step or data length disagree.
    #[error("{topic}: {height}×{width} image with step {step} needs {needed} bytes, has {actual}")]
    Size {
        /// Topic role.
        topic: &'static str,
        /// Rows.
        height: u32,
        /// Columns.
        width: u32,
        /// Bytes per row.
        step: u32,
        /// Bytes needed.
        needed: u64,
        /// Bytes present.
        actual: usize,
    },
    /// A value that is not finite or out of range.
    #[error("{0}")]
    Value(String),
}

/// Yaw of a quaternion (rotation about +z of its heading).
pub fn yaw_of(q: &ros::Quaternion) -> f64 {
    (2.0 * (q.w * q.z + q.x * q.y)).atan2(1.0 - 2.0 * (q.y * q.y + q.z * q.z))
}

/// Robot odometry from `nav_msgs/Odometry` (pose in the odometry frame, twist in the body frame).
pub fn odometry_from_ros(msg: &ros::Odometry, base: &TimeBase) -> Result<Odometry, ConvertError> {
    let p = &msg.pose.pose;
    let pose = Pose2::new(p.position.x, p.position.y, yaw_of(&p.orientation));
    let twist = Twist2 { v: msg.twist.twist.linear.x, omega: msg.twist.twist.angular.z };
    if ![pose.x, pose.y, pose.yaw, twist.v, twist.omega].iter().all(|v| v.is_finite()) {
        return Err(ConvertError::Value("odometry: a pose or twist value is not finite".into()));
    }
    Ok(Odometry { stamp: base.to_robot(msg.header.stamp), pose, twist })
}

/// `nav_msgs/Odometry` from robot odometry.
pub fn odometry_to_ros(frames: &RobotFrames, odom: &Odometry, base: &TimeBase) -> ros::Odometry {
    ros::Odometry::from_odometry(frames, odom, base.to_ros(odom.stamp))
}

/// The `odom → base_link` transform of an odometry pose (what a robot's driver broadcasts).
pub fn odom_to_base(frames: &RobotFrames, odom: &Odometry, base: &TimeBase) -> ros::TfMessage {
    let stamp = base.to_ros(odom.stamp);
    ros::TfMessage {
        transforms: vec![ros::TransformStamped::planar(&frames.odom, &frames.base_link, odom.pose, 0.0, stamp)],
    }
}

/// The static `base_link → sensor` transform: the panorama sensor `height_m` above the body
/// origin, axes aligned (what `robot_state_publisher` sends on `tf_static`).
pub fn sensor_mount(frames: &RobotFrames, height_m: f64, stamp: Time, base: &TimeBase) -> ros::TfMessage {
    let mount = ros::TransformStamped::planar(
        &frames.base_link,
        &frames.sensor,
        Pose2::new(0.0, 0.0, 0.0),
        height_m,
        base.to_ros(stamp),
    );
    ros::TfMessage { transforms: vec![mount] }
}

/// A velocity command as `geometry_msgs/Twist`.
pub fn twist_to_ros(cmd: Twist2) -> ros::Twist {
    ros::Twist::from_twist2(cmd)
}

/// A velocity command as `geometry_msgs/TwistStamped` in the body frame.
pub fn twist_stamped_to_ros(cmd: Twist2, frames: &RobotFrames, stamp: Time, base: &TimeBase) -> ros::TwistStamped {
    ros::TwistStamped::from_twist2(cmd, &frames.base_link, base.to_ros(stamp))
}

/// A velocity command from `geometry_msgs/Twist` (non-finite values are refused).
pub fn twist_from_ros(msg: &ros::Twist) -> Result<Twist2, ConvertError> {
    let cmd = Twist2 { v: msg.linear.x, omega: msg.angular.z };
    if cmd.v.is_finite() && cmd.omega.is_finite() {
        Ok(cmd)
    } else {
        Err(ConvertError::Value("cmd_vel: not finite".into()))
    }
}

/// A UAV position setpoint (`geometry_msgs/PoseStamped` in `map`, as a PX4/MAVROS offboard bridge
/// takes it: x east, y north, z up), facing the direction of travel from `from`.
pub fn setpoint_to_ros(
    cmd: &FlightCommand,
    from: Option<Point2>,
    map: &str,
    stamp: Time,
    base: &TimeBase,
) -> ros::PoseStamped {
    let yaw = from.map_or(0.0, |p| (cmd.target.y - p.y).atan2(cmd.target.x - p.x));
    ros::PoseStamped {
        header: ros::Header { stamp: base.to_ros(stamp), frame_id: map.into() },
        pose: ros::Pose::from_pose2(Pose2::new(cmd.target.x, cmd.target.y, yaw), cmd.altitude_m),
    }
}

/// A map-frame pose input (`geometry_msgs/PoseStamped`: a UAV's local position, a surveyed
/// pose, a simulator's truth) as a pose estimate.
pub fn pose_from_ros(msg: &ros::PoseStamped, base: &TimeBase) -> Result<PoseEstimate, ConvertError> {
    let p = &msg.pose;
    let pose = Pose2::new(p.position.x, p.position.y, yaw_of(&p.orientation));
    if ![pose.x, pose.y, pose.yaw].iter().all(|v| v.is_finite()) {
        return Err(ConvertError::Value("pose input: not finite".into()));
    }
    Ok(PoseEstimate { stamp: base.to_robot(msg.header.stamp), pose, covariance: [0.0; 9], confidence: 1.0 })
}

/// A map-frame pose as `geometry_msgs/PoseStamped`.
pub fn pose_to_ros(pose: Pose2, z: f64, map: &str, stamp: Time, base: &TimeBase) -> ros::PoseStamped {
    ros::PoseStamped {
        header: ros::Header { stamp: base.to_ros(stamp), frame_id: map.into() },
        pose: ros::Pose::from_pose2(pose, z),
    }
}

/// WGS 84 → local east-north on the tangent plane at the origin. Good to centimetres over the
/// few kilometres of a mission area.
pub fn gps_to_map(lat_deg: f64, lon_deg: f64, origin_lat_deg: f64, origin_lon_deg: f64) -> Point2 {
    // WGS 84 radii of curvature at the origin's latitude.
    const A: f64 = 6_378_137.0;
    const E2: f64 = 6.694_379_990_14e-3;
    let lat0 = origin_lat_deg.to_radians();
    let s = lat0.sin();
    let w = (1.0 - E2 * s * s).sqrt();
    let meridian = A * (1.0 - E2) / (w * w * w);
    let normal = A / w;
    let d_lat = (lat_deg - origin_lat_deg).to_radians();
    let mut d_lon = (lon_deg - origin_lon_deg).to_radians();
    if d_lon > std::f64::consts::PI {
        d_lon -= std::f64::consts::TAU;
    } else if d_lon < -std::f64::consts::PI {
        d_lon += std::f64::consts::TAU;
    }
    Point2::new(d_lon * normal * lat0.cos(), d_lat * meridian)
}

/// A GNSS fix as a position estimate (the heading is unknown: the estimate's yaw is 0 with an
/// infinite variance). Fixes without a fix (status −1) or with non-finite values are refused.
pub fn navsat_to_estimate(
    msg: &ros::NavSatFix,
    origin: (f64, f64),
    base: &TimeBase,
) -> Result<PoseEstimate, ConvertError> {
    if msg.status.status < 0 {
        return Err(ConvertError::Value("gps: no fix".into()));
    }
    if !(msg.latitude.is_finite() && msg.longitude.is_finite()) {
        return Err(ConvertError::Value("gps: latitude or longitude not finite".into()));
    }
    let p = gps_to_map(msg.latitude, msg.longitude, origin.0, origin.1);
    let var = |v: f64| if v.is_finite() && v > 0.0 { v } else { 1.0 };
    let mut covariance = [0.0; 9];
    covariance[0] = var(msg.position_covariance[0]);
    covariance[4] = var(msg.position_covariance[4]);
    covariance[8] = f64::INFINITY;
    Ok(PoseEstimate {
        stamp: base.to_robot(msg.header.stamp),
        pose: Pose2::new(p.x, p.y, 0.0),
        covariance,
        confidence: 1.0,
    })
}

/// Checks an image's shape: `bytes_per_pixel` per pixel, rows of `step` bytes.
fn check_image(img: &ros::Image, topic: &'static str, bytes_per_pixel: u32) -> Result<(), ConvertError> {
    let needed = u64::from(img.step) * u64::from(img.height);
    let row_ok = u64::from(img.step) >= u64::from(img.width) * u64::from(bytes_per_pixel);
    if !row_ok || (img.data.len() as u64) < needed || img.width == 0 || img.height == 0 {
        return Err(ConvertError::Size {
            topic,
            height: img.height,
            width: img.width,
            step: img.step,
            needed,
            actual: img.data.len(),
        });
    }
    Ok(())
}

/// A depth panorama from an image in any [`DepthEncoding`], read by its own `encoding` field:
/// `32FC1` metres (non-finite or ≤ 0 = no return), `16UC1` and `mono16` counts of `scale_m`
/// metres (`None`: 1 mm for `16UC1` per REP-118, 1/512 m for `mono16`; 0 = no return).
pub fn depth_from_ros(img: &ros::Image, v_fov_rad: f64, scale_m: Option<f64>) -> Result<DepthPanorama, ConvertError> {
    let encoding = DepthEncoding::from_name(&img.encoding).ok_or_else(|| ConvertError::Encoding {
        topic: "panorama/depth",
        expected: "32FC1, 16UC1 or mono16",
        found: img.encoding.clone(),
    })?;
    check_image(img, "panorama/depth", encoding.bytes_per_pixel() as u32)?;
    let geometry = PanoramaGeometry { rows: img.height as usize, cols: img.width as usize, v_fov_rad };
    let mut range_m = Vec::with_capacity(geometry.len());
    let bpp = encoding.bytes_per_pixel();
    let big = img.is_bigendian != 0;
    let scale = scale_m.or(encoding.default_scale_m()).unwrap_or(1.0);
    for r in 0..geometry.rows {
        let row = &img.data[r * img.step as usize..][..geometry.cols * bpp];
        for px in row.chunks_exact(bpp) {
            let m = if let [a, b, c, d] = *px {
                let v = if big { f32::from_be_bytes([a, b, c, d]) } else { f32::from_le_bytes([a, b, c, d]) };
                if v.is_finite() && v > 0.0 { v } else { 0.0 }
            } else {
                let bytes = [px[0], px[1]];
                let count = if big { u16::from_be_bytes(bytes) } else { u16::from_le_bytes(bytes) };
                (f64::from(count) * scale) as f32
            };
            range_m.push(m);
        }
    }
    Ok(DepthPanorama { geometry, range_m })
}

/// A depth panorama as an image in `encoding` in the sensor frame `frame` (`scale_m`: metres
/// per count of an integer encoding, `None` for its default).
pub fn depth_to_ros(
    frame: &str,
    depth: &DepthPanorama,
    encoding: DepthEncoding,
    scale_m: Option<f64>,
    stamp: Time,
    base: &TimeBase,
) -> ros::Image {
    let header = ros::Header { stamp: base.to_ros(stamp), frame_id: frame.into() };
    ros::Image::from_depth(header, depth, encoding, scale_m, 1)
}

/// Semantic labels from a `mono8`/`8UC1` image; labels beyond the class table become unknown.
pub fn semantic_from_ros(img: &ros::Image, v_fov_rad: f64, classes: usize) -> Result<SemanticPanorama, ConvertError> {
    if !matches!(img.encoding.as_str(), "mono8" | "8UC1") {
        return Err(ConvertError::Encoding {
            topic: "panorama/semantic",
            expected: "mono8 or 8UC1",
            found: img.encoding.clone(),
        });
    }
    check_image(img, "panorama/semantic", 1)?;
    let geometry = PanoramaGeometry { rows: img.height as usize, cols: img.width as usize, v_fov_rad };
    let mut class: Vec<ClassId> = Vec::with_capacity(geometry.len());
    for r in 0..geometry.rows {
        let row = &img.data[r * img.step as usize..][..geometry.cols];
        class.extend(row.iter().map(|&c| if (c as usize) < classes { c } else { UNKNOWN_CLASS }));
    }
    Ok(SemanticPanorama { geometry, class })
}

/// Semantic labels as a `mono8` image in the sensor frame `frame`.
pub fn semantic_to_ros(frame: &str, sem: &SemanticPanorama, stamp: Time, base: &TimeBase) -> ros::Image {
    let g = sem.geometry;
    ros::Image {
        header: ros::Header { stamp: base.to_ros(stamp), frame_id: frame.into() },
        height: g.rows as u32,
        width: g.cols as u32,
        encoding: "mono8".into(),
        is_bigendian: 0,
        step: g.cols as u32,
        data: sem.class.clone(),
    }
}

/// The pose estimate as `geometry_msgs/PoseWithCovarianceStamped` in `map` (x, y, yaw
/// variances placed in the 6 × 6 matrix; z, roll, pitch unknown).
pub fn estimate_to_ros(est: &PoseEstimate, map: &str, base: &TimeBase) -> ros::PoseWithCovarianceStamped {
    ros::PoseWithCovarianceStamped::from_estimate(est, map, base.to_ros(est.stamp))
}

/// The `map → odom` transform that puts the odometry pose at the estimate:
/// T(map←odom) = T(map←base) · T(odom←base)⁻¹.
pub fn map_to_odom(frames: &RobotFrames, estimate: Pose2, odom: Pose2, stamp: Time, base: &TimeBase) -> ros::TfMessage {
    ros::TfMessage::map_to_odom(frames, estimate, odom, base.to_ros(stamp))
}

/// A planned path as `nav_msgs/Path` in `map`.
pub fn path_to_ros(points: &[Point2], map: &str, stamp: Time, base: &TimeBase) -> ros::Path {
    let mut path = ros::Path::from_points(points, base.to_ros(stamp));
    path.header.frame_id = map.into();
    for p in &mut path.poses {
        p.header.frame_id = map.into();
    }
    path
}

/// A reachability scan as `sensor_msgs/LaserScan` in the body frame (bin i at angle −i·2π/N,
/// intensity 1 where a known obstacle ends the bin; REP-117 limits) — the recorder's layout.
pub fn scan_to_ros(scan: &ReachabilityScan, frames: &RobotFrames, base: &TimeBase) -> ros::LaserScan {
    ros::LaserScan::from_reachability(scan, &frames.base_link, base.to_ros(scan.stamp))
}

/// Goals and claims as `visualization_msgs/MarkerArray`: one cylinder per goal (grey open,
/// orange claimed, green visited) and a text label with its id and holder. The first marker
/// deletes all earlier ones, so goals that merged disappear.
pub fn goals_to_ros(goals: &[GoalView], map: &str, stamp: Time, base: &TimeBase) -> ros::MarkerArray {
    let goals = goals.iter().map(|g| ros::GoalMarkerInput {
        id: &g.id,
        position: g.position,
        claimed_by: g.claimant.as_ref().map(|c| c.robot.as_str()),
        visited_by: g.visited.as_ref().map(|(_, r)| r.as_str()),
        cancelled: g.cancelled.is_some(),
        priority: g.priority,
    });
    let mut markers = ros::MarkerArray::goals(goals, base.to_ros(stamp));
    for m in &mut markers.markers {
        m.header.frame_id = map.into();
    }
    markers
}

/// Wraps a depth and a semantic panorama of one instant into a frame.
pub fn frame(
    seq: u64,
    stamp: Time,
    odom_pose: Pose2,
    sensor_height_m: f64,
    depth: DepthPanorama,
    semantic: SemanticPanorama,
) -> spomp_core::PanoramaFrame {
    spomp_core::PanoramaFrame {
        seq,
        stamp,
        odom_pose,
        sensor_height_m,
        depth: Arc::new(depth),
        semantic: Arc::new(semantic),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn panorama() -> DepthPanorama {
        // No return, near, mid, beyond 16UC1's 65.535 m, not finite.
        let range_m = vec![0.0, 0.5, 12.25, 70.0, f32::NAN, -1.0];
        DepthPanorama { geometry: PanoramaGeometry { rows: 2, cols: 3, v_fov_rad: 1.0 }, range_m }
    }

    fn round_trip(encoding: DepthEncoding, scale_m: Option<f64>) -> (ros::Image, Vec<f32>) {
        let img = depth_to_ros("ugv1/lidar", &panorama(), encoding, scale_m, Time::ZERO, &TimeBase::SIMULATED);
        let back = depth_from_ros(&img, 1.0, scale_m).expect("decodes");
        (img, back.range_m)
    }

    #[test]
    fn float_metres_keep_every_range_and_mark_no_return_infinite() {
        let (img, back) = round_trip(DepthEncoding::Float32Metres, None);
        assert_eq!((img.encoding.as_str(), img.step, img.data.len()), ("32FC1", 12, 24));
        let first = f32::from_le_bytes([img.data[0], img.data[1], img.data[2], img.data[3]]);
        assert_eq!(first, f32::INFINITY, "REP-117: no return is +inf");
        assert_eq!(back, vec![0.0, 0.5, 12.25, 70.0, 0.0, 0.0]);
    }

    #[test]
    fn millimetres_per_rep_118_saturate_at_65_m() {
        let (img, back) = round_trip(DepthEncoding::Uint16, None);
        assert_eq!(img.encoding, "16UC1");
        assert_eq!(u16::from_le_bytes([img.data[4], img.data[5]]), 12_250, "12.25 m = 12250 mm");
        assert_eq!(back, vec![0.0, 0.5, 12.25, 65.535, 0.0, 0.0]);
    }

    #[test]
    fn mono16_keeps_its_1_512_m_counts_and_reads_as_before() {
        let (img, back) = round_trip(DepthEncoding::Mono16, None);
        assert_eq!(img.encoding, "mono16");
        assert_eq!(u16::from_le_bytes([img.data[2], img.data[3]]), 256, "0.5 m = 256 counts of 1/512 m");
        assert_eq!(back, vec![0.0, 0.5, 12.25, 70.0, 0.0, 0.0]);
        // A configured scale applies to both integer encodings.
        let (img, back) = round_trip(DepthEncoding::Mono16, Some(0.01));
        assert_eq!(u16::from_le_bytes([img.data[4], img.data[5]]), 1225);
        assert_eq!(back[2], 12.25);
    }

    #[test]
    fn big_endian_images_and_other_encodings() {
        let mut img =
            depth_to_ros("s", &panorama(), DepthEncoding::Float32Metres, None, Time::ZERO, &TimeBase::SIMULATED);
        for px in img.data.chunks_exact_mut(4) {
            px.reverse();
        }
        img.is_bigendian = 1;
        assert_eq!(depth_from_ros(&img, 1.0, None).unwrap().range_m[2], 12.25);
        img.encoding = "rgb8".into();
        let e = depth_from_ros(&img, 1.0, None).unwrap_err();
        assert!(e.to_string().contains("expected encoding 32FC1, 16UC1 or mono16, found `rgb8`"), "{e}");
        img.encoding = "32FC1".into();
        img.data.truncate(10);
        assert!(matches!(depth_from_ros(&img, 1.0, None), Err(ConvertError::Size { .. })));
    }
}
