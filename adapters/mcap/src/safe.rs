//! A log file that stays readable when the process dies: every chunk is written whole, and each
//! write of chunks ends with a temporary end of file (a `DataEnd` and a `Footer` without a
//! summary, then the closing magic), so between writes the file on disk is always a complete
//! MCAP file that standard readers open in their default mode (they read it front to back).
//! The next write starts where that temporary end began and replaces it; `finish` writes the
//! real summary, footer and magic.
//!
//! Each write of chunks is one `pwrite` of the chunks and the temporary end together: a kill
//! during that one system call (microseconds, against seconds between chunks) is the only moment
//! the file is not complete, and `spomp log recover` rebuilds such a file to its last whole chunk.

use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::os::unix::fs::FileExt;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};

/// The magic that opens and closes an MCAP file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Bytes of [`provisional_end`].
pub const PROVISIONAL_END_LEN: usize = 13 + 29 + 8;

/// A `DataEnd` record (no CRC), a `Footer` that points at no summary, and the closing magic:
/// the end of a file whose readers must read it linearly.
pub fn provisional_end() -> [u8; PROVISIONAL_END_LEN] {
    let mut out = [0u8; PROVISIONAL_END_LEN];
    // DataEnd: opcode 0x0F, length 4, data_section_crc 0.
    out[0] = 0x0F;
    out[1..9].copy_from_slice(&4u64.to_le_bytes());
    // Footer: opcode 0x02, length 20, summary_start 0, summary_offset_start 0, summary_crc 0.
    out[13] = 0x02;
    out[14..22].copy_from_slice(&20u64.to_le_bytes());
    out[42..50].copy_from_slice(MAGIC);
    out
}

/// The file under a [`crate::Recorder`] made by [`crate::Recorder::create`]: it keeps what the
/// MCAP writer writes in memory until a chunk is complete, then writes it at once followed by
/// the provisional end (see the module documentation).
#[derive(Debug)]
pub struct SafeFile {
    file: File,
    /// Bytes accepted but not yet on disk.
    pending: Vec<u8>,
    /// Bytes on disk, not counting the provisional end.
    committed: u64,
    /// What a flush means, set by the recorder: [`FLUSH_IGNORE`], [`FLUSH_CHUNK`] (the writer
    /// just closed a chunk, so `pending` is a whole number of records) or [`FLUSH_LAST`].
    mode: Arc<AtomicU8>,
}

/// A flush in the middle of a record: nothing is written.
pub(crate) const FLUSH_IGNORE: u8 = 0;
/// A flush after a whole chunk: write it and the provisional end.
pub(crate) const FLUSH_CHUNK: u8 = 1;
/// The flush after the summary: write it and cut the file there.
pub(crate) const FLUSH_LAST: u8 = 2;

impl SafeFile {
    /// Creates the file at `path` anew (an old regular file is replaced; a symbolic link, a
    /// FIFO or a folder there is refused, never written through); `mode` tells what a flush
    /// means.
    pub(crate) fn create(path: &Path, mode: Arc<AtomicU8>) -> std::io::Result<Self> {
        let file = spomp_behaviors::mission::output::create_file(path)?;
        Ok(SafeFile { file, pending: Vec::new(), committed: 0, mode })
    }

    /// Writes what is pending, with the provisional end after it unless `last`.
    fn commit(&mut self, last: bool) -> std::io::Result<()> {
        if self.pending.is_empty() && !last {
            return Ok(());
        }
        if !last {
            self.pending.extend_from_slice(&provisional_end());
        }
        self.file.write_all_at(&self.pending, self.committed)?;
        let data = if last { self.pending.len() } else { self.pending.len() - PROVISIONAL_END_LEN };
        self.committed += data as u64;
        self.pending.clear();
        if last {
            self.file.set_len(self.committed)?;
            self.file.sync_all()?;
        }
        Ok(())
    }

    fn position(&self) -> u64 {
        self.committed + self.pending.len() as u64
    }
}

impl Write for SafeFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.pending.extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match self.mode.load(Ordering::Relaxed) {
            FLUSH_CHUNK => self.commit(false),
            FLUSH_LAST => self.commit(true),
            _ => Ok(()),
        }
    }
}

impl Seek for SafeFile {
    /// Only reports the position: the MCAP writer runs with seeking disabled and asks nothing
    /// else.
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        let here = self.position();
        match pos {
            SeekFrom::Current(0) | SeekFrom::End(0) => Ok(here),
            SeekFrom::Start(p) if p == here => Ok(here),
            _ => Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "a log file is written front to back")),
        }
    }
}
