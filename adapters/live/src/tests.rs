#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::net::SocketAddr;
use std::time::Duration;

use super::*;
use crate::viewer::Viewer;

const WAIT: Duration = Duration::from_secs(20);

const STRING_DEFINITION: &str = "string data\n";

/// `std_msgs/String` as ROS 2 puts it on the wire: encapsulation header, length with the NUL,
/// bytes, NUL.
fn cdr_string(text: &str) -> Vec<u8> {
    let mut out = vec![0x00, 0x01, 0x00, 0x00];
    out.extend_from_slice(&(text.len() as u32 + 1).to_le_bytes());
    out.extend_from_slice(text.as_bytes());
    out.push(0);
    out
}

fn loopback_any_port() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 0))
}

#[test]
fn a_viewer_sees_advertised_ros2_channels_their_messages_and_the_run_time() {
    let mut server = LiveServer::start(loopback_any_port(), "spomp test").unwrap();
    assert_ne!(server.local_addr().port(), 0, "the port the system chose");
    assert_eq!(server.url(), format!("ws://127.0.0.1:{}", server.local_addr().port()));
    server.publish("/early", "std_msgs/msg/String", STRING_DEFINITION, 5, &cdr_string("before"), false).unwrap();
    let mut viewer = Viewer::connect(server.local_addr(), WAIT).unwrap();
    assert_eq!(viewer.server_info["name"], "spomp test");
    let capabilities = viewer.server_info["capabilities"].as_array().unwrap();
    assert!(capabilities.iter().any(|c| c == "time"), "{:?}", viewer.server_info);
    viewer.wait_for_channels(&["/early"], WAIT).unwrap();
    let channel = &viewer.channels["/early"];
    assert_eq!(
        (channel.encoding.as_str(), channel.schema_name.as_str(), channel.schema_encoding.as_str()),
        ("cdr", "std_msgs/msg/String", "ros2msg")
    );
    assert_eq!(channel.schema, STRING_DEFINITION);
    viewer.subscribe(&["/early"]).unwrap();
    // Not latched: what was published before the subscription is not sent again. Wait until
    // the server has the subscription (its count of viewers is not enough), by publishing until
    // one arrives.
    let mut received = None;
    for k in 0..200u64 {
        server
            .publish("/early", "std_msgs/msg/String", STRING_DEFINITION, 1_000 + k, &cdr_string("after"), false)
            .unwrap();
        match viewer.next_message(Duration::from_millis(100)) {
            Ok(m) => {
                received = Some(m);
                break;
            }
            Err(crate::viewer::ViewerError::Timeout(_)) => continue,
            Err(e) => panic!("{e}"),
        }
    }
    let m = received.expect("a message after subscribing");
    assert_eq!(m.topic, "/early");
    assert!(m.log_time_ns >= 1_000, "only messages after the subscription: {}", m.log_time_ns);
    assert_eq!(m.data, cdr_string("after"));
    assert_eq!(server.client_count(), 1);
    // A channel that appears while the viewer is connected is advertised to it.
    server.publish("/late", "std_msgs/msg/String", STRING_DEFINITION, 2_000_000_000, &cdr_string("x"), false).unwrap();
    viewer.wait_for_channels(&["/late"], WAIT).unwrap();
    assert_eq!(viewer.wait_for_time(2_000_000_000, WAIT).unwrap(), 2_000_000_000, "the run's time is broadcast");
    assert!(viewer.bytes_received > 0);
    server.stop();
}

#[test]
fn a_late_subscriber_gets_the_latest_message_of_a_latched_channel_at_once() {
    let mut server = LiveServer::start(loopback_any_port(), "spomp").unwrap();
    for (t, text) in [(10, "map v1"), (20, "map v2")] {
        server.publish("/map", "std_msgs/msg/String", STRING_DEFINITION, t, &cdr_string(text), true).unwrap();
    }
    let mut viewer = Viewer::connect(server.local_addr(), WAIT).unwrap();
    viewer.wait_for_channels(&["/map"], WAIT).unwrap();
    viewer.subscribe(&["/map"]).unwrap();
    let m = viewer.next_message(WAIT).unwrap();
    assert_eq!((m.topic.as_str(), m.log_time_ns, m.data), ("/map", 20, cdr_string("map v2")));
    server.stop();
}

