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
    /// A checksum of the log does not match its bytes.
    #[error("corrupt MCAP log: {0}")]
    Checksum(String),
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

/// What [`check_log`] found in a log file.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LogCheck {
    /// The file was closed properly: a summary section and footer follow the data.
    pub closed: bool,
    /// Chunks read, every one whole and decompressing to well-formed records.
    pub chunks: usize,
    /// Messages readable, by topic.
    pub topics: std::collections::BTreeMap<String, u64>,
    /// Bytes from the start of the file to the end of the last whole record of the data.
    pub readable_bytes: u64,
    /// Bytes after them that are not part of a whole record (what a crash cut short), or, when
    /// `bad_record` is set, everything from the bad record on.
    pub lost_bytes: u64,
    /// The first record that is whole but corrupt (offset and why), if any: the data after it is
    /// not read. A chunk whose content does not match its CRC is such a record.
    pub bad_record: Option<(u64, String)>,
    /// Chunks not read because they lie after `bad_record` (the bad one included).
    pub dropped_chunks: usize,
    /// Checksums verified and found right (chunks, attachments, the data section, the summary).
    pub crcs_verified: usize,
    /// Every checksum that does not match, in file order: where the checked bytes start and
    /// what failed.
    pub crc_failures: Vec<(u64, String)>,
    /// Attachments of the readable data whose CRC does not match (offsets): not to be trusted.
    pub bad_attachments: Vec<u64>,
}

impl LogCheck {
    /// Messages readable.
    pub fn messages(&self) -> u64 {
        self.topics.values().sum()
    }

    /// Every record and checksum read checked out: no corrupt record, no CRC mismatch.
    pub fn intact(&self) -> bool {
        self.bad_record.is_none() && self.crc_failures.is_empty()
    }
}

/// A CRC mismatch, worded for the user.
fn crc_mismatch(what: &str, saved: u32, computed: u32) -> String {
    format!("{what} CRC mismatch (recorded {saved:08x}, computed {computed:08x})")
}

const OP_CHUNK: u8 = 0x06;
const OP_ATTACHMENT: u8 = 0x09;
const OP_DATA_END: u8 = 0x0F;
const OP_FOOTER: u8 = 0x02;
/// Bytes of a footer record: opcode, length, summary start, summary offset start, summary CRC.
const FOOTER_LEN: usize = 1 + 8 + 8 + 8 + 4;

/// Checks a log file as a crash may have left it: every record of the data section is read up
/// to the last whole one, every chunk decompressed and its records checked, and the messages
/// counted by topic. Every checksum the format has is verified where it is set: each chunk's
/// `uncompressed_crc` (a mismatch is a bad record: nothing from it on is read), each
/// attachment's CRC, the data section CRC of the `DataEnd` record and the summary CRC of the
/// footer. An error only when the file is not an MCAP log at all.
pub fn check_log(bytes: &[u8]) -> Result<LogCheck, ReadError> {
    let (check, data_end) = scan_data(bytes)?;
    let mut check = check;
    for m in mcap::MessageStream::new(&readable_prefix(bytes, data_end))? {
        match m {
            Ok(m) => *check.topics.entry(m.channel.topic.clone()).or_default() += 1,
            Err(e) => {
                check.bad_record.get_or_insert((data_end as u64, format!("message stream: {e}")));
                break;
            }
        }
    }
    Ok(check)
}

/// Rewrites the part of a log that checks out (see [`check_log`]) as a complete, indexed MCAP
/// file: the messages of the chunks before the first corrupt record or CRC mismatch, and the
/// metadata and attachments among them whose checksums hold (none of the metadata when the data
/// section CRC fails: nothing else covers it). What was left out is in the returned check.
pub fn recover_log<W: std::io::Write + std::io::Seek>(bytes: &[u8], out: W) -> Result<LogCheck, ReadError> {
    let (mut check, data_end) = scan_data(bytes)?;
    let data_crc_failed = check.crc_failures.iter().any(|(_, why)| why.starts_with(DATA_SECTION));
    let mut writer = mcap::WriteOptions::new().profile("ros2").library("spomp log recover").create(out)?;
    let prefix = readable_prefix(bytes, data_end);
    for m in mcap::MessageStream::new(&prefix)? {
        let Ok(m) = m else { break };
        *check.topics.entry(m.channel.topic.clone()).or_default() += 1;
        writer.write(&m)?;
    }
    // The records outside chunks: metadata (the run's setup) and attachments whose CRC holds.
    let mut at = MAGIC_LEN;
    while let Some((opcode, body)) = record_at(&prefix[..data_end], at) {
        match opcode {
            0x0C if !data_crc_failed => {
                if let Ok(mcap::records::Record::Metadata(m)) = mcap::parse_record(opcode, body) {
                    writer.write_metadata(&m)?;
                }
            }
            OP_ATTACHMENT if !check.bad_attachments.contains(&(at as u64)) => {
                if let Ok(mcap::records::Record::Attachment { header, data, .. }) = mcap::parse_record(opcode, body) {
                    writer.attach(&mcap::Attachment {
                        log_time: header.log_time,
                        create_time: header.create_time,
                        name: header.name,
                        media_type: header.media_type,
                        data,
                    })?;
                }
            }
            _ => {}
        }
        at += 9 + body.len();
    }
    writer.finish()?;
    Ok(check)
}

