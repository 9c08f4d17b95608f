//! A recorded run reads back with the same content, standard schemas, and bad logs are
//! rejected without a panic.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::io::Cursor;
use std::sync::Arc;

use proptest::prelude::*;
use spomp_behaviors::Status;
use spomp_behaviors::trace::TransitionRecord;
use spomp_core::{DepthPanorama, PanoramaGeometry, Pose2, ReachabilityScan, RobotId, SemanticPanorama, Time, Twist2};
use spomp_mcap::{McapLog, Recorder, RecorderOptions, decode_cdr};
use spomp_ros_msgs::{Image, LaserScan, Log, PoseStamped};

fn sample_log() -> Vec<u8> {
    let mut buf = Cursor::new(Vec::new());
    let mut rec = Recorder::new(&mut buf, RecorderOptions::default()).unwrap();
    for i in 0..5 {
        let t = Time::from_millis(100 * i);
        rec.pose("ugv1", t, Pose2::new(i as f64, 2.0, 0.5), 0.0).unwrap();
        rec.command("ugv1", t, Twist2 { v: 1.0, omega: -0.2 }).unwrap();
    }
    let g = PanoramaGeometry { rows: 8, cols: 16, v_fov_rad: 1.0 };
    let depth = DepthPanorama { geometry: g, range_m: (0..128).map(|i| i as f32 * 0.25).collect() };
    let sem = SemanticPanorama { geometry: g, class: (0..128).map(|i| (i % 9) as u8).collect() };
    rec.panorama("ugv1", Time::from_millis(500), &depth, Some(&sem)).unwrap();
    let scan = ReachabilityScan {
        robot: RobotId::new("ugv1"),
        stamp: Time::from_millis(500),
        pose: Pose2::default(),
        range_m: vec![1.0, 2.0, 3.0, 4.0],
        obstacle: vec![true, false, false, true],
    };
    rec.reachability(&scan).unwrap();
    let tr = TransitionRecord {
        tick: 3,
        time: Time::from_millis(300),
        node_id: 2,
        path: Arc::<str>::from("visitor/sequence").to_string(),
        from: Status::Idle,
        to: Status::Running,
    };
    rec.transitions("ugv1", &[tr]).unwrap();
    rec.json("/team/state", Time::from_millis(600), &serde_json::json!({"goal": 1, "status": "claimed"})).unwrap();
    // 5 poses, 5 commands, 2 panorama images, a scan, a transition and the active path it
    // changed, a JSON document.
    assert_eq!(rec.message_count(), 16);
    rec.finish().unwrap();
    buf.into_inner()
}