#[test]
fn an_address_in_use_is_an_error_naming_it() {
    let first = LiveServer::start(loopback_any_port(), "spomp").unwrap();
    let Err(e) = LiveServer::start(first.local_addr(), "spomp") else { panic!("a second server on the same port") };
    assert!(e.to_string().contains(&first.local_addr().to_string()), "{e}");
}

/// A viewer offering only `name` connects, is answered with `name`, and gets the server's
/// channels and messages.
fn a_viewer_offering_only(name: &str) {
    let mut server = LiveServer::start(loopback_any_port(), "spomp").unwrap();
    server.publish("/map", "std_msgs/msg/String", STRING_DEFINITION, 7, &cdr_string("map"), true).unwrap();
    let mut viewer = Viewer::connect_offering(server.local_addr(), &[name], WAIT).unwrap();
    assert_eq!(viewer.server_info["name"], "spomp");
    viewer.wait_for_channels(&["/map"], WAIT).unwrap();
    viewer.subscribe(&["/map"]).unwrap();
    let m = viewer.next_message(WAIT).unwrap();
    assert_eq!((m.topic.as_str(), m.data), ("/map", cdr_string("map")));
    server.stop();
}

#[test]
fn a_viewer_offering_only_the_current_name_connects() {
    a_viewer_offering_only(SUBPROTOCOL);
}

#[test]
fn a_viewer_offering_only_the_original_name_connects() {
    a_viewer_offering_only(LEGACY_SUBPROTOCOL);
}

