//! Where the program keeps its files: the data directory, and the session stores in it.
//!
//! The window, the `sessions` subcommand and the settings all start from [`data_dir`]; a
//! session the window switches to gets its store beside the current one ([`store_beside`]).

use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// The folder of the data directory that holds one store directory per session.
pub const SESSIONS_DIR: &str = "sessions";

/// The program's data directory: `$XDG_DATA_HOME/sculpt`, else `~/.local/share/sculpt`;
/// `None` when neither variable is set.
pub fn data_dir() -> Option<PathBuf> {
    data_dir_from(std::env::var_os("XDG_DATA_HOME"), std::env::var_os("HOME"))
}

/// [`data_dir`] from the values of `XDG_DATA_HOME` and `HOME` (an empty value counts as unset,
/// as the XDG specification says).
pub fn data_dir_from(xdg_data_home: Option<OsString>, home: Option<OsString>) -> Option<PathBuf> {
    let non_empty = |value: Option<OsString>| value.filter(|v| !v.is_empty());
    if let Some(data) = non_empty(xdg_data_home) {
        return Some(PathBuf::from(data).join("sculpt"));
    }
    non_empty(home).map(|home| PathBuf::from(home).join(".local/share/sculpt"))
}

/// The store directory named `dir_name` beside `store` (in the same parent; in the current
/// directory when `store` has no parent).
pub fn store_beside(store: &Path, dir_name: &str) -> PathBuf {
    store
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
        .join(dir_name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_data_directory_follows_xdg_then_home() {
        let some = |s: &str| Some(OsString::from(s));
        assert_eq!(
            data_dir_from(some("/x"), some("/home/u")),
            Some(PathBuf::from("/x/sculpt"))
        );
        assert_eq!(
            data_dir_from(some(""), some("/home/u")),
            Some(PathBuf::from("/home/u/.local/share/sculpt")),
            "an empty XDG_DATA_HOME counts as unset"
        );
        assert_eq!(data_dir_from(None, some("")), None);
        assert_eq!(data_dir_from(None, None), None);
    }

    #[test]
    fn a_store_beside_another_shares_its_parent() {
        assert_eq!(
            store_beside(Path::new("/data/sessions/demo"), "joined-1"),
            PathBuf::from("/data/sessions/joined-1")
        );
        assert_eq!(store_beside(Path::new("demo"), "b"), PathBuf::from("b"));
        assert_eq!(store_beside(Path::new("/"), "b"), PathBuf::from("./b"));
    }
}
