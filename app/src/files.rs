//! Reading scene files a user opens: the file itself within the size limit, and its `Inline`
//! URLs confined to the scene's folder.
//!
//! A scene file may come from anyone (a download, a peer, a classroom share). Its `Inline`
//! URLs are paths the file's author chose, so an absolute path, a `..` or a symbolic link
//! could read any file of the user's. [`InlineResolver`] allows only files inside the root
//! it is given (the scene's folder unless the user names a wider one), checked on the
//! canonical path after links are followed.

use std::io::Read;
use std::path::{Component, Path, PathBuf};

use formats::fvrml::MAX_FILE_BYTES;

/// Reads a scene file as text, refusing one over [`MAX_FILE_BYTES`] before reading it.
pub fn read_scene_text(path: &Path) -> Result<String, String> {
    String::from_utf8(read_scene_bytes(path)?)
        .map_err(|_| format!("{}: not UTF-8 text", path.display()))
}

/// Reads a file a scene names (an `Inline`'s text, a grid's samples), refusing one over
/// [`MAX_FILE_BYTES`] before reading it.
pub fn read_scene_bytes(path: &Path) -> Result<Vec<u8>, String> {
    read_bounded(path, MAX_FILE_BYTES as u64)
}

/// Reads a regular file of at most `limit` bytes: anything else is an error that names the
/// path, found before reading and never by waiting.
///
/// A file a user or a scene names may be a FIFO, a device or a folder: opening a FIFO waits
/// for a writer and reading a device may never end, so the file is opened without blocking,
/// refused unless the opened file is a regular one (checked on the open file, so it cannot
/// be swapped after the check), and read through a bound in case it grows while being read.
pub fn read_bounded(path: &Path, limit: u64) -> Result<Vec<u8>, String> {
    let fail = |why: String| format!("{}: {why}", path.display());
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::custom_flags(&mut options, libc::O_NONBLOCK);
    let file = options.open(path).map_err(|e| fail(e.to_string()))?;
    let metadata = file.metadata().map_err(|e| fail(e.to_string()))?;
    if !metadata.is_file() {
        let kind = if metadata.is_dir() {
            "a folder"
        } else {
            "a FIFO, socket or device"
        };
        return Err(fail(format!("{kind}, not a regular file")));
    }
    let too_large = |len: u64| fail(format!("{len} bytes, more than the limit of {limit}"));
    if metadata.len() > limit {
        return Err(too_large(metadata.len()));
    }
    let mut bytes = Vec::with_capacity(metadata.len() as usize);
    file.take(limit + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| fail(e.to_string()))?;
    if bytes.len() as u64 > limit {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// Resolves and reads `Inline` URLs relative to a scene's folder, only inside `root`.
pub struct InlineResolver {
    base: PathBuf,
    root: PathBuf,
}

impl InlineResolver {
    /// URLs are relative to `base` (the scene's folder) and must stay inside `root` (the
    /// same folder, unless the user allowed a wider one).
    pub fn new(base: &Path, root: &Path) -> Result<Self, String> {
        let canonical = |p: &Path| {
            let p = if p.as_os_str().is_empty() {
                Path::new(".")
            } else {
                p
            };
            p.canonicalize()
                .map_err(|e| format!("{}: {e}", p.display()))
        };
        Ok(Self {
            base: canonical(base)?,
            root: canonical(root)?,
        })
    }

    /// The file an `Inline` URL names, if it is allowed.
    pub fn path(&self, url: &str) -> Result<PathBuf, String> {
        let url = url.strip_prefix("file://").unwrap_or(url);
        let relative = Path::new(url);
        if url.contains("://") {
            return Err(format!("Inline \"{url}\": only local files can be inlined"));
        }
        let path = self
            .base
            .join(relative)
            .canonicalize()
            .map_err(|e| format!("Inline \"{url}\": {e}"))?;
        if path.starts_with(&self.root) {
            return Ok(path);
        }
        let how = if relative.is_absolute() {
            "is an absolute path"
        } else if relative.components().any(|c| c == Component::ParentDir) {
            "leaves the scene's folder through `..`"
        } else {
            "leads outside through a link"
        };
        Err(format!(
            "Inline \"{url}\" {how} (to {}), outside {}: a scene may read only files there; \
             allow a wider folder with --inline-root DIR",
            path.display(),
            self.root.display()
        ))
    }

    /// Reads the file an `Inline` or grid URL names (see [`InlineResolver::path`]).
    pub fn read(&self, url: &str) -> Result<Vec<u8>, String> {
        read_scene_bytes(&self.path(url)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `read` on another thread and fails, instead of hanging, if it does not answer
    /// within a few seconds.
    fn answers_in_time<T: Send + 'static>(read: impl FnOnce() -> T + Send + 'static) -> T {
        let (send, receive) = std::sync::mpsc::channel();
        std::thread::Builder::new()
            .name("read-under-test".into())
            .spawn(move || send.send(read()))
            .unwrap();
        receive
            .recv_timeout(std::time::Duration::from_secs(5))
            .expect("the read answers instead of waiting")
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_a_device_or_a_folder_is_refused_without_waiting() {
        let dir = std::env::temp_dir().join(format!("sculpt-fifo-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let fifo = dir.join("part.wrl");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success(), "mkfifo");
        let path = fifo.clone();
        let why = answers_in_time(move || read_scene_bytes(&path)).unwrap_err();
        assert!(why.contains("not a regular file"), "{why}");
        assert!(why.contains("part.wrl"), "names the file: {why}");
        let why = answers_in_time(|| read_bounded(Path::new("/dev/zero"), 1 << 20)).unwrap_err();
        assert!(why.contains("not a regular file"), "{why}");
        let folder = dir.clone();
        let why = answers_in_time(move || read_scene_text(&folder)).unwrap_err();
        assert!(why.contains("a folder"), "{why}");
        // An Inline naming the FIFO inside the scene's folder is refused the same way.
        let resolver = InlineResolver::new(&dir, &dir).unwrap();
        let why = answers_in_time(move || resolver.read("part.wrl")).unwrap_err();
        assert!(why.contains("not a regular file"), "{why}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_file_over_the_limit_is_refused_and_one_at_it_is_read() {
        let dir = std::env::temp_dir().join(format!("sculpt-bound-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("grid.raw");
        std::fs::write(&path, [7u8; 100]).unwrap();
        assert_eq!(read_bounded(&path, 100).unwrap().len(), 100);
        let why = read_bounded(&path, 99).unwrap_err();
        assert!(
            why.contains("100 bytes, more than the limit of 99"),
            "{why}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn inlines_stay_inside_the_scene_folder_unless_allowed() {
        let dir = std::env::temp_dir().join(format!("sculpt-files-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let scenes = dir.join("scenes");
        std::fs::create_dir_all(scenes.join("parts")).unwrap();
        std::fs::write(scenes.join("parts/wheel.wrl"), "#VRML V2.0 utf8\n").unwrap();
        std::fs::write(dir.join("secret.txt"), "password").unwrap();
        let r = InlineResolver::new(&scenes, &scenes).unwrap();
        assert!(r.read("parts/wheel.wrl").is_ok());
        assert!(r.read("file://parts/wheel.wrl").is_ok());
        let outside = dir.join("secret.txt");
        let absolute = r.read(outside.to_str().unwrap()).unwrap_err();
        assert!(absolute.contains("absolute"), "{absolute}");
        assert!(r.read("../secret.txt").unwrap_err().contains(".."));
        assert!(r.read("parts/../../secret.txt").is_err());
        assert!(
            r.read("parts/../parts/wheel.wrl").is_ok(),
            "`..` that stays inside"
        );
        assert!(r.read("http://example.invalid/x.wrl").is_err());
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(&outside, scenes.join("link.wrl")).unwrap();
            let linked = r.read("link.wrl").unwrap_err();
            assert!(linked.contains("link"), "{linked}");
            let wide = InlineResolver::new(&scenes, &dir).unwrap();
            assert_eq!(wide.read("link.wrl").unwrap(), b"password");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