#[test]
fn messages_round_trip_with_ros2_schemas() {
    let log = McapLog::from_bytes(sample_log());
    let msgs = log.messages().unwrap();
    assert_eq!(msgs.len(), 16);
    assert!(msgs.iter().all(|m| m.schema_encoding == "ros2msg" && m.encoding == "cdr"));
    let pose = msgs.iter().find(|m| m.topic == "/ugv1/pose" && m.log_time == 300_000_000).unwrap();
    assert_eq!(pose.schema, "geometry_msgs/msg/PoseStamped");
    let p: PoseStamped = decode_cdr(&pose.topic, &pose.data).unwrap();
    assert_eq!(p.pose.position.x, 3.0);
    assert_eq!(p.header.frame_id, "map");
    assert!((p.pose.orientation.z - (0.25f64).sin()).abs() < 1e-12);

    let depth = msgs.iter().find(|m| m.topic == "/ugv1/panorama/depth").unwrap();
    let img: Image = decode_cdr(&depth.topic, &depth.data).unwrap();
    // Downsampled by 4: 2 × 4 pixels of REP-118's canonical 32FC1 (metres).
    assert_eq!((img.height, img.width, img.encoding.as_str(), img.step), (2, 4, "32FC1", 16));
    let second = f32::from_le_bytes([img.data[4], img.data[5], img.data[6], img.data[7]]);
    assert_eq!(second, 1.0, "pixel (0, 4) is 1.0 m");

    let scan = msgs.iter().find(|m| m.topic == "/ugv1/reachability").unwrap();
    let s: LaserScan = decode_cdr(&scan.topic, &scan.data).unwrap();
    assert_eq!(s.ranges, vec![1.0, 2.0, 3.0, 4.0]);
    assert_eq!(s.intensities, vec![1.0, 0.0, 0.0, 1.0]);
    // REP-117: a fixed range_max above every reach, range_min the floor, so laser_geometry and
    // rviz (which keep range_min ≤ r < range_max) keep every bin — the longest one too.
    assert_eq!((s.range_min, s.range_max), (0.0, spomp_core::scan::REACHABILITY_RANGE_MAX_M));
    assert!(s.ranges.iter().all(|r| (s.range_min..s.range_max).contains(r)));
    assert_eq!(s.header.frame_id, "ugv1/base_link");
    let cmd = msgs.iter().find(|m| m.topic == "/ugv1/cmd_vel").unwrap();
    assert_eq!(cmd.schema, "geometry_msgs/msg/TwistStamped", "the default command type, as on DDS");

    let bt = msgs.iter().find(|m| m.topic == "/ugv1/bt").unwrap();
    let l: Log = decode_cdr(&bt.topic, &bt.data).unwrap();
    assert_eq!(l.name, "ugv1/visitor/sequence");
    assert!(l.msg.starts_with("idle -> running"));
    let path = msgs.iter().find(|m| m.topic == "/ugv1/active_path").unwrap();
    assert_eq!((path.schema.as_str(), path.log_time), ("std_msgs/msg/String", 300_000_000));
    let p: spomp_ros_msgs::StringMsg = decode_cdr(&path.topic, &path.data).unwrap();
    assert_eq!(p.data, "visitor/sequence");
}

#[test]
fn truncated_and_garbage_logs_are_errors() {
    let bytes = sample_log();
    for cut in [0, 8, 100, bytes.len() / 2, bytes.len() - 10] {
        let log = McapLog::from_bytes(bytes[..cut].to_vec());
        assert!(log.messages().is_err(), "cut at {cut} should not read cleanly");
    }
    assert!(decode_cdr::<PoseStamped>("/x", &[1, 2, 3]).is_err());
    assert!(decode_cdr::<PoseStamped>("/x", &[0, 1, 0, 0, 9]).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]
    #[test]
    fn corrupted_logs_never_panic(flips in prop::collection::vec((0usize..4096, any::<u8>()), 1..8)) {
        let mut bytes = sample_log();
        let n = bytes.len();
        for (i, b) in flips {
            bytes[i % n] ^= b | 1;
        }
        if let Ok(msgs) = McapLog::from_bytes(bytes).messages() {
            for m in msgs {
                let _ = decode_cdr::<PoseStamped>(&m.topic, &m.data);
                let _ = decode_cdr::<Image>(&m.topic, &m.data);
            }
        }
    }
}

/// Regression: a corrupt record length inside a chunk made the `mcap` reader try to allocate
/// petabytes and abort the process. It must be an error.
#[test]
fn huge_record_length_inside_a_chunk_is_an_error_not_an_abort() {
    let mut buf = Cursor::new(Vec::new());
    let mut rec = Recorder::new(
        &mut buf,
        RecorderOptions { panorama_downsample: 4, compress: false, ..RecorderOptions::default() },
    )
    .unwrap();
    rec.pose("ugv1", Time::ZERO, Pose2::default(), 0.0).unwrap();
    rec.finish().unwrap();
    let mut bytes = buf.into_inner();
    assert!(McapLog::from_bytes(bytes.clone()).messages().is_ok());
    let body = first_chunk(&bytes) + 9;
    let name_len = u32::from_le_bytes(bytes[body + 28..body + 32].try_into().unwrap()) as usize;
    let first_inner = body + 40 + name_len;
    bytes[first_inner + 1..first_inner + 9].copy_from_slice(&(1u64 << 57).to_le_bytes());
    // The chunk's CRC would catch the change first; without one (0: not recorded) the length
    // check must.
    let crc = McapLog::from_bytes(bytes.clone()).messages().unwrap_err();
    assert!(crc.to_string().contains("CRC mismatch"), "{crc}");
    bytes[body + 24..body + 28].copy_from_slice(&[0; 4]);
    let err = McapLog::from_bytes(bytes).messages().unwrap_err();
    assert!(err.to_string().contains("declares"), "{err}");
}

