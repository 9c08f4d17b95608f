//! What a replay needs: every call an adapter made on one robot's seam (`spomp_robot::Robot`),
//! in order, losslessly, and the run's setup in the log's metadata.
//!
//! Per robot `R`, one channel `/R/seam` (schema `spomp_msgs/msg/SeamCall`): each message is one
//! call — `odometry`, `panorama`, `external_pose`, `camera_tiles`, `team_in` (bytes from a peer,
//! as received), `team_out` (a sync request to a peer: tiers, budget, and the bytes the robot
//! returned), `tick` (`maintain` + `tick`, with the command or flight command it produced) or
//! `halt`. The argument travels as little-endian CDR of the spomp-core type in the `data`
//! field (floats bit for bit, the panorama at full resolution). Calls are written in the order
//! they were made: a reader replays them in file order.
//!
//! The run's setup is an MCAP metadata record named [`RUN_METADATA`] (spomp version, run seed,
//! each robot's seed, the mission's text and its includes, the map publishing settings) and an
//! attachment named [`AREA_ATTACHMENT`] (the operating area: class table, map grid, prior map).

use std::collections::BTreeMap;
use std::io::{Seek, Write};
use std::sync::Arc;

use byteorder::LittleEndian;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use spomp_core::{AerialMap, ClassTable, GridSpec, RobotId, Time};
use spomp_robot::SeamCall;
use spomp_ros_msgs::RosMessage;
use spomp_teamstate::TierSet;

use crate::read::ReadError;
use crate::record::{RecordError, Recorder};

/// Name of the metadata record holding the run's setup.
pub const RUN_METADATA: &str = "spomp.run";
/// Name of the attachment holding the operating area.
pub const AREA_ATTACHMENT: &str = "spomp/operating_area.cdr";
/// Media type of CDR-encoded spomp attachments.
const CDR_MEDIA_TYPE: &str = "application/x-spomp-cdr";

/// One message on `/R/seam` as it is on the wire.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SeamCallMsg {
    /// Time of the call, nanoseconds.
    pub stamp_ns: i64,
    /// Which call (`SeamCall::name`: `odometry`, `panorama`, `team_in`, …).
    pub call: String,
    /// The peer of a team message (`team_in`: the sender, `team_out`: the receiver), else empty.
    pub peer: String,
    /// The call's argument: little-endian CDR of its spomp-core type, without encapsulation.
    #[serde(with = "bytes")]
    pub data: Vec<u8>,
}

impl RosMessage for SeamCallMsg {
    const TYPE_NAME: &'static str = "spomp_msgs/msg/SeamCall";
    const DEFINITION: &'static str = "int64 stamp_ns\nstring call\nstring peer\nuint8[] data\n";
}

/// Byte sequences as one CDR `uint8[]` (length + bytes), not byte by byte.
mod bytes {
    use serde::{Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &[u8], s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(v)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<u8>, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = Vec<u8>;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("bytes")
            }
            fn visit_bytes<E: serde::de::Error>(self, v: &[u8]) -> Result<Vec<u8>, E> {
                Ok(v.to_vec())
            }
            fn visit_byte_buf<E: serde::de::Error>(self, v: Vec<u8>) -> Result<Vec<u8>, E> {
                Ok(v)
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<u8>, A::Error> {
                let mut out = Vec::new();
                while let Some(b) = seq.next_element()? {
                    out.push(b);
                }
                Ok(out)
            }
        }
        d.deserialize_byte_buf(V)
    }
}

/// A `team_out` call's request and answer as the log stores it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TeamOut {
    /// The tiers the link allowed, as bits (`TierSet::bits`: bit k = tier k).
    pub tiers: u8,
    /// The byte budget.
    pub budget_bytes: u64,
    /// The bytes the robot returned; `None`: nothing to send.
    pub sent: Option<Vec<u8>>,
}

