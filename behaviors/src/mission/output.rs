//! Writing output files without writing through what someone else planted in the output folder.
//!
//! Every file the command line writes (worlds, summaries, plots, logs, experiment rows) goes
//! through these functions, so that a symbolic link or a hard link placed in an output folder
//! beforehand is never followed to a file elsewhere:
//!
//! - [`create_file`] removes an old *regular* file of that name, then creates the file anew
//!   (`O_CREAT | O_EXCL`, which never follows a link): a link planted between the two steps makes
//!   the creation fail instead of being written through;
//! - [`write_file`] writes the whole file to an unpredictably named temporary file in the same
//!   folder, then renames it over the name (a rename replaces the name itself, never a link's
//!   target), so readers see the old file or the new one, never half of one;
//! - [`append_file`] opens with `O_NOFOLLOW` and checks the opened file is a regular file with
//!   one name;
//! - [`create_dir`] makes a folder the program fills and refuses one that is a symbolic link.
//!
//! A name in the output folder that is a symbolic link, a FIFO, a device or a folder is an error
//! that says so ([`refused`]): the user sees it and removes it, nothing is overwritten silently.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
use std::path::Path;

/// The error for a name that is not a regular file (or not a plain folder) where one is written.
pub fn refused(path: &Path, what: &str) -> io::Error {
    io::Error::new(
        io::ErrorKind::AlreadyExists,
        format!("{} is {what}; refusing to write through it (remove it first)", path.display()),
    )
}

/// What is at `path` without following a link: `Ok(None)` when nothing is, an error when it is
/// not a regular file.
fn existing_regular(path: &Path) -> io::Result<Option<std::fs::Metadata>> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_file() => Ok(Some(m)),
        Ok(m) if m.file_type().is_symlink() => Err(refused(path, "a symbolic link")),
        Ok(m) if m.is_dir() => Err(refused(path, "a folder")),
        Ok(_) => Err(refused(path, "not a regular file")),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(e),
    }
}

/// Creates `path` as a new, empty file for writing: an old regular file of that name is removed
/// first (so a hard link to a file elsewhere is unlinked, not truncated); a symbolic link, FIFO,
/// device or folder there is refused. The file is created exclusively, so nothing planted
/// between the removal and the creation is followed.
pub fn create_file(path: &Path) -> io::Result<File> {
    if existing_regular(path)?.is_some() {
        std::fs::remove_file(path)?;
    }
    OpenOptions::new().write(true).create_new(true).open(path).map_err(|e| {
        if e.kind() == io::ErrorKind::AlreadyExists {
            refused(path, "a name that appeared while it was being replaced")
        } else {
            e
        }
    })
}

/// Writes `bytes` as the whole of `path`, atomically: through a temporary file with an
/// unpredictable name in the same folder, synced, then renamed over `path`. A symbolic link,
/// FIFO, device or folder at `path` is refused.
pub fn write_file(path: &Path, bytes: &[u8]) -> io::Result<()> {
    existing_regular(path)?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path.file_name().ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "no file name"))?;
    // The mode a plain create gives (0666 less the umask), not the temporary file's 0600.
    let mut tmp = tempfile::Builder::new()
        .prefix(&format!(".{}.", name.to_string_lossy()))
        .suffix(".tmp")
        .permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666))
        .tempfile_in(dir)?;
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// Opens `path` for appending, creating it if missing, without following a symbolic link
/// (`O_NOFOLLOW`); the opened file must be a regular file with a single name (a hard link to a
/// file elsewhere is refused).
pub fn append_file(path: &Path) -> io::Result<File> {
    let file = OpenOptions::new()
        .create(true)
        .append(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| if e.raw_os_error() == Some(libc::ELOOP) { refused(path, "a symbolic link") } else { e })?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(refused(path, "not a regular file"));
    }
    if meta.nlink() > 1 {
        return Err(refused(path, "a file with another name (a hard link)"));
    }
    Ok(file)
}

