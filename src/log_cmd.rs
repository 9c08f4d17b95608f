//! `spomp log check` and `spomp log recover`: logs a crash or a kill cut short.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use spomp_behaviors::mission::limits::read_regular;
use spomp_mcap::LogCheck;

/// The largest log these commands read, bytes (they hold it in memory).
const MAX_LOG_BYTES: u64 = 16 << 30;

fn read_log(path: &Path) -> Result<Vec<u8>> {
    read_regular(path, MAX_LOG_BYTES).map_err(|e| anyhow::anyhow!("{e}"))
}

fn describe(path: &Path, c: &LogCheck) -> String {
    let state = if c.closed && !c.intact() {
        "closed, but corrupt (see below)".to_string()
    } else if c.closed {
        "closed properly".to_string()
    } else if c.lost_bytes > 0 {
        format!("not closed (the run was cut short); {} bytes after the last whole chunk are lost", c.lost_bytes)
    } else {
        "not closed (the run was cut short); readable to its last chunk".to_string()
    };
    let mut out = format!(
        "{}: {state}\n  {} chunks, {} messages on {} topics readable ({} bytes)\n",
        path.display(),
        c.chunks,
        c.messages(),
        c.topics.len(),
        c.readable_bytes
    );
    out.push_str(&format!("  {} checksum(s) verified, {} failed\n", c.crcs_verified, c.crc_failures.len()));
    for (offset, why) in &c.crc_failures {
        out.push_str(&format!("  checksum failed at byte {offset}: {why}\n"));
    }
    if let Some((offset, why)) = &c.bad_record {
        out.push_str(&format!(
            "  corrupt record at byte {offset}: {why}; nothing after it is read ({} chunk(s) from there on)\n",
            c.dropped_chunks
        ));
    }
    out
}

/// What `log recover` left out of the recovered log, one line each (empty: nothing).
fn dropped(c: &LogCheck) -> Vec<String> {
    let mut out = Vec::new();
    if let Some((offset, _)) = &c.bad_record {
        out.push(format!("{} chunk(s) from byte {offset} on (the corrupt record and all after it)", c.dropped_chunks));
    }
    for offset in &c.bad_attachments {
        out.push(format!("the attachment at byte {offset} (its CRC does not match)"));
    }
    if c.crc_failures.iter().any(|(_, why)| why.starts_with("data section")) {
        out.push("the metadata records (the data section CRC fails and nothing else covers them)".to_string());
    }
    out
}

fn as_json(path: &Path, c: &LogCheck) -> serde_json::Value {
    serde_json::json!({
        "file": path,
        "closed": c.closed,
        "chunks": c.chunks,
        "messages": c.messages(),
        "topics": c.topics,
        "readable_bytes": c.readable_bytes,
        "lost_bytes": c.lost_bytes,
        "corrupt": c.bad_record.as_ref().map(|(o, why)| serde_json::json!({"offset": o, "message": why})),
        "dropped_chunks": c.dropped_chunks,
        "crcs_verified": c.crcs_verified,
        "crc_failures": c.crc_failures.iter().map(|(o, why)| serde_json::json!({"offset": o, "message": why})).collect::<Vec<_>>(),
        "intact": c.intact(),
    })
}

/// `spomp log check LOG`: exit 0 when the log reads cleanly to its end or, for a log a crash cut
/// short, to its last whole chunk, with every checksum it records matching; 1 when a whole
/// record is corrupt, a checksum fails or the file is no MCAP log.
pub fn check(path: &Path, json: bool) -> Result<ExitCode> {
    let bytes = read_log(path)?;
    let c = spomp_mcap::check_log(&bytes).with_context(|| format!("{}", path.display()))?;
    if json {
        out!("{}", serde_json::to_string_pretty(&as_json(path, &c))?);
    } else {
        out!("{}", describe(path, &c).trim_end());
        if !c.closed {
            out!("  `spomp log recover {} --out FIXED.mcap` writes it as a closed, indexed log", path.display());
        }
    }
    Ok(if c.intact() { ExitCode::SUCCESS } else { ExitCode::from(1) })
}

/// `spomp log recover LOG --out FIXED`: writes what checks out of a log (its readable messages,
/// the metadata and attachments whose checksums hold) as a complete, indexed MCAP file, and
/// says what it left out.
pub fn recover(path: &Path, out_path: &Path, json: bool) -> Result<ExitCode> {
    if same_file(path, out_path) {
        bail!("--out {} is the log itself; write the recovered log to another file", out_path.display());
    }
    let bytes = read_log(path)?;
    let mut buf = std::io::Cursor::new(Vec::new());
    let c = spomp_mcap::recover_log(&bytes, &mut buf).with_context(|| format!("{}", path.display()))?;
    crate::output::write(out_path, buf.into_inner())?;
    let left_out = dropped(&c);
    if json {
        let mut v = as_json(path, &c);
        v["out"] = serde_json::json!(out_path);
        v["dropped"] = serde_json::json!(left_out);
        out!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        out!("{}", describe(path, &c).trim_end());
        for d in &left_out {
            out!("dropped: {d}");
        }
        out!("wrote {} messages to {}", c.messages(), out_path.display());
    }
    Ok(ExitCode::SUCCESS)
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}