/// The wire message of a call on a robot's seam at `now` (the robot layer's
/// [`SeamCall`], answers included).
pub fn call_to_msg(call: &SeamCall, now: Time) -> Result<SeamCallMsg, RecordError> {
    let (peer, data) = match call {
        SeamCall::Odometry(o) => (String::new(), cdr(o)?),
        SeamCall::Panorama(p) => (String::new(), cdr(&**p)?),
        SeamCall::ExternalPose(e) => (String::new(), cdr(e)?),
        SeamCall::CameraTiles(t) => (String::new(), cdr(t)?),
        SeamCall::TeamIn { from, bytes } => (from.to_string(), bytes.clone()),
        SeamCall::TeamOut { to, tiers, budget_bytes, sent } => {
            let out = TeamOut { tiers: tiers.bits(), budget_bytes: *budget_bytes as u64, sent: sent.clone() };
            (to.to_string(), cdr(&out)?)
        }
        SeamCall::Tick(out) => (String::new(), cdr(out)?),
        SeamCall::Halt => (String::new(), Vec::new()),
        SeamCall::TakeWork(ids) => (String::new(), cdr(ids)?),
        SeamCall::FinishWork(id) => (String::new(), cdr(id)?),
        SeamCall::Resume(bytes) => (String::new(), bytes.clone()),
    };
    Ok(SeamCallMsg { stamp_ns: now.nanos, call: call.name().to_string(), peer, data })
}

/// Decodes a wire message of `topic` into the call it records.
pub fn call_from_msg(topic: &str, msg: &SeamCallMsg) -> Result<SeamCall, ReadError> {
    let bad = |message: String| ReadError::Decode { topic: topic.to_string(), message };
    let data = &msg.data[..];
    let decode = |what: &str| bad(format!("`{}` call: {what} does not decode", msg.call));
    Ok(match msg.call.as_str() {
        "odometry" => SeamCall::Odometry(uncdr(data).ok_or_else(|| decode("odometry"))?),
        "panorama" => SeamCall::Panorama(Arc::new(uncdr(data).ok_or_else(|| decode("panorama"))?)),
        "external_pose" => SeamCall::ExternalPose(uncdr(data).ok_or_else(|| decode("pose"))?),
        "camera_tiles" => SeamCall::CameraTiles(uncdr(data).ok_or_else(|| decode("tiles"))?),
        "team_in" => SeamCall::TeamIn { from: RobotId::new(&msg.peer), bytes: msg.data.clone() },
        "team_out" => {
            let out: TeamOut = uncdr(data).ok_or_else(|| decode("request"))?;
            SeamCall::TeamOut {
                to: RobotId::new(&msg.peer),
                tiers: TierSet::from_bits(out.tiers),
                budget_bytes: usize::try_from(out.budget_bytes).unwrap_or(usize::MAX),
                sent: out.sent,
            }
        }
        "tick" => SeamCall::Tick(uncdr(data).ok_or_else(|| decode("tick output"))?),
        "halt" => SeamCall::Halt,
        "take_work" => SeamCall::TakeWork(uncdr(data).ok_or_else(|| decode("work numbers"))?),
        "finish_work" => SeamCall::FinishWork(uncdr(data).ok_or_else(|| decode("work number"))?),
        "resume" => SeamCall::Resume(msg.data.clone()),
        other => return Err(bad(format!("unknown seam call `{other}`"))),
    })
}

fn cdr<T: Serialize>(v: &T) -> Result<Vec<u8>, RecordError> {
    cdr_encoding::to_vec::<T, LittleEndian>(v)
        .map_err(|e| RecordError::Encode { type_name: std::any::type_name::<T>(), message: e.to_string() })
}

fn uncdr<T: DeserializeOwned>(data: &[u8]) -> Option<T> {
    cdr_encoding::from_bytes::<T, LittleEndian>(data).ok().map(|(v, _)| v)
}

/// Where the robots operate, as the log stores it (the robot layer's `OperatingArea`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AreaRecord {
    /// The class table.
    pub classes: ClassTable,
    /// The team map's grid.
    pub grid: GridSpec,
    /// The map the robots start with, if any (shared with the robots replayed over it).
    pub prior_map: Option<Arc<AerialMap>>,
    /// Where the map frame's origin lies on the Earth, when the area is georeferenced (kept in
    /// the run metadata as `map_origin`, so logs written before it read as before).
    #[serde(skip)]
    pub map_origin: Option<spomp_core::GeoPoint>,
}

