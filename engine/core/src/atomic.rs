//! Atomic file writes: write a temporary sibling file, then rename it over the target.
//!
//! A run killed mid-write leaves at most a stray temporary file, never a truncated output.
//! (No fsync: this guards against a killed process, not against power loss.)

use std::ffi::OsString;
use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path` via `<path>.tmp` and a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let tmp = tmp_sibling(path, None)?;
    let written = fs::File::create(&tmp).and_then(|mut f| f.write_all(bytes));
    finish(written, &tmp, path)
}

/// Calls `write` with a temporary sibling path that keeps the extension
/// (`<stem>.tmp.<ext>`, for encoders that pick the format from it), then renames it onto `path`.
/// The temporary file is removed if `write` or the rename fails.
pub fn write_atomic_with<E, F>(path: &Path, write: F) -> Result<(), E>
where
    E: From<io::Error>,
    F: FnOnce(&Path) -> Result<(), E>,
{
    let ext = path.extension().map(|e| e.to_os_string());
    let tmp = tmp_sibling(path, ext)?;
    match write(&tmp) {
        Ok(()) => finish(Ok(()), &tmp, path).map_err(E::from),
        Err(e) => {
            let _ = fs::remove_file(&tmp);
            Err(e)
        }
    }
}

/// `dir/name` -> `dir/name.tmp`, or `dir/stem.tmp.ext` when `ext` is given.
fn tmp_sibling(path: &Path, ext: Option<OsString>) -> io::Result<PathBuf> {
    let name = path.file_name().ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("not a file path: {}", path.display()),
        )
    })?;
    let mut tmp_name = match (&ext, path.file_stem()) {
        (Some(_), Some(stem)) => stem.to_os_string(),
        _ => name.to_os_string(),
    };
    tmp_name.push(".tmp");
    if let Some(ext) = ext {
        tmp_name.push(".");
        tmp_name.push(ext);
    }
    Ok(path.with_file_name(tmp_name))
}

fn finish(written: io::Result<()>, tmp: &Path, path: &Path) -> io::Result<()> {
    let result = written.and_then(|()| fs::rename(tmp, path));
    if result.is_err() {
        let _ = fs::remove_file(tmp);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!(
            "sph_core_atomic_{name}_{}_{:?}",
            std::process::id(),
            std::thread::current().id()
        ));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn writes_and_replaces_without_leftovers() {
        let dir = test_dir("replace");
        let p = dir.join("a.txt");
        write_atomic(&p, b"first").unwrap();
        write_atomic(&p, b"second").unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"second");
        let names: Vec<_> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![OsString::from("a.txt")]);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn tmp_names() {
        let p = Path::new("/x/frame.vtp");
        assert_eq!(tmp_sibling(p, None).unwrap(), Path::new("/x/frame.vtp.tmp"));
        let ext = p.extension().map(|e| e.to_os_string());
        assert_eq!(tmp_sibling(p, ext).unwrap(), Path::new("/x/frame.tmp.vtp"));
        assert!(tmp_sibling(Path::new("/"), None).is_err());
    }

    #[test]
    fn failed_writer_leaves_nothing() {
        let dir = test_dir("fail");
        let p = dir.join("b.png");
        let r: io::Result<()> = write_atomic_with(&p, |tmp| {
            fs::write(tmp, b"partial")?;
            Err(io::Error::other("boom"))
        });
        assert!(r.is_err());
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 0);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_folder_is_an_error() {
        let p = std::env::temp_dir().join("sph_core_no_such_dir_xyz/c.txt");
        assert!(write_atomic(&p, b"x").is_err());
    }
}
