//! Points a viewer publishes: the protocol's client-publish channel, opt-in
//! ([`crate::LiveOptions::points`]).
//!
//! Foxglove's 3-D panel "Publish point" tool advertises a client channel (default topic
//! `/clicked_point`, schema `geometry_msgs/PointStamped`) in the first message encoding of the
//! server's `supportedEncodings` it can write, then sends one message per click. The server
//! lists `json` first, which Foxglove writes whatever its data-source profile, then `cdr` (a
//! ROS 2 client's choice). Each point is decoded here and handed to the handler the server was
//! started with; what the handler answers goes back to that viewer as a status message (shown
//! in Foxglove's problems list). Channels of any other type are refused with a status naming
//! what is taken.

use std::sync::Arc;

use serde_json::Value;

/// Schema names of the one message type taken (ROS 1 style, as Foxglove's 3-D panel names it,
/// and the ROS 2 full name).
pub const POINT_SCHEMAS: [&str; 2] = ["geometry_msgs/PointStamped", "geometry_msgs/msg/PointStamped"];

/// The message encodings a client may publish in, in the order the server offers them.
pub const POINT_ENCODINGS: [&str; 2] = ["json", "cdr"];

/// The longest point message taken, bytes (a `PointStamped` is tens of bytes; the frame id is
/// the only part of any length).
pub const MAX_POINT_BYTES: usize = 4096;

/// A point a viewer published.
#[derive(Debug, Clone, PartialEq)]
pub struct PublishedPoint {
    /// The client channel's topic (`/clicked_point` from Foxglove's 3-D panel).
    pub topic: String,
    /// `header.frame_id`: the frame the point is in (the 3-D panel's display frame).
    pub frame_id: String,
    /// `header.stamp`, nanoseconds (the viewer's clock: wall time for Foxglove).
    pub stamp_ns: i64,
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
    /// z, metres.
    pub z: f64,
}

/// What the server does with each published point: the answer (`Ok` for what was done, `Err`
/// for why it was refused) is sent back to the viewer as an info or error status. Called on
/// the server's threads: hand the point on, never block for long.
pub type PointHandler = Arc<dyn Fn(&PublishedPoint) -> Result<String, String> + Send + Sync>;

/// Whether a client channel of `schema_name` in `encoding` carries points taken here; if not,
/// why (for the viewer).
pub fn accepts(schema_name: &str, encoding: &str) -> Result<(), String> {
    if !POINT_SCHEMAS.contains(&schema_name) {
        return Err(format!(
            "schema `{schema_name}` is not taken: this server takes only geometry_msgs/PointStamped (Publish point)"
        ));
    }
    if !POINT_ENCODINGS.contains(&encoding) {
        return Err(format!("encoding `{encoding}` is not taken: publish points as json or cdr"));
    }
    Ok(())
}

/// Decodes a point message of `encoding` (`json` or `cdr`) published on `topic`; non-finite
/// coordinates are refused.
pub fn decode(topic: &str, encoding: &str, payload: &[u8]) -> Result<PublishedPoint, String> {
    if payload.len() > MAX_POINT_BYTES {
        return Err(format!("a point message of {} bytes; at most {MAX_POINT_BYTES} are taken", payload.len()));
    }
    let point = match encoding {
        "json" => decode_json(topic, payload)?,
        "cdr" => decode_cdr(topic, payload)?,
        other => return Err(format!("encoding `{other}` is not taken: publish points as json or cdr")),
    };
    if ![point.x, point.y, point.z].iter().all(|v| v.is_finite()) {
        return Err(format!("point ({}, {}, {}) is not finite", point.x, point.y, point.z));
    }
    Ok(point)
}

/// `{"header": {"stamp": {"sec", "nsec" | "nanosec"}, "frame_id"}, "point": {"x", "y", "z"}}`
/// (Foxglove writes `nsec`, ROS 2 JSON tools `nanosec`; a missing header or stamp is zero).
fn decode_json(topic: &str, payload: &[u8]) -> Result<PublishedPoint, String> {
    let value: Value = serde_json::from_slice(payload).map_err(|e| format!("a json point that is not JSON: {e}"))?;
    let point = value.get("point").ok_or("a json point without `point`")?;
    let coordinate = |name: &str| {
        point.get(name).and_then(Value::as_f64).ok_or_else(|| format!("`point.{name}` is missing or not a number"))
    };
    let header = value.get("header");
    let frame_id = header.and_then(|h| h.get("frame_id")).and_then(Value::as_str).unwrap_or_default();
    let stamp = header.and_then(|h| h.get("stamp"));
    let field = |name: &str| stamp.and_then(|s| s.get(name)).and_then(Value::as_i64);
    let sec = field("sec").unwrap_or(0);
    let nanosec = field("nsec").or_else(|| field("nanosec")).unwrap_or(0);
    Ok(PublishedPoint {
        topic: topic.to_string(),
        frame_id: frame_id.to_string(),
        stamp_ns: sec.saturating_mul(1_000_000_000).saturating_add(nanosec),
        x: coordinate("x")?,
        y: coordinate("y")?,
        z: coordinate("z")?,
    })
}