/// The run's setup, as a replay needs it to build a fresh robot.
#[derive(Clone, Debug, PartialEq)]
pub struct RunInfo {
    /// `spomp --version` of the recording.
    pub spomp_version: String,
    /// What recorded it (`sim`, `run`).
    pub source: String,
    /// The run's seed.
    pub run_seed: u64,
    /// Each robot's seed (of its random stream), by id.
    pub robot_seeds: BTreeMap<String, u64>,
    /// The mission file and its includes: (path relative to the mission's folder, with leading
    /// `..` when outside it; text). The mission comes first. Replay refuses any other shape.
    pub files: Vec<(String, String)>,
    /// How often the mapping robot publishes its map, seconds.
    pub map_publish_period_s: f64,
    /// PNG effort of the published map (`fast`, `default`, `best`).
    pub map_compression: String,
    /// The operating area.
    pub area: AreaRecord,
    /// The robots ran their heavy skills in the background (`spomp run`): their seam calls
    /// include `take_work` and `finish_work`, and a replay sets its robot up the same way.
    pub background_skills: bool,
    /// The session the recorded robot's team-state messages carried (`spomp run` starts a new
    /// one each boot; 0 in the simulator): a replay sets it so its messages are the same bytes.
    pub team_session: u64,
    /// The recorded robot signed its team state with the team's keys (`spomp run --keys`).
    pub team_secured: bool,
}

impl RunInfo {
    fn to_metadata(&self) -> BTreeMap<String, String> {
        let mut m = BTreeMap::new();
        m.insert("spomp_version".into(), self.spomp_version.clone());
        m.insert("source".into(), self.source.clone());
        m.insert("seed".into(), self.run_seed.to_string());
        m.insert("map_publish_period_s".into(), self.map_publish_period_s.to_string());
        m.insert("map_compression".into(), self.map_compression.clone());
        m.insert("files".into(), self.files.len().to_string());
        m.insert("background_skills".into(), self.background_skills.to_string());
        m.insert("team_session".into(), self.team_session.to_string());
        m.insert("team_secured".into(), self.team_secured.to_string());
        if let Some(o) = self.area.map_origin {
            m.insert("map_origin".into(), format!("{},{}", o.latitude_deg, o.longitude_deg));
        }
        for (k, (path, text)) in self.files.iter().enumerate() {
            m.insert(format!("file.{k}.path"), path.clone());
            m.insert(format!("file.{k}.text"), text.clone());
        }
        for (id, seed) in &self.robot_seeds {
            m.insert(format!("robot_seed.{id}"), seed.to_string());
        }
        m
    }

    fn from_metadata(m: &BTreeMap<String, String>, mut area: AreaRecord) -> Result<RunInfo, ReadError> {
        if let Some(v) = m.get("map_origin") {
            let corrupt = || ReadError::Corrupt(format!("run metadata `map_origin` is not LAT,LON: `{v}`"));
            let (lat, lon) = v.split_once(',').ok_or_else(corrupt)?;
            let (lat, lon) = (lat.parse().map_err(|_| corrupt())?, lon.parse().map_err(|_| corrupt())?);
            area.map_origin = Some(spomp_core::GeoPoint::new(lat, lon));
        }
        let get = |k: &str| m.get(k).ok_or_else(|| ReadError::Corrupt(format!("run metadata lacks `{k}`")));
        let num = |k: &str| -> Result<u64, ReadError> {
            get(k)?.parse().map_err(|_| ReadError::Corrupt(format!("run metadata `{k}` is not a number")))
        };
        let n = num("files")? as usize;
        let mut files = Vec::with_capacity(n.min(1024));
        for k in 0..n {
            files.push((get(&format!("file.{k}.path"))?.clone(), get(&format!("file.{k}.text"))?.clone()));
        }
        let mut robot_seeds = BTreeMap::new();
        for (k, v) in m {
            if let Some(id) = k.strip_prefix("robot_seed.") {
                let seed = v.parse().map_err(|_| ReadError::Corrupt(format!("run metadata `{k}` is not a number")))?;
                robot_seeds.insert(id.to_string(), seed);
            }
        }
        Ok(RunInfo {
            spomp_version: get("spomp_version")?.clone(),
            source: get("source")?.clone(),
            run_seed: num("seed")?,
            robot_seeds,
            files,
            map_publish_period_s: get("map_publish_period_s")?
                .parse()
                .map_err(|_| ReadError::Corrupt("run metadata `map_publish_period_s` is not a number".into()))?,
            map_compression: get("map_compression")?.clone(),
            area,
            // Logs from before background skills existed ran every skill inline.
            background_skills: m.get("background_skills").is_some_and(|v| v == "true"),
            team_secured: m.get("team_secured").is_some_and(|v| v == "true"),
            // Logs from before sessions had none.
            team_session: match m.get("team_session") {
                None => 0,
                Some(v) => {
                    v.parse().map_err(|_| ReadError::Corrupt("run metadata `team_session` is not a number".into()))?
                }
            },
        })
    }
}