/// The record (opcode and body) at `at` of `data`, if `data` holds it whole.
fn record_at(data: &[u8], at: usize) -> Option<(u8, &[u8])> {
    let rest = data.get(at..)?;
    let len = read_u64(rest, 1)?;
    let body = usize::try_from(len).ok().and_then(|l| rest.get(9..9usize.checked_add(l)?))?;
    Some((rest[0], body))
}

/// How a data section CRC failure is worded (and recognised).
const DATA_SECTION: &str = "data section";

/// The data section up to `data_end`, closed with a provisional end so that a linear reader
/// reads it to the end.
pub(crate) fn readable_prefix(bytes: &[u8], data_end: usize) -> Vec<u8> {
    let mut v = Vec::with_capacity(data_end + crate::safe::PROVISIONAL_END_LEN);
    v.extend_from_slice(&bytes[..data_end]);
    v.extend_from_slice(&crate::safe::provisional_end());
    v
}

/// Walks the data section; returns what it found and where the readable data ends.
fn scan_data(bytes: &[u8]) -> Result<(LogCheck, usize), ReadError> {
    if bytes.get(..MAGIC_LEN) != Some(&crate::safe::MAGIC[..]) {
        return Err(corrupt("the file does not start with the MCAP magic".into()));
    }
    let mut check = LogCheck::default();
    let mut at = MAGIC_LEN;
    loop {
        let rest = &bytes[at..];
        let Some(len) = read_u64(rest, 1) else { break };
        let Some(body) = usize::try_from(len).ok().and_then(|l| rest.get(9..9usize.checked_add(l)?)) else {
            break; // a record the file does not hold whole: where a crash cut the log
        };
        match rest[0] {
            OP_CHUNK => {
                match check_chunk(body) {
                    Ok(crc_checked) => check.crcs_verified += usize::from(crc_checked),
                    Err(e) => {
                        if let ReadError::Checksum(why) = &e {
                            check.crc_failures.push((at as u64, why.clone()));
                        }
                        check.bad_record = Some((at as u64, e.to_string()));
                        check.dropped_chunks = count_chunks(&bytes[at..]);
                        break;
                    }
                }
                check.chunks += 1;
            }
            OP_ATTACHMENT if check_fields(OP_ATTACHMENT, body).is_ok() => {
                match mcap::parse_record(OP_ATTACHMENT, body) {
                    Err(mcap::McapError::BadAttachmentCrc { saved, calculated }) => {
                        let name = attachment_name(body);
                        check
                            .crc_failures
                            .push((at as u64, crc_mismatch(&format!("attachment `{name}`"), saved, calculated)));
                        check.bad_attachments.push(at as u64);
                    }
                    Ok(mcap::records::Record::Attachment { crc, .. }) if crc != 0 => check.crcs_verified += 1,
                    _ => {}
                }
            }
            OP_DATA_END => {
                // The data section CRC covers every byte before this record, the magic included.
                if let Some(saved) = read_u32(body, 0).filter(|&c| c != 0) {
                    let computed = crc32fast::hash(&bytes[..at]);
                    if computed == saved {
                        check.crcs_verified += 1;
                    } else {
                        check.crc_failures.push((0, crc_mismatch(DATA_SECTION, saved, computed)));
                    }
                }
                let after = &rest[9 + body.len()..];
                // A footer that points at a summary, then the magic: a file closed properly.
                check.closed = after.len() >= 9 + 20 + MAGIC_LEN
                    && after[after.len() - MAGIC_LEN..] == crate::safe::MAGIC[..]
                    && after[after.len() - MAGIC_LEN - 29] == OP_FOOTER
                    && read_u64(after, after.len() - MAGIC_LEN - 20).is_some_and(|s| s != 0);
                if after.len() >= FOOTER_LEN + MAGIC_LEN && after[after.len() - MAGIC_LEN..] == crate::safe::MAGIC[..] {
                    check_summary_crc(bytes, &mut check);
                }
                break;
            }
            OP_FOOTER => break,
            opcode => {
                if let Err(field) = check_fields(opcode, body) {
                    let why =
                        format!("record (opcode {opcode:#04x}): its {field} declares more bytes than the record holds");
                    check.bad_record = Some((at as u64, why));
                    break;
                }
            }
        }
        at += 9 + body.len();
    }
    // The walk stopped at a record the file does not hold whole, yet the file ends as a closed
    // log does (a footer, then the magic): no crash leaves that, a damaged length field does.
    if check.bad_record.is_none() && !check.closed && record_at(bytes, at).is_none() && ends_closed(bytes) {
        check.bad_record =
            Some((at as u64, "record length runs past the data section of a closed log (a damaged length)".into()));
        check.dropped_chunks = count_chunks_after(bytes, at);
    }
    check.readable_bytes = at as u64;
    check.lost_bytes = (bytes.len() - at) as u64;
    if check.closed || bytes[at..].first() == Some(&OP_DATA_END) {
        check.lost_bytes = 0;
    }
    Ok((check, at))
}

