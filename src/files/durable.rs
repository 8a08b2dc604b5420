//! Durable file writes: a file is replaced whole or not at all, so a crash
//! or power loss mid-write never leaves a half-written map behind.

#[cfg(test)]
use std::fs;
use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path` atomically: a temporary file in the same
/// directory, flushed to disk, renamed over the target, and the directory
/// entry flushed too (the rename is durable only then). On failure the
/// previous file at `path`, if any, is untouched.
///
/// The temporary file has an unpredictable name and is created
/// exclusively (`O_EXCL`), so a link planted in the directory is never
/// followed: it makes the creation fail, or is simply not the name
/// chosen, and no file elsewhere is written or truncated.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> io::Result<()> {
    write_atomically_with(path, |f| f.write_all(bytes))
}

/// [`write_atomically`] of what `write` writes to the temporary file, so
/// a large file streams to disk instead of being built in memory first.
pub fn write_atomically_with(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "the path names no file"))?;
    let mut prefix = std::ffi::OsString::from(".");
    prefix.push(name);
    prefix.push(".tmp-");
    // Dropping the temporary file on an error path removes it.
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix);
    // Readable by others as a plainly created file would be (0666 less the
    // umask), not tempfile's private 0600: a map server or viewer under
    // another account reads these files.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder.tempfile_in(&dir)?;
    write(tmp.as_file_mut())?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    File::open(&dir).and_then(|d| d.sync_all())
}

/// Whether a file can be created in `dir`: one with no name, or an
/// unpredictable one removed at once, so nothing in `dir` is followed or
/// truncated.
pub fn check_writable(dir: &Path) -> io::Result<()> {
    let mut f = tempfile::tempfile_in(dir)?;
    f.write_all(b"clsmap")?;
    f.sync_all()
}

/// Largest configuration file read (bytes): 1 MiB, far above any real one.
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;
/// Largest map file read (bytes): 1 GiB (the CSAIL floor's is 4.2 MB).
pub const MAX_MAP_BYTES: u64 = 1 << 30;

/// The text of `path`, refused (`InvalidData`) beyond `max` bytes, so a
/// wrong path (`/dev/zero`, a huge log given as a config) fails at once
/// instead of filling memory.
pub fn read_bounded(path: &Path, max: u64) -> io::Result<String> {
    use std::io::Read as _;
    let mut text = String::new();
    File::open(path)?
        .take(max.saturating_add(1))
        .read_to_string(&mut text)?;
    if text.len() as u64 > max {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("larger than {max} bytes; not read"),
        ));
    }
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_the_file_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("clsmap-durable-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("map.json");
        write_atomically(&path, b"first").unwrap();
        write_atomically(&path, b"second").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"second");
        let names: Vec<_> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        fs::remove_dir_all(&dir).unwrap();
    }

    /// A link planted where the temporary file of the old, predictable
    /// scheme would go, and one at every name the directory listing
    /// suggests: the victim it points at is never touched.
    #[cfg(unix)]
    #[test]
    fn planted_links_are_never_followed() {
        let dir = std::env::temp_dir().join(format!("clsmap-durable-ln-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(dir.join("out")).unwrap();
        let victim = dir.join("victim");
        fs::write(&victim, b"keep").unwrap();
        let out = dir.join("out");
        for name in [
            format!(".map.json.tmp-{}", std::process::id()),
            ".map.json.tmp-".to_owned(),
            ".clsmap-write-test".to_owned(),
        ] {
            std::os::unix::fs::symlink(&victim, out.join(name)).unwrap();
        }
        let path = out.join("map.json");
        write_atomically(&path, b"map").unwrap();
        check_writable(&out).unwrap();
        assert_eq!(fs::read(&victim).unwrap(), b"keep");
        assert_eq!(fs::read(&path).unwrap(), b"map");
        assert!(
            !fs::symlink_metadata(&path)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        // Nothing left behind but the map and the planted links.
        assert_eq!(fs::read_dir(&out).unwrap().count(), 4);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn reads_are_bounded() {
        let e = read_bounded(Path::new("/dev/zero"), 1000).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData, "{e}");
        let dir = std::env::temp_dir().join(format!("clsmap-bounded-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("small");
        fs::write(&path, "x = 1\n").unwrap();
        assert_eq!(read_bounded(&path, 6).unwrap(), "x = 1\n");
        assert!(read_bounded(&path, 5).is_err());
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_failed_write_keeps_the_old_file() {
        let dir = std::env::temp_dir().join(format!("clsmap-durable-ro-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("map.json");
        write_atomically(&path, b"good").unwrap();
        // A directory in the way of the rename makes it fail.
        let blocked = dir.join("blocked");
        fs::create_dir_all(blocked.join("inner")).unwrap();
        assert!(write_atomically(&blocked, b"new").is_err());
        assert_eq!(fs::read(&path).unwrap(), b"good");
        fs::remove_dir_all(&dir).unwrap();
    }
}