impl<W: Write + Seek> Recorder<W> {
    /// Writes the run's setup (metadata and the operating area), and closes the chunk so that
    /// it is on disk before the first message.
    pub fn run_info(&mut self, info: &RunInfo) -> Result<(), RecordError> {
        self.end_chunk()?;
        let area = cdr(&info.area)?;
        self.write_metadata(RUN_METADATA, info.to_metadata())?;
        self.write_attachment(AREA_ATTACHMENT, CDR_MEDIA_TYPE, area)?;
        self.end_chunk()
    }

    /// One call on robot `robot`'s seam at `now`, with its answers (`/R/seam`).
    pub fn seam(&mut self, robot: &str, now: Time, call: &SeamCall) -> Result<(), RecordError> {
        let msg = call_to_msg(call, now)?;
        self.log(&format!("/{robot}/seam"), now, &msg)
    }
}

/// What a log holds for replay, all of it in memory (tests and tools; [`open_replay_log`]
/// streams instead).
#[derive(Clone, Debug)]
pub struct ReplayLog {
    /// The run's setup; `None` when the log has none (recorded without it).
    pub info: Option<RunInfo>,
    /// Every message of the readable part, in file order.
    pub messages: Vec<crate::LogMessage>,
    /// The file was not closed properly (a crash or a cut): only its readable part is here.
    pub truncated: bool,
    /// Log time of the last readable message, nanoseconds.
    pub end_ns: u64,
}

/// Reads a whole log for replay: metadata, attachments and messages of its readable part (a
/// truncated log reads up to its last whole chunk).
pub fn read_replay_log(bytes: &[u8]) -> Result<ReplayLog, ReadError> {
    let log = open_replay_log(bytes)?;
    let mut messages = Vec::new();
    log.stream(&|_| true, &mut |m| {
        messages.push(m);
        true
    })?;
    Ok(ReplayLog { info: log.info, messages, truncated: log.truncated, end_ns: log.end_ns })
}

/// A log opened for replay: its setup read, its messages streamed on demand.
pub struct OpenLog {
    /// The readable part of the file, closed so that a linear reader reads it to the end.
    prefix: Vec<u8>,
    /// The run's setup; `None` when the log has none (recorded without it).
    pub info: Option<RunInfo>,
    /// The file was not closed properly (a crash or a cut): only its readable part is read.
    pub truncated: bool,
    /// Log time of the last readable message, nanoseconds.
    pub end_ns: u64,
}

/// Opens a log for replay: reads the run's setup and where the readable data ends, without
/// decompressing a chunk.
pub fn open_replay_log(bytes: &[u8]) -> Result<OpenLog, ReadError> {
    let check = crate::read::check_log(bytes)?;
    let prefix = crate::read::readable_prefix(bytes, check.readable_bytes as usize);
    let mut metadata = None;
    let mut area = None;
    let mut end_ns = 0;
    for rec in mcap::read::LinearReader::new(&prefix)? {
        use mcap::records::Record;
        match rec? {
            Record::Metadata(m) if m.name == RUN_METADATA => metadata = Some(m.metadata),
            Record::Attachment { header, data, .. } if header.name == AREA_ATTACHMENT => {
                area =
                    Some(uncdr::<AreaRecord>(&data).ok_or_else(|| {
                        ReadError::Corrupt(format!("attachment `{AREA_ATTACHMENT}` does not decode"))
                    })?);
            }
            Record::Chunk { header, .. } => end_ns = end_ns.max(header.message_end_time),
            Record::Message { header, .. } => end_ns = end_ns.max(header.log_time),
            _ => {}
        }
    }
    let info = match (metadata, area) {
        (Some(m), Some(a)) => Some(RunInfo::from_metadata(&m, a)?),
        _ => None,
    };
    Ok(OpenLog { prefix, info, truncated: !check.closed, end_ns })
}