/// Foxglove's 3-D panel "Publish point": a client channel of `geometry_msgs/PointStamped`, in
/// json (what Foxglove writes when the server lists json first) or cdr; each point goes to the
/// handler, and its answer back to the viewer. Other types are refused with a status.
#[test]
fn points_a_viewer_publishes_reach_the_handler_and_its_answer_reaches_the_viewer() {
    use std::sync::Mutex;
    let got: Arc<Mutex<Vec<PublishedPoint>>> = Arc::default();
    let handler: PointHandler = {
        let got = got.clone();
        Arc::new(move |p: &PublishedPoint| {
            if p.frame_id != "map" {
                return Err(format!("frame `{}`, not map", p.frame_id));
            }
            got.lock().unwrap().push(p.clone());
            Ok(format!("goal requested at ({}, {})", p.x, p.y))
        })
    };
    let options = LiveOptions { points: Some(handler) };
    let server = LiveServer::start_with(loopback_any_port(), "spomp", options).unwrap();
    let mut viewer = Viewer::connect(server.local_addr(), WAIT).unwrap();
    let capabilities = viewer.server_info["capabilities"].as_array().unwrap();
    assert!(capabilities.iter().any(|c| c == "clientPublish"), "{:?}", viewer.server_info);
    assert_eq!(viewer.server_info["supportedEncodings"], serde_json::json!(["json", "cdr"]));

    viewer.advertise(1, "/clicked_point", "json", "geometry_msgs/PointStamped").unwrap();
    viewer.wait_for_status("becomes an operator's goal", WAIT).unwrap();
    let json = br#"{"header":{"stamp":{"sec":1,"nsec":0},"frame_id":"map"},"point":{"x":40,"y":12.5,"z":0}}"#;
    viewer.publish(1, json).unwrap();
    viewer.wait_for_status("goal requested at (40, 12.5)", WAIT).unwrap();
    viewer.publish(1, br#"{"header":{"frame_id":"ugv1/base_link"},"point":{"x":1,"y":2,"z":0}}"#).unwrap();
    viewer.wait_for_status("refused: frame `ugv1/base_link`", WAIT).unwrap();
    viewer.publish(1, b"not json").unwrap();
    viewer.wait_for_status("refused: a json point that is not JSON", WAIT).unwrap();

    viewer.advertise(2, "/ros2_point", "cdr", "geometry_msgs/msg/PointStamped").unwrap();
    viewer.publish(2, &points::tests::cdr_point("map", 3, 0, [-7.0, 8.0, 0.0])).unwrap();
    viewer.wait_for_status("goal requested at (-7, 8)", WAIT).unwrap();

    viewer.advertise(3, "/move_base_simple/goal", "json", "geometry_msgs/PoseStamped").unwrap();
    viewer.wait_for_status("/move_base_simple/goal: schema `geometry_msgs/PoseStamped` is not taken", WAIT).unwrap();
    viewer.publish(3, b"{}").unwrap();
    viewer.wait_for_status("/move_base_simple/goal: refused", WAIT).unwrap();

    let got = got.lock().unwrap().clone();
    let summary: Vec<(&str, f64, f64)> = got.iter().map(|p| (p.topic.as_str(), p.x, p.y)).collect();
    assert_eq!(summary, [("/clicked_point", 40.0, 12.5), ("/ros2_point", -7.0, 8.0)]);
    server.stop();
}

#[test]
fn without_a_point_handler_a_viewer_may_not_publish() {
    let server = LiveServer::start(loopback_any_port(), "spomp").unwrap();
    let mut viewer = Viewer::connect(server.local_addr(), WAIT).unwrap();
    let capabilities = viewer.server_info["capabilities"].as_array().unwrap();
    assert!(!capabilities.iter().any(|c| c == "clientPublish"), "{:?}", viewer.server_info);
    viewer.advertise(1, "/clicked_point", "json", "geometry_msgs/PointStamped").unwrap();
    viewer.wait_for_status("clientPublish", WAIT).unwrap();
    server.stop();
}

/// The stdlib-only Python client (`scripts/foxglove-publish-point.py`, written from the
/// protocol's description like a third-party tool) publishes a point in each encoding: each
/// reaches the handler, and the client reads the handler's answer. Skipped where there is no
/// `python3`.
#[test]
fn the_python_client_publishes_a_point_in_json_and_in_cdr() {
    use std::process::Command;
    use std::sync::Mutex;
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/foxglove-publish-point.py");
    if Command::new("python3").arg("--version").output().is_err() {
        eprintln!("no python3: skipped");
        return;
    }
    let got: Arc<Mutex<Vec<PublishedPoint>>> = Arc::default();
    let handler: PointHandler = {
        let got = got.clone();
        Arc::new(move |p: &PublishedPoint| {
            got.lock().unwrap().push(p.clone());
            if p.frame_id == "map" { Ok(format!("goal at ({}, {})", p.x, p.y)) } else { Err("not map".into()) }
        })
    };
    let server = LiveServer::start_with(loopback_any_port(), "spomp", LiveOptions { points: Some(handler) }).unwrap();
    let run = |args: &[&str]| {
        let out = Command::new("python3").arg(&script).arg(server.url()).args(args).output().unwrap();
        (out.status.code(), String::from_utf8_lossy(&out.stdout).trim().to_string())
    };
    assert_eq!(run(&["40", "12.5"]), (Some(0), "/clicked_point: goal at (40, 12.5)".to_string()));
    assert_eq!(run(&["-3", "7", "--encoding", "cdr"]), (Some(0), "/clicked_point: goal at (-3, 7)".to_string()));
    let (code, text) = run(&["1", "2", "--frame", "ugv1/base_link"]);
    assert_eq!((code, text.as_str()), (Some(1), "/clicked_point: refused: not map"));
    let got: Vec<(String, f64, f64)> = got.lock().unwrap().iter().map(|p| (p.frame_id.clone(), p.x, p.y)).collect();
    assert_eq!(got, [("map".into(), 40.0, 12.5), ("map".into(), -3.0, 7.0), ("ugv1/base_link".into(), 1.0, 2.0)]);
    // A server that takes no points: the client says so.
    let plain = LiveServer::start(loopback_any_port(), "spomp").unwrap();
    let out = Command::new("python3").arg(&script).arg(plain.url()).args(["1", "2"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stdout));
    server.stop();
    plain.stop();
}
