//! A robot's state file: written atomically (a temporary file beside it, fsync, rename, fsync of
//! the folder), so a crash or power loss leaves the old file or the new one, never half of one;
//! read back only if it is whole (length and CRC-32 checked) and of the expected kind.
//!
//! Layout: `SPSTATE1`, the robot id's length (u16, little endian) and bytes, the payload length
//! (u64 LE), the payload, the CRC-32 of everything before it (u32 LE).

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"SPSTATE1";
/// A state file larger than this is not one of ours (a team state is megabytes at most).
pub const MAX_STATE_BYTES: u64 = 512 * 1024 * 1024;

/// Why a state file was not written or not taken.
#[derive(Debug, thiserror::Error)]
pub enum StateFileError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The file is damaged, foreign or not a state file.
    #[error("{path}: {reason}")]
    Refused {
        /// The file.
        path: PathBuf,
        /// Why it is not trusted.
        reason: String,
    },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> StateFileError + '_ {
    move |source| StateFileError::Io { path: path.to_path_buf(), source }
}

/// Writes `payload` as `robot`'s state to `path` atomically.
pub fn write_state(path: &Path, robot: &str, payload: &[u8]) -> Result<(), StateFileError> {
    let mut bytes = Vec::with_capacity(payload.len() + 64);
    bytes.extend_from_slice(MAGIC);
    let id = robot.as_bytes();
    let id_len = u16::try_from(id.len())
        .map_err(|_| StateFileError::Refused { path: path.to_path_buf(), reason: "robot id too long".into() })?;
    bytes.extend_from_slice(&id_len.to_le_bytes());
    bytes.extend_from_slice(id);
    bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    bytes.extend_from_slice(payload);
    let crc = crc32fast::hash(&bytes);
    bytes.extend_from_slice(&crc.to_le_bytes());

    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "state".into());
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    {
        let mut f = fs::File::create(&tmp).map_err(io_err(&tmp))?;
        f.write_all(&bytes).map_err(io_err(&tmp))?;
        f.sync_all().map_err(io_err(&tmp))?;
    }
    fs::rename(&tmp, path).map_err(io_err(path))?;
    // The rename is durable once the folder is synced.
    if let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// Reads `robot`'s state from `path`: the payload, or why the file is not trusted. A missing
/// file is `Ok(None)`.
pub fn read_state(path: &Path, robot: &str) -> Result<Option<Vec<u8>>, StateFileError> {
    let refused = |reason: String| StateFileError::Refused { path: path.to_path_buf(), reason };
    let meta = match fs::metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io_err(path)(e)),
    };
    if !meta.is_file() {
        return Err(refused("not a regular file".into()));
    }
    if meta.len() > MAX_STATE_BYTES {
        return Err(refused(format!("{} bytes, more than a state file holds", meta.len())));
    }
    let bytes = fs::read(path).map_err(io_err(path))?;
    let body = bytes.len().checked_sub(4).map(|n| bytes.split_at(n)).ok_or_else(|| refused("cut short".into()))?;
    let (body, crc) = body;
    let crc = u32::from_le_bytes(crc.try_into().map_err(|_| refused("cut short".into()))?);
    if !body.starts_with(MAGIC) {
        return Err(refused("not a spomp state file".into()));
    }
    if crc32fast::hash(body) != crc {
        return Err(refused("damaged (checksum mismatch)".into()));
    }
    let rest = &body[MAGIC.len()..];
    let (id_len, rest) = rest.split_first_chunk::<2>().ok_or_else(|| refused("cut short".into()))?;
    let id_len = u16::from_le_bytes(*id_len) as usize;
    let (id, rest) = rest.split_at_checked(id_len).ok_or_else(|| refused("cut short".into()))?;
    if id != robot.as_bytes() {
        return Err(refused(format!("the state of robot `{}`, not `{robot}`", String::from_utf8_lossy(id))));
    }
    let (len, payload) = rest.split_first_chunk::<8>().ok_or_else(|| refused("cut short".into()))?;
    if u64::from_le_bytes(*len) != payload.len() as u64 {
        return Err(refused("payload length does not match".into()));
    }
    Ok(Some(payload.to_vec()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_refusals() {
        let dir = std::env::temp_dir().join(format!("spomp-state-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("ugv1.state");
        assert!(read_state(&path, "ugv1").unwrap().is_none());
        write_state(&path, "ugv1", b"hello").unwrap();
        assert_eq!(read_state(&path, "ugv1").unwrap().unwrap(), b"hello");
        write_state(&path, "ugv1", b"second").unwrap();
        assert_eq!(read_state(&path, "ugv1").unwrap().unwrap(), b"second");
        assert!(read_state(&path, "ugv2").unwrap_err().to_string().contains("not `ugv2`"));
        let good = fs::read(&path).unwrap();
        for k in 0..good.len() {
            let mut bad = good.clone();
            bad[k] ^= 0x10;
            fs::write(&path, &bad).unwrap();
            assert!(read_state(&path, "ugv1").is_err(), "flip at {k} accepted");
        }
        for cut in 0..good.len() {
            fs::write(&path, &good[..cut]).unwrap();
            assert!(read_state(&path, "ugv1").is_err(), "cut at {cut} accepted");
        }
        assert!(read_state(&dir, "ugv1").is_err(), "a folder");
        let _ = fs::remove_dir_all(&dir);
    }
}