/// The file ends with a footer record and the MCAP magic, as a log that was closed does.
fn ends_closed(bytes: &[u8]) -> bool {
    bytes.len() >= MAGIC_LEN + FOOTER_LEN + MAGIC_LEN
        && bytes[bytes.len() - MAGIC_LEN..] == crate::safe::MAGIC[..]
        && bytes[bytes.len() - MAGIC_LEN - FOOTER_LEN] == OP_FOOTER
        && read_u64(bytes, bytes.len() - MAGIC_LEN - FOOTER_LEN + 1) == Some(20)
}

/// Chunks at or after byte `at`, as the summary's chunk index lists them (0 when the footer
/// points at no summary or the index does not read).
fn count_chunks_after(bytes: &[u8], at: usize) -> usize {
    const OP_CHUNK_INDEX: u8 = 0x08;
    let footer = bytes.len() - MAGIC_LEN - FOOTER_LEN;
    let Some(start) =
        read_u64(bytes, footer + 9).and_then(|s| usize::try_from(s).ok()).filter(|&s| s != 0 && s < footer)
    else {
        return 0;
    };
    let summary = &bytes[start..footer];
    let mut n = 0;
    let mut i = 0;
    while let Some((opcode, body)) = record_at(summary, i) {
        // A chunk index begins with the message start and end times, then the chunk's offset.
        let offset = read_u64(body, 16).and_then(|o| usize::try_from(o).ok());
        n += usize::from(opcode == OP_CHUNK_INDEX && offset.is_some_and(|o| o >= at));
        i += 9 + body.len();
    }
    n
}

/// Verifies the footer's summary CRC (when set): it covers the summary section (or nothing when
/// there is none) through the footer's `summary_offset_start` field.
fn check_summary_crc(bytes: &[u8], check: &mut LogCheck) {
    let footer = bytes.len() - MAGIC_LEN - FOOTER_LEN;
    if bytes[footer] != OP_FOOTER {
        return;
    }
    let (Some(summary_start), Some(saved)) = (read_u64(bytes, footer + 9), read_u32(bytes, footer + 25)) else {
        return;
    };
    if saved == 0 {
        return;
    }
    let start = if summary_start == 0 { Some(footer) } else { usize::try_from(summary_start).ok() };
    let what = "summary section";
    match start.filter(|&s| s <= footer) {
        Some(start) => {
            let computed = crc32fast::hash(&bytes[start..footer + 25]);
            if computed == saved {
                check.crcs_verified += 1;
            } else {
                check.crc_failures.push((start as u64, crc_mismatch(what, saved, computed)));
            }
        }
        None => check.crc_failures.push((
            footer as u64,
            format!("{what}: the footer's summary start {summary_start} lies past the footer, so its CRC cannot hold"),
        )),
    }
}

/// Chunks among the whole records of `data` (a run of top-level records).
fn count_chunks(data: &[u8]) -> usize {
    let mut n = 0;
    let mut at = 0;
    while let Some((opcode, body)) = record_at(data, at) {
        n += usize::from(opcode == OP_CHUNK);
        at += 9 + body.len();
    }
    n
}

/// The name of an attachment record (lossy), for messages.
fn attachment_name(body: &[u8]) -> String {
    let name = read_u32(body, 16)
        .and_then(|l| body.get(20..20usize.checked_add(usize::try_from(l).ok()?)?))
        .unwrap_or_default();
    String::from_utf8_lossy(name).chars().take(80).collect()
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
        check_fields(opcode, body).map_err(|field| {
            let place = if top_level {
                format!("file offset {}", offset + MAGIC_LEN)
            } else {
                format!("chunk offset {offset}")
            };
            corrupt(format!(
                "record (opcode {opcode:#04x}) at {place}: its {field} declares more bytes than the record holds"
            ))
        })?;
        offset += 9 + body.len();
        data = &data[9 + body.len()..];
    }
    if !top_level && !data.is_empty() {
        return Err(corrupt(format!("{} stray bytes at the end of a chunk", data.len())));
    }
    Ok(())
}

