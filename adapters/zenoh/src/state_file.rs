//! A robot's state file: written atomically (a temporary file beside it, fsync, rename, fsync of
//! the folder), so a crash or power loss leaves the old file or the new one, never half of one;
//! read back only if it is whole (length and CRC-32 checked) and of the expected kind.
//!
//! The temporary file has an unpredictable name and is created new (`O_EXCL`, which follows no
//! symbolic link), so nothing planted in the folder is written through. A file at the path that
//! is not this robot's state file (another file, a link, a folder, another robot's state) is
//! never overwritten: reading it says so ([`StateFileError::NotAStateFile`]) and writing refuses.
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
    /// The path holds something that is not this robot's state file (any other file, a symbolic
    /// link, a folder, another robot's state): it is never overwritten.
    #[error("{path}: {reason}; it is not overwritten (give another --state-file, or move it away)")]
    NotAStateFile {
        /// The path.
        path: PathBuf,
        /// What is there.
        reason: String,
    },
    /// The file is this robot's state file but damaged (cut short, checksum mismatch).
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

/// What is at `path` now: `Ok` if nothing or (the start of) a state file, which may be replaced.
fn check_replaceable(path: &Path) -> Result<(), StateFileError> {
    let not_ours = |reason: &str| StateFileError::NotAStateFile { path: path.to_path_buf(), reason: reason.into() };
    let meta = match fs::symlink_metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(io_err(path)(e)),
    };
    if meta.file_type().is_symlink() {
        return Err(not_ours("a symbolic link"));
    }
    if !meta.is_file() {
        return Err(not_ours("not a regular file"));
    }
    if meta.len() == 0 {
        return Ok(());
    }
    let mut head = [0u8; MAGIC.len()];
    let read = fs::File::open(path).and_then(|mut f| std::io::Read::read(&mut f, &mut head)).map_err(io_err(path))?;
    if read < head.len() || &head != MAGIC {
        return Err(not_ours("not a spomp state file"));
    }
    Ok(())
}

/// Writes `payload` as `robot`'s state to `path` atomically. Refuses to replace anything at
/// `path` that is not a state file.
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

    check_replaceable(path)?;
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "state".into());
    // A random name, created new: never an existing file or a link planted at a name guessed
    // in advance. Removed again if anything below fails.
    let mut tmp =
        tempfile::Builder::new().prefix(&format!(".{name}.")).suffix(".tmp").tempfile_in(dir).map_err(io_err(dir))?;
    tmp.write_all(&bytes).map_err(io_err(tmp.path()))?;
    tmp.as_file().sync_all().map_err(io_err(path))?;
    // The rename replaces the directory entry itself (a link planted at `path` meanwhile is
    // replaced, not followed).
    tmp.persist(path).map_err(|e| io_err(path)(e.error))?;
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
    let not_ours = |reason: String| StateFileError::NotAStateFile { path: path.to_path_buf(), reason };
    let meta = match fs::symlink_metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io_err(path)(e)),
    };
    if meta.file_type().is_symlink() {
        return Err(not_ours("a symbolic link".into()));
    }
    if !meta.is_file() {
        return Err(not_ours("not a regular file".into()));
    }
    if meta.len() > MAX_STATE_BYTES {
        return Err(not_ours(format!("{} bytes, more than a state file holds", meta.len())));
    }
    let bytes = fs::read(path).map_err(io_err(path))?;
    if bytes.is_empty() {
        // Made with `touch`, say: nothing to resume, and nothing lost by replacing it.
        return Err(refused("empty".into()));
    }
    if !bytes.starts_with(MAGIC) {
        return Err(not_ours("not a spomp state file".into()));
    }
    let body = bytes.len().checked_sub(4).map(|n| bytes.split_at(n)).ok_or_else(|| refused("cut short".into()))?;
    let (body, crc) = body;
    let crc = u32::from_le_bytes(crc.try_into().map_err(|_| refused("cut short".into()))?);
    if crc32fast::hash(body) != crc {
        return Err(refused("damaged (checksum mismatch)".into()));
    }
    let rest = &body[MAGIC.len()..];
    let (id_len, rest) = rest.split_first_chunk::<2>().ok_or_else(|| refused("cut short".into()))?;
    let id_len = u16::from_le_bytes(*id_len) as usize;
    let (id, rest) = rest.split_at_checked(id_len).ok_or_else(|| refused("cut short".into()))?;
    if id != robot.as_bytes() {
        return Err(not_ours(format!("the state of robot `{}`, not `{robot}`", String::from_utf8_lossy(id))));
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

    /// Regression (issue 36): the temporary file had a predictable name (`.NAME.tmp-PID`), and a
    /// link planted there was written through.
    #[cfg(unix)]
    #[test]
    fn a_link_planted_at_the_temporary_name_is_not_written_through() {
        let dir = std::env::temp_dir().join(format!("spomp-state-link-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        let victim = dir.join("victim.txt");
        fs::write(&victim, "precious\n").unwrap();
        let path = dir.join("ugv1.state");
        let planted = dir.join(format!(".ugv1.state.tmp-{}", std::process::id()));
        std::os::unix::fs::symlink(&victim, &planted).unwrap();
        write_state(&path, "ugv1", b"payload").unwrap();
        assert_eq!(fs::read_to_string(&victim).unwrap(), "precious\n", "written through the planted link");
        assert_eq!(read_state(&path, "ugv1").unwrap().unwrap(), b"payload");
        // Only the state file and the planted link: no temporary file left behind.
        let mut names: Vec<String> =
            fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        names.sort();
        assert_eq!(names.len(), 3, "{names:?}");
        let _ = fs::remove_dir_all(&dir);
    }

    /// Regression (issue 36): a path holding some other file was reported as ignored, then
    /// overwritten by the first save.
    #[test]
    fn a_file_that_is_not_a_state_file_is_never_overwritten() {
        let dir = std::env::temp_dir().join(format!("spomp-state-foreign-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        let notes = dir.join("notes.txt");
        fs::write(&notes, "my notes\n").unwrap();
        let err = read_state(&notes, "ugv1").unwrap_err();
        assert!(matches!(err, StateFileError::NotAStateFile { .. }), "{err}");
        assert!(err.to_string().contains("not a spomp state file") && err.to_string().contains("not overwritten"));
        assert!(matches!(write_state(&notes, "ugv1", b"x"), Err(StateFileError::NotAStateFile { .. })));
        assert_eq!(fs::read_to_string(&notes).unwrap(), "my notes\n");
        // Another robot's state file is not this robot's to replace either.
        let other = dir.join("ugv2.state");
        write_state(&other, "ugv2", b"theirs").unwrap();
        assert!(matches!(read_state(&other, "ugv1"), Err(StateFileError::NotAStateFile { .. })));
        #[cfg(unix)]
        {
            let link = dir.join("link.state");
            std::os::unix::fs::symlink(&other, &link).unwrap();
            assert!(matches!(read_state(&link, "ugv2"), Err(StateFileError::NotAStateFile { .. })));
            assert!(matches!(write_state(&link, "ugv2", b"x"), Err(StateFileError::NotAStateFile { .. })));
        }
        assert_eq!(read_state(&other, "ugv2").unwrap().unwrap(), b"theirs");
        let _ = fs::remove_dir_all(&dir);
    }
}
