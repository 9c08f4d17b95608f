//! Two ROS 2 participants on loopback only find each other and exchange the message types of
//! spomp, byte for byte.

use std::time::{Duration, Instant};

use spomp_ros_msgs as ros;
use spomp_ros2::dds::{DdsNode, DdsSettings, sensor_qos, state_qos};

fn loopback(domain_id: u16) -> DdsSettings {
    DdsSettings { domain_id, interfaces: vec![std::net::IpAddr::from([127, 0, 0, 1])] }
}

/// A domain id of this test process's own, so parallel test runs do not hear each other.
fn test_domain(offset: u16) -> u16 {
    100 + ((std::process::id() as u16).wrapping_add(offset) % 100)
}

#[test]
fn odometry_and_images_cross_between_two_participants_on_loopback() {
    let settings = loopback(test_domain(0));
    let mut a = DdsNode::new(&settings, "/", "talker").expect("participant a");
    let mut b = DdsNode::new(&settings, "/", "listener").expect("participant b");
    let odom_pub = a.publisher::<ros::Odometry>("/t/odom", &state_qos(5)).expect("publisher");
    let image_pub = a.publisher::<ros::Image>("/t/image", &state_qos(2)).expect("publisher");
    let odom_sub = b.subscription::<ros::Odometry>("/t/odom", &sensor_qos(5)).expect("subscription");
    let image_sub = b.subscription::<ros::Image>("/t/image", &sensor_qos(2)).expect("subscription");

    let mut odom = ros::Odometry::default();
    odom.header.frame_id = "ugv1/odom".into();
    odom.pose.pose.position.x = 12.5;
    odom.pose.covariance.0[35] = 0.25;
    let image = ros::Image {
        header: ros::Header::default(),
        height: 64,
        width: 256,
        encoding: "mono16".into(),
        is_bigendian: 0,
        step: 512,
        data: (0..64 * 512).map(|i| (i % 251) as u8).collect(),
    };
    let deadline = Instant::now() + Duration::from_secs(20);
    let (mut got_odom, mut got_image) = (None, None);
    while Instant::now() < deadline && (got_odom.is_none() || got_image.is_none()) {
        let _ = odom_pub.publish(odom.clone());
        let _ = image_pub.publish(image.clone());
        std::thread::sleep(Duration::from_millis(100));
        if let Ok(Some((m, _))) = odom_sub.take() {
            got_odom = Some(m);
        }
        if let Ok(Some((m, _))) = image_sub.take() {
            got_image = Some(m);
        }
    }
    assert_eq!(got_odom.as_ref(), Some(&odom), "odometry did not arrive intact within 20 s");
    assert_eq!(got_image.as_ref(), Some(&image), "the image did not arrive intact within 20 s");
}