/// Opens an existing regular file of the output folder for writing in place (to cut it or write
/// at an offset), with the same refusals as [`append_file`].
pub fn open_existing_file(path: &Path) -> io::Result<File> {
    let file = OpenOptions::new()
        .write(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| if e.raw_os_error() == Some(libc::ELOOP) { refused(path, "a symbolic link") } else { e })?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(refused(path, "not a regular file"));
    }
    if meta.nlink() > 1 {
        return Err(refused(path, "a file with another name (a hard link)"));
    }
    Ok(file)
}

/// Creates the folder `path` (and missing parents) for the program to fill; `path` itself must
/// end up a folder, not a symbolic link to one (its parents may be links: the user chose them).
pub fn create_dir(path: &Path) -> io::Result<()> {
    std::fs::create_dir_all(path)?;
    let meta = std::fs::symlink_metadata(path)?;
    if meta.file_type().is_symlink() {
        return Err(refused(path, "a symbolic link"));
    }
    if !meta.is_dir() {
        return Err(refused(path, "not a folder"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

    use super::*;
    use std::os::unix::fs::symlink;

    #[test]
    fn planted_links_are_never_written_through() {
        let dir = tempfile::tempdir().unwrap();
        let victim = dir.path().join("victim");
        std::fs::write(&victim, "precious").unwrap();
        let out = dir.path().join("out");
        std::fs::create_dir(&out).unwrap();
        let link = out.join("summary.json");
        symlink(&victim, &link).unwrap();
        let e = write_file(&link, b"new").unwrap_err();
        assert!(e.to_string().contains("symbolic link"), "{e}");
        let e = create_file(&link).unwrap_err();
        assert!(e.to_string().contains("symbolic link"), "{e}");
        let e = append_file(&link).unwrap_err();
        assert!(e.to_string().contains("symbolic link"), "{e}");
        assert!(open_existing_file(&link).is_err());
        // A dangling link too (the target would be created).
        let dangling = out.join("run.mcap");
        symlink(dir.path().join("created"), &dangling).unwrap();
        assert!(create_file(&dangling).is_err() && write_file(&dangling, b"x").is_err());
        assert!(!dir.path().join("created").exists());
        // A hard link: replaced (create, write) or refused (append), never written into.
        let hard = out.join("trials.csv");
        std::fs::hard_link(&victim, &hard).unwrap();
        assert!(append_file(&hard).is_err());
        create_file(&hard).unwrap().write_all(b"new").unwrap();
        std::fs::remove_file(&hard).unwrap();
        std::fs::hard_link(&victim, &hard).unwrap();
        write_file(&hard, b"new").unwrap();
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
        // A planted folder link.
        let plots = out.join("plots");
        symlink(dir.path(), &plots).unwrap();
        assert!(create_dir(&plots).unwrap_err().to_string().contains("symbolic link"));
    }

    #[test]
    fn regular_files_are_replaced_whole_and_temporaries_cleaned() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("a.json");
        write_file(&f, b"first, longer").unwrap();
        write_file(&f, b"second").unwrap();
        assert_eq!(std::fs::read_to_string(&f).unwrap(), "second");
        create_file(&f).unwrap().write_all(b"third").unwrap();
        assert_eq!(std::fs::read_to_string(&f).unwrap(), "third");
        append_file(&f).unwrap().write_all(b"+").unwrap();
        assert_eq!(std::fs::read_to_string(&f).unwrap(), "third+");
        // Readable as a plainly created file is (the umask decides), not only by its owner.
        let plain = dir.path().join("plain");
        std::fs::write(&plain, b"").unwrap();
        let mode = |p: &Path| std::os::unix::fs::PermissionsExt::mode(&std::fs::metadata(p).unwrap().permissions());
        assert_eq!(mode(&f), mode(&plain));
        std::fs::remove_file(&plain).unwrap();
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 1, "{names:?}");
        create_dir(&dir.path().join("x/y")).unwrap();
        create_dir(&dir.path().join("x/y")).unwrap();
    }
}
