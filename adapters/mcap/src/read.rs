//! Reading logs back (replay, tests, tools). Malformed files are rejected with an error, never
//! a panic.

use byteorder::LittleEndian;
use serde::de::DeserializeOwned;

use crate::record::CDR_LE_HEADER;

/// Why a log could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// Not a valid MCAP file, or a corrupt record.
    #[error("not a readable MCAP log: {0}")]
    Mcap(#[from] mcap::McapError),
    /// A record declares sizes the file cannot hold.
    #[error("corrupt MCAP log: {0}")]
    Corrupt(String),
    /// A message is not CDR as ROS 2 writes it.
    #[error("message on {topic} is not little-endian CDR: {message}")]
    Decode {
        /// Topic.
        topic: String,
        /// What failed.
        message: String,
    },
}

/// One message of a log.
#[derive(Debug, Clone)]
pub struct LogMessage {
    /// Topic.
    pub topic: String,
    /// Schema name (`geometry_msgs/msg/PoseStamped`).
    pub schema: String,
    /// Schema encoding (`ros2msg`).
    pub schema_encoding: String,
    /// Message encoding (`cdr`).
    pub encoding: String,
    /// Log time, nanoseconds.
    pub log_time: u64,
    /// Encoded bytes.
    pub data: Vec<u8>,
}

/// A log in memory.
pub struct McapLog {
    bytes: Vec<u8>,
}

impl McapLog {
    /// Wraps the bytes of a file.
    pub fn from_bytes(bytes: Vec<u8>) -> Self {
        McapLog { bytes }
    }

    /// Every message in log order; stops at the first corrupt record with an error.
    pub fn messages(&self) -> Result<Vec<LogMessage>, ReadError> {
        check_chunk_sizes(&self.bytes)?;
        let mut out = Vec::new();
        for m in mcap::MessageStream::new(&self.bytes)? {
            let m = m?;
            let (schema, schema_encoding) = match &m.channel.schema {
                Some(s) => (s.name.clone(), s.encoding.clone()),
                None => (String::new(), String::new()),
            };
            out.push(LogMessage {
                topic: m.channel.topic.clone(),
                schema,
                schema_encoding,
                encoding: m.channel.message_encoding.clone(),
                log_time: m.log_time,
                data: m.data.into_owned(),
            });
        }
        Ok(out)
    }
}

/// Largest decompressed chunk accepted, and the largest expansion over the compressed size.
const MAX_CHUNK_BYTES: u64 = 512 << 20;
const MAX_EXPANSION: u64 = 4096;

/// Walks every record, inside chunks too, and rejects lengths the data cannot hold before the
/// reader allocates buffers of that size: a corrupt length field must be an error, not an
/// out-of-memory abort.
fn check_chunk_sizes(bytes: &[u8]) -> Result<(), ReadError> {
    if bytes.len() < MAGIC_LEN {
        return Ok(()); // the reader reports the missing magic
    }
    check_records(&bytes[MAGIC_LEN..], true)
}

/// Length of the magic that opens an MCAP file.
const MAGIC_LEN: usize = 8;

fn corrupt(what: String) -> ReadError {
    ReadError::Corrupt(what)
}

/// Checks a run of records (`opcode u8, length u64, body`); descends into chunks at top level.
fn check_records(mut data: &[u8], top_level: bool) -> Result<(), ReadError> {
    const CHUNK_OPCODE: u8 = 0x06;
    let mut offset = 0usize;
    while data.len() >= 9 {
        let opcode = data[0];
        let len = read_u64(data, 1).unwrap_or(u64::MAX);
        // A record that claims more than is left is corrupt even at top level: the reader
        // streams a chunk from its header's sizes without looking at the record length, so a
        // chunk behind an overrunning length would otherwise go unchecked.
        let Some(body) = usize::try_from(len).ok().and_then(|l| data.get(9..9usize.checked_add(l)?)) else {
            let (place, container) = if top_level {
                (format!("file offset {}", offset + MAGIC_LEN), "the file")
            } else {
                (format!("chunk offset {offset}"), "the chunk")
            };
            let left = data.len() - 9;
            return Err(corrupt(format!(
                "record at {place} declares {len} bytes, more than {container} holds ({left} left)"
            )));
        };
        if top_level && opcode == CHUNK_OPCODE {
            check_chunk(body)?;
        }
        offset += 9 + body.len();
        data = &data[9 + body.len()..];
    }
    if !top_level && !data.is_empty() {
        return Err(corrupt(format!("{} stray bytes at the end of a chunk", data.len())));
    }
    Ok(())
}

/// A chunk body: start and end time, uncompressed size and CRC, compression name, records.
fn check_chunk(body: &[u8]) -> Result<(), ReadError> {
    let uncompressed = read_u64(body, 16).ok_or_else(|| corrupt("truncated chunk header".into()))?;
    let name_len = read_u32(body, 28).ok_or_else(|| corrupt("truncated chunk header".into()))? as usize;
    let name = body.get(32..32 + name_len).ok_or_else(|| corrupt("truncated chunk compression name".into()))?;
    let records_len = read_u64(body, 32 + name_len).ok_or_else(|| corrupt("truncated chunk header".into()))?;
    let records = usize::try_from(records_len)
        .ok()
        .and_then(|l| body.get(40 + name_len..(40 + name_len).checked_add(l)?))
        .ok_or_else(|| corrupt(format!("chunk declares {records_len} record bytes, more than it holds")))?;
    if uncompressed > MAX_CHUNK_BYTES
        || uncompressed > (records.len() as u64).saturating_mul(MAX_EXPANSION).max(1 << 16)
    {
        return Err(corrupt(format!("chunk declares {uncompressed} decompressed bytes from {}", records.len())));
    }
    match name {
        b"" => check_records(records, false),
        b"zstd" => {
            let plain = zstd::bulk::decompress(records, uncompressed as usize)
                .map_err(|e| corrupt(format!("chunk does not decompress: {e}")))?;
            if plain.len() as u64 != uncompressed {
                return Err(corrupt(format!("chunk decompresses to {} bytes, declared {uncompressed}", plain.len())));
            }
            check_records(&plain, false)
        }
        other => Err(corrupt(format!("unsupported chunk compression `{}`", String::from_utf8_lossy(other)))),
    }
}

fn read_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let b: [u8; 4] = bytes.get(at..at.checked_add(4)?)?.try_into().ok()?;
    Some(u32::from_le_bytes(b))
}

fn read_u64(bytes: &[u8], at: usize) -> Option<u64> {
    let b: [u8; 8] = bytes.get(at..at.checked_add(8)?)?.try_into().ok()?;
    Some(u64::from_le_bytes(b))
}

/// Decodes a CDR message (with its encapsulation header) into `T`.
pub fn decode_cdr<T: DeserializeOwned>(topic: &str, data: &[u8]) -> Result<T, ReadError> {
    let bad = |message: String| ReadError::Decode { topic: topic.to_string(), message };
    let Some(body) = data.strip_prefix(&CDR_LE_HEADER[..]) else {
        return Err(bad("missing the little-endian CDR encapsulation header".into()));
    };
    cdr_encoding::from_bytes::<T, LittleEndian>(body).map(|(v, _)| v).map_err(|e| bad(e.to_string()))
}