/// Regression (CI, proptest `corrupted_logs_never_panic`): two flipped bytes — one making a
/// zstd chunk's record length run past the end of the file, one inside its compressed records —
/// aborted the process. The size check stopped at the overrunning length, while the `mcap` reader
/// streams a chunk from its header and decompressed a record claiming ~2⁵⁷ bytes.
#[test]
fn a_compressed_chunk_behind_an_overrunning_length_is_still_checked() {
    let mut bytes = sample_log();
    let chunk = first_chunk(&bytes);
    let body = chunk + 9;
    let name_len = u32::from_le_bytes(bytes[body + 28..body + 32].try_into().unwrap()) as usize;
    assert_eq!(&bytes[body + 32..body + 32 + name_len], b"zstd");
    let size_at = body + 32 + name_len;
    let compressed_len = u64::from_le_bytes(bytes[size_at..size_at + 8].try_into().unwrap()) as usize;
    let records_at = size_at + 8;
    let uncompressed = u64::from_le_bytes(bytes[body + 16..body + 24].try_into().unwrap()) as usize;
    let mut plain = zstd::bulk::decompress(&bytes[records_at..records_at + compressed_len], uncompressed).unwrap();
    plain[1..9].copy_from_slice(&(1u64 << 57).to_le_bytes()); // the first inner record's length
    let recompressed = zstd::bulk::compress(&plain, 3).unwrap();

    let mut corrupt = bytes[..size_at].to_vec();
    corrupt.extend_from_slice(&(recompressed.len() as u64).to_le_bytes());
    corrupt.extend_from_slice(&recompressed);
    corrupt.extend_from_slice(&bytes.split_off(records_at + compressed_len));
    corrupt[chunk + 1..chunk + 9].copy_from_slice(&(u64::MAX / 2).to_le_bytes());
    let err = McapLog::from_bytes(corrupt).messages().unwrap_err();
    assert!(err.to_string().contains("more than the file holds"), "{err}");
}

