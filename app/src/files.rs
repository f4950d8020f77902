//! Reading scene files a user opens: the file itself within the size limit, and its `Inline`
//! URLs confined to the scene's folder.
//!
//! A scene file may come from anyone (a download, a peer, a classroom share). Its `Inline`
//! URLs are paths the file's author chose, so an absolute path, a `..` or a symbolic link
//! could read any file of the user's. [`InlineResolver`] allows only files inside the root
//! it is given (the scene's folder unless the user names a wider one), checked on the
//! canonical path after links are followed.

use std::path::{Component, Path, PathBuf};

use fdsl::fvrml::MAX_FILE_BYTES;

/// Reads a scene file as text, refusing one over [`MAX_FILE_BYTES`] before reading it.
pub fn read_scene_text(path: &Path) -> Result<String, String> {
    String::from_utf8(read_scene_bytes(path)?)
        .map_err(|_| format!("{}: not UTF-8 text", path.display()))
}

/// Reads a file a scene names (an `Inline`'s text, a grid's samples), refusing one over
/// [`MAX_FILE_BYTES`] before reading it.
pub fn read_scene_bytes(path: &Path) -> Result<Vec<u8>, String> {
    let len = std::fs::metadata(path)
        .map_err(|e| format!("{}: {e}", path.display()))?
        .len();
    if len > MAX_FILE_BYTES as u64 {
        return Err(format!(
            "{}: {len} bytes, more than the limit of {MAX_FILE_BYTES}",
            path.display()
        ));
    }
    std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))
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