/// A field of a record, as the reader decodes it.
#[derive(Clone, Copy)]
enum Field {
    /// A fixed-size integer of this many bytes.
    Fixed(usize),
    /// A `u32`-length-prefixed string or byte array.
    Bytes32,
    /// A `u64`-length-prefixed byte array.
    Bytes64,
    /// A `u32`-byte-length-prefixed map of string to string.
    StrMap,
    /// A `u32`-byte-length-prefixed array of fixed-size entries.
    Array32,
}

/// The fields of the records a data section holds whose lengths the reader trusts (header,
/// schema, channel, attachment, metadata, message index), by opcode.
fn fields_of(opcode: u8) -> &'static [(&'static str, Field)] {
    use Field::*;
    match opcode {
        0x01 => &[("profile", Bytes32), ("library", Bytes32)],
        0x03 => &[("id", Fixed(2)), ("name", Bytes32), ("encoding", Bytes32), ("data", Bytes32)],
        0x04 => &[
            ("id", Fixed(2)),
            ("schema id", Fixed(2)),
            ("topic", Bytes32),
            ("message encoding", Bytes32),
            ("metadata", StrMap),
        ],
        0x07 => &[("channel id", Fixed(2)), ("records", Array32)],
        0x09 => &[
            ("log time", Fixed(8)),
            ("create time", Fixed(8)),
            ("name", Bytes32),
            ("media type", Bytes32),
            ("data", Bytes64),
            // The reader slices the data up to the CRC: the CRC must fit too.
            ("crc", Fixed(4)),
        ],
        0x0C => &[("name", Bytes32), ("metadata", StrMap)],
        _ => &[],
    }
}

/// Checks that every length-prefixed field of a record fits in the record, before the reader
/// reserves a buffer of that length (a corrupt 4 GB string length in a 6 kB log made it
/// allocate 4 GB). Returns the name of the first field that does not fit.
fn check_fields(opcode: u8, body: &[u8]) -> Result<(), &'static str> {
    let mut at = 0usize;
    for &(name, field) in fields_of(opcode) {
        let len = match field {
            Field::Fixed(n) => Some(n),
            Field::Bytes32 | Field::StrMap | Field::Array32 => {
                read_u32(body, at).and_then(|l| usize::try_from(l).ok()?.checked_add(4))
            }
            Field::Bytes64 => read_u64(body, at).and_then(|l| usize::try_from(l).ok()?.checked_add(8)),
        };
        let Some(end) = len.and_then(|l| at.checked_add(l)).filter(|&end| end <= body.len()) else {
            return Err(name);
        };
        if let Field::StrMap = field {
            // Each entry: a key and a value, both length-prefixed strings inside the map.
            let mut entry = at + 4;
            while entry < end {
                for _ in 0..2 {
                    let fits = read_u32(&body[..end], entry)
                        .and_then(|l| usize::try_from(l).ok()?.checked_add(4))
                        .and_then(|l| entry.checked_add(l))
                        .filter(|&e| e <= end);
                    entry = fits.ok_or(name)?;
                }
            }
        }
        at = end;
    }
    Ok(())
}

/// A chunk body: start and end time, uncompressed size and CRC, compression name, records.
/// Verifies the records' CRC when the chunk records one; returns whether it did.
fn check_chunk(body: &[u8]) -> Result<bool, ReadError> {
    let uncompressed = read_u64(body, 16).ok_or_else(|| corrupt("truncated chunk header".into()))?;
    let saved_crc = read_u32(body, 24).ok_or_else(|| corrupt("truncated chunk header".into()))?;
    let verify = |plain: &[u8]| -> Result<bool, ReadError> {
        if saved_crc == 0 {
            return Ok(false); // no CRC recorded
        }
        let computed = crc32fast::hash(plain);
        if computed != saved_crc {
            return Err(ReadError::Checksum(crc_mismatch("chunk", saved_crc, computed)));
        }
        Ok(true)
    };
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
        b"" => {
            let checked = verify(records)?;
            check_records(records, false)?;
            Ok(checked)
        }
        b"zstd" => {
            let plain = zstd::bulk::decompress(records, uncompressed as usize)
                .map_err(|e| corrupt(format!("chunk does not decompress: {e}")))?;
            if plain.len() as u64 != uncompressed {
                return Err(corrupt(format!("chunk decompresses to {} bytes, declared {uncompressed}", plain.len())));
            }
            let checked = verify(&plain)?;
            check_records(&plain, false)?;
            Ok(checked)
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