/// An attachment whose fields fill its record with no room left for its CRC: the `mcap` reader
/// slices the data up to the CRC and panicked on it (through `open_replay_log`, and `check_log`
/// once it verified attachment CRCs). A corrupt record now, never a panic.
#[test]
fn an_attachment_without_room_for_its_crc_is_corrupt_not_a_panic() {
    let mut body = Vec::new();
    body.extend_from_slice(&0u64.to_le_bytes()); // log time
    body.extend_from_slice(&0u64.to_le_bytes()); // create time
    for text in [&b"area"[..], b"application/x"] {
        body.extend_from_slice(&(text.len() as u32).to_le_bytes());
        body.extend_from_slice(text);
    }
    body.extend_from_slice(&0u64.to_le_bytes()); // no data, and no CRC after it
    const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
    let mut bytes = MAGIC.to_vec();
    bytes.push(0x09);
    bytes.extend_from_slice(&(body.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&body);
    // A data end without CRC, a footer without summary, the magic.
    bytes.push(0x0F);
    bytes.extend_from_slice(&4u64.to_le_bytes());
    bytes.extend_from_slice(&[0; 4]);
    bytes.push(0x02);
    bytes.extend_from_slice(&20u64.to_le_bytes());
    bytes.extend_from_slice(&[0; 20]);
    bytes.extend_from_slice(MAGIC);
    let check = spomp_mcap::check_log(&bytes).unwrap();
    assert!(check.bad_record.as_ref().is_some_and(|(_, why)| why.contains("crc")), "{check:?}");
    let _ = spomp_mcap::open_replay_log(&bytes);
    let _ = spomp_mcap::recover_log(&bytes, Cursor::new(Vec::new()));
}

/// Offset of the first top-level chunk record (opcode 6) after the magic.
/// Regression (CI, `tests/it/cli_harden.rs` bit flips): a flipped bit in the length of the
/// message index after a chunk made the record run past the data section, and `log check` took
/// the closed log for one a crash cut short ("not closed", exit 0). A closed log whose records
/// stop making sense is corrupt.
#[test]
fn a_damaged_record_length_in_a_closed_log_is_corruption_not_a_cut() {
    let bytes = sample_log();
    assert!(spomp_mcap::check_log(&bytes).unwrap().intact());
    let chunk = first_chunk(&bytes);
    let chunk_len = u64::from_le_bytes(bytes[chunk + 1..chunk + 9].try_into().unwrap()) as usize;
    let index = chunk + 9 + chunk_len;
    assert_eq!(bytes[index], 0x07, "a message index follows the chunk");
    let mut damaged = bytes.clone();
    damaged[index + 2] ^= 1 << 4; // the length grows by 4096 × 256: past the end of the file
    let check = spomp_mcap::check_log(&damaged).unwrap();
    assert!(!check.intact(), "{check:?}");
    let (offset, why) = check.bad_record.clone().unwrap();
    assert_eq!(offset, index as u64);
    assert!(why.contains("damaged length"), "{why}");
    // A log that really was cut short inside that record stays a cut, not corruption.
    let cut = spomp_mcap::check_log(&bytes[..index + 20]).unwrap();
    assert!(cut.intact() && !cut.closed, "{cut:?}");
}

fn first_chunk(bytes: &[u8]) -> usize {
    let mut pos = 8;
    while bytes[pos] != 0x06 {
        let len = u64::from_le_bytes(bytes[pos + 1..pos + 9].try_into().unwrap()) as usize;
        pos += 9 + len;
    }
    pos
}

#[test]
fn obstacle_mask_keeps_single_pixels_when_downsampled() {
    let mut buf = Cursor::new(Vec::new());
    let mut rec = Recorder::new(&mut buf, RecorderOptions::default()).unwrap();
    let g = PanoramaGeometry { rows: 8, cols: 16, v_fov_rad: 1.0 };
    let mut mask = vec![false; g.len()];
    mask[5 * 16 + 13] = true; // row 5, column 13 → block (1, 3) at 4× downsampling
    rec.obstacle_panorama("ugv1", Time::from_millis(500), g, &mask).unwrap();
    rec.finish().unwrap();
    let msgs = McapLog::from_bytes(buf.into_inner()).messages().unwrap();
    let m = msgs.iter().find(|m| m.topic == "/ugv1/terrain/obstacles").unwrap();
    let img: Image = decode_cdr(&m.topic, &m.data).unwrap();
    assert_eq!((img.height, img.width, img.encoding.as_str()), (2, 4, "mono8"));
    let lit: Vec<usize> = img.data.iter().enumerate().filter(|(_, v)| **v == 255).map(|(i, _)| i).collect();
    assert_eq!(lit, vec![4 + 3]);
}

#[test]
fn problems_are_logged_under_the_robots_rcl_logger_name() {
    let mut buf = Cursor::new(Vec::new());
    let mut rec = Recorder::new(&mut buf, RecorderOptions::default()).unwrap();
    rec.problem("ugv1", Time::from_millis(100), "planner: no path").unwrap();
    let mut husky = spomp_mcap::RobotConventions::defaults("ugv2");
    husky.logger = spomp_ros_msgs::rcl_logger_name("/fleet/husky", spomp_ros_msgs::ROBOT_NODE_NAME);
    rec.set_conventions("ugv2", husky);
    rec.problem("ugv2", Time::from_millis(200), "e-stop").unwrap();
    rec.finish().unwrap();
    let msgs = McapLog::from_bytes(buf.into_inner()).messages().unwrap();
    let names: Vec<(String, String)> =
        msgs.iter().map(|m| (m.topic.clone(), decode_cdr::<Log>(&m.topic, &m.data).unwrap().name)).collect();
    // As rcl names a node's logger (and as the robot's DDS /rosout entries are named): dots.
    assert_eq!(
        names,
        vec![
            ("/ugv1/rosout".to_string(), "ugv1.spomp".to_string()),
            ("/ugv2/rosout".to_string(), "fleet.husky.spomp".to_string())
        ]
    );
}