/// ROS 2 CDR: the 4-byte encapsulation header (`00 01` little-endian, `00 00` big-endian), then
/// `int32 sec`, `uint32 nanosec`, `string frame_id` (length with the NUL, bytes, NUL), padding
/// to 8 bytes (counted from after the header), three `float64`.
fn decode_cdr(topic: &str, payload: &[u8]) -> Result<PublishedPoint, String> {
    let short = || format!("a cdr point of {} bytes is cut short", payload.len());
    let (head, body) = payload.split_first_chunk::<4>().ok_or_else(short)?;
    let little = match head[..2] {
        [0, 1] => true,
        [0, 0] => false,
        _ => return Err(format!("cdr encapsulation {:02x} {:02x} is not plain CDR", head[0], head[1])),
    };
    let mut at = 0usize;
    let mut take = |n: usize, align: usize| -> Result<&[u8], String> {
        at = at.div_ceil(align) * align;
        let bytes = body.get(at..at + n).ok_or_else(short)?;
        at += n;
        Ok(bytes)
    };
    let word = |b: &[u8]| -> [u8; 4] { [b[0], b[1], b[2], b[3]] };
    let u32_of = |b: [u8; 4]| if little { u32::from_le_bytes(b) } else { u32::from_be_bytes(b) };
    let sec = u32_of(word(take(4, 4)?)) as i32;
    let nanosec = u32_of(word(take(4, 4)?));
    let len = u32_of(word(take(4, 4)?)) as usize;
    if len > MAX_POINT_BYTES {
        return Err(format!("a frame id of {len} bytes"));
    }
    let text = take(len, 1)?;
    let text = text.strip_suffix(&[0]).unwrap_or(text);
    let frame_id = std::str::from_utf8(text).map_err(|_| "a frame id that is not UTF-8".to_string())?;
    let mut coordinate = || -> Result<f64, String> {
        let b = take(8, 8)?;
        let bytes = [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
        Ok(if little { f64::from_le_bytes(bytes) } else { f64::from_be_bytes(bytes) })
    };
    let (x, y, z) = (coordinate()?, coordinate()?, coordinate()?);
    Ok(PublishedPoint {
        topic: topic.to_string(),
        frame_id: frame_id.to_string(),
        stamp_ns: i64::from(sec) * 1_000_000_000 + i64::from(nanosec),
        x,
        y,
        z,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A `PointStamped` in little-endian CDR, as a ROS 2 writer lays it out.
    pub(crate) fn cdr_point(frame: &str, sec: i32, nanosec: u32, p: [f64; 3]) -> Vec<u8> {
        let mut out = vec![0, 1, 0, 0];
        out.extend_from_slice(&sec.to_le_bytes());
        out.extend_from_slice(&nanosec.to_le_bytes());
        out.extend_from_slice(&(frame.len() as u32 + 1).to_le_bytes());
        out.extend_from_slice(frame.as_bytes());
        out.push(0);
        while (out.len() - 4) % 8 != 0 {
            out.push(0);
        }
        for v in p {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out
    }

    #[test]
    fn json_as_foxglove_writes_it_and_cdr_as_ros2_does_decode_to_the_same_point() {
        let json = br#"{"header":{"stamp":{"sec":12,"nsec":5},"frame_id":"map"},"point":{"x":40.5,"y":-3,"z":0}}"#;
        let a = decode("/clicked_point", "json", json).unwrap();
        let b = decode("/clicked_point", "cdr", &cdr_point("map", 12, 5, [40.5, -3.0, 0.0])).unwrap();
        assert_eq!(a, b);
        assert_eq!((a.frame_id.as_str(), a.stamp_ns, a.x, a.y), ("map", 12_000_000_005, 40.5, -3.0));
        // Frame ids of every length pad the coordinates differently.
        for frame in ["", "m", "map", "odom_frame", "a_longer_frame_id"] {
            let p = decode("/p", "cdr", &cdr_point(frame, 1, 2, [1.0, 2.0, 3.0])).unwrap();
            assert_eq!((p.frame_id.as_str(), p.x, p.y, p.z), (frame, 1.0, 2.0, 3.0));
        }
    }

    #[test]
    fn bad_points_are_refused_with_the_reason() {
        let cases: [(&str, &[u8], &str); 6] = [
            ("json", b"{", "not JSON"),
            ("json", br#"{"point":{"x":1,"y":2}}"#, "point.z"),
            ("json", br#"{"header":{},"point":{"x":1e999,"y":2,"z":0}}"#, "not JSON"),
            ("cdr", &[0, 1, 0, 0, 1, 2], "cut short"),
            ("cdr", &[9, 9, 0, 0], "not plain CDR"),
            ("protobuf", b"", "not taken"),
        ];
        for (encoding, payload, why) in cases {
            let err = decode("/p", encoding, payload).unwrap_err();
            assert!(err.contains(why), "{encoding} {payload:?}: {err}");
        }
        let nan = cdr_point("map", 0, 0, [f64::NAN, 0.0, 0.0]);
        assert!(decode("/p", "cdr", &nan).unwrap_err().contains("not finite"));
        let mut cut = cdr_point("map", 0, 0, [1.0, 2.0, 3.0]);
        cut.pop();
        assert!(decode("/p", "cdr", &cut).unwrap_err().contains("cut short"));
        assert!(decode("/p", "json", &vec![b' '; MAX_POINT_BYTES + 1]).unwrap_err().contains("at most"));
        assert!(accepts("geometry_msgs/PoseStamped", "json").unwrap_err().contains("PointStamped"));
        assert!(accepts("geometry_msgs/msg/PointStamped", "ros1").is_err());
        assert!(accepts("geometry_msgs/PointStamped", "json").is_ok());
    }
}