impl OpenLog {
    /// Calls `f` with every message whose topic `keep` accepts, in file order, until `f`
    /// returns false.
    pub fn stream(
        &self,
        keep: &dyn Fn(&str) -> bool,
        f: &mut dyn FnMut(crate::LogMessage) -> bool,
    ) -> Result<(), ReadError> {
        use mcap::records::Record;
        let mut schemas: BTreeMap<u16, (String, String)> = BTreeMap::new();
        let mut channels: BTreeMap<u16, (String, String, String, String)> = BTreeMap::new();
        for rec in mcap::read::ChunkFlattener::new(&self.prefix)? {
            match rec? {
                Record::Schema { header, .. } => {
                    schemas.insert(header.id, (header.name, header.encoding));
                }
                Record::Channel(c) => {
                    let (name, enc) = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                    channels.insert(c.id, (c.topic, name, enc, c.message_encoding));
                }
                Record::Message { header, data } => {
                    let Some((topic, schema, schema_encoding, encoding)) = channels.get(&header.channel_id) else {
                        continue;
                    };
                    if !keep(topic) {
                        continue;
                    }
                    let m = crate::LogMessage {
                        topic: topic.clone(),
                        schema: schema.clone(),
                        schema_encoding: schema_encoding.clone(),
                        encoding: encoding.clone(),
                        log_time: header.log_time,
                        data: data.into_owned(),
                    };
                    if !f(m) {
                        break;
                    }
                }
                _ => {}
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::sync::Arc;

    use spomp_core::{
        DepthPanorama, Odometry, PanoramaFrame, PanoramaGeometry, Point2, Pose2, SemanticPanorama, Twist2,
    };
    use spomp_robot::TickOutput;
    use spomp_teamstate::{Tier, TierSet};

    use super::*;
    use crate::RecorderOptions;

    fn info() -> RunInfo {
        RunInfo {
            spomp_version: "0.1.0".into(),
            source: "sim".into(),
            run_seed: u64::MAX,
            robot_seeds: [("ugv1".to_string(), 0x9E37_79B9_7F4A_7C16)].into_iter().collect(),
            files: vec![("m.yaml".into(), "mission: m\n".into()), ("sub/x.yaml".into(), "é ✓ = text\n".into())],
            map_publish_period_s: 0.1 + 0.2,
            map_compression: "fast".into(),
            area: AreaRecord {
                classes: ClassTable::default_table(),
                grid: GridSpec::new(Point2::new(-0.1, 1e-300), 0.5, 3, 2),
                prior_map: None,
                map_origin: Some(spomp_core::GeoPoint::new(39.952_7, -75.165_1)),
            },
            background_skills: true,
            team_session: u64::MAX - 3,
            team_secured: true,
        }
    }

    fn record(calls: &[(Time, SeamCall)]) -> Vec<u8> {
        let mut buf = std::io::Cursor::new(Vec::new());
        let mut rec = Recorder::new(&mut buf, RecorderOptions::default()).unwrap();
        rec.run_info(&info()).unwrap();
        for (t, c) in calls {
            rec.seam("ugv1", *t, c).unwrap();
        }
        rec.finish().unwrap();
        buf.into_inner()
    }

    #[test]
    fn seam_calls_and_run_info_read_back_bit_for_bit() {
        let g = PanoramaGeometry { rows: 2, cols: 3, v_fov_rad: 1.0 };
        let frame = PanoramaFrame {
            seq: 7,
            stamp: Time::from_nanos(1_000_000_001),
            odom_pose: Pose2::new(1.0 / 3.0, -0.0, f64::MIN_POSITIVE),
            sensor_height_m: 0.4,
            depth: Arc::new(DepthPanorama {
                geometry: g,
                range_m: vec![f32::NAN, 0.1, f32::INFINITY, -0.0, 1e-45, 3.0],
            }),
            semantic: Arc::new(SemanticPanorama { geometry: g, class: vec![0, 1, 2, 3, 4, 255] }),
        };
        let odom = Odometry { stamp: Time::from_nanos(5), pose: Pose2::new(0.1, 0.2, 0.3), twist: Twist2::default() };
        let peer = RobotId::new("uav1");
        let tick = TickOutput { command: Some(Twist2 { v: 1.5, omega: -1e-17 }), flight: None };
        let tiers = TierSet::only(Tier::Coordination).with(Tier::Maps);
        let frame = Arc::new(frame);
        let calls = [
            (Time::from_nanos(5), SeamCall::Odometry(odom)),
            (Time::from_nanos(6), SeamCall::Panorama(Arc::clone(&frame))),
            (Time::from_nanos(7), SeamCall::TeamIn { from: peer.clone(), bytes: vec![1, 2, 3] }),
            (Time::from_nanos(7), SeamCall::TeamOut { to: peer.clone(), tiers, budget_bytes: 9, sent: None }),
            (Time::from_nanos(8), SeamCall::Tick(tick)),
            (Time::from_nanos(9), SeamCall::Halt),
            (Time::from_nanos(9), SeamCall::TakeWork(vec![7, 8])),
            (Time::from_nanos(10), SeamCall::FinishWork(8)),
            (Time::from_nanos(10), SeamCall::Resume(vec![1, 2, 3])),
        ];
        let log = read_replay_log(&record(&calls)).unwrap();
        assert!(!log.truncated);
        assert_eq!(log.info, Some(info()));
        let read: Vec<SeamCall> = log
            .messages
            .iter()
            .map(|m| call_from_msg(&m.topic, &crate::decode_cdr(&m.topic, &m.data).unwrap()).unwrap())
            .collect();
        assert_eq!(read.len(), calls.len());
        assert_eq!(read[0], SeamCall::Odometry(odom));
        let SeamCall::Panorama(p) = &read[1] else { panic!("{:?}", read[1]) };
        let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&p.depth.range_m), bits(&frame.depth.range_m), "ranges bit for bit, NaN included");
        assert_eq!(
            (p.odom_pose.y.to_bits(), p.semantic.class.clone()),
            ((-0.0f64).to_bits(), frame.semantic.class.to_vec())
        );
        assert_eq!(read[2], SeamCall::TeamIn { from: peer.clone(), bytes: vec![1, 2, 3] });
        assert_eq!(read[3], SeamCall::TeamOut { to: peer, tiers, budget_bytes: 9, sent: None });
        assert_eq!(tiers.bits(), 0b101, "bit k = tier k on the wire");
        assert_eq!(read[4], SeamCall::Tick(tick));
        assert_eq!(read[5], SeamCall::Halt);
        assert_eq!(read[6], SeamCall::TakeWork(vec![7, 8]));
        assert_eq!(read[7], SeamCall::FinishWork(8));
        assert_eq!(read[8], SeamCall::Resume(vec![1, 2, 3]));
    }

    #[test]
    fn an_unclosed_log_reads_as_truncated_and_unknown_calls_are_errors() {
        let odom = Odometry::default();
        let bytes = record(&[(Time::from_nanos(2_000_000_000), SeamCall::Odometry(odom))]);
        // Without its footer and magic: not closed, the data whole.
        let log = read_replay_log(&bytes[..bytes.len() - 20]).unwrap();
        assert!(log.truncated);
        assert_eq!(log.end_ns, 2_000_000_000);
        assert!(log.info.is_some());
        let bad = SeamCallMsg { stamp_ns: 0, call: "teleport".into(), peer: String::new(), data: vec![] };
        assert!(call_from_msg("/x/seam", &bad).is_err());
        let short = SeamCallMsg { stamp_ns: 0, call: "odometry".into(), peer: String::new(), data: vec![1, 2] };
        assert!(call_from_msg("/x/seam", &short).is_err());
    }
}
