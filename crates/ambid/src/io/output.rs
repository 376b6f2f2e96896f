//! Atomic output: files are written into a temporary directory beside the destination and
//! renamed into place only when everything succeeded, so a failure never leaves a half-written
//! result; an existing destination is replaced only when asked (`--force`).

use std::path::{Path, PathBuf};

/// Why outputs could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The destination exists and `force` was not given.
    #[error("{0} already exists: choose another --out directory, or pass --force to replace it")]
    Exists(PathBuf),
    /// The file system refused.
    #[error("{path}: {reason}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The operating system's reason.
        reason: String,
    },
    /// A relative file name that leaves the output directory.
    #[error("`{0}` is not a relative path inside the output directory")]
    BadName(String),
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> OutputError + '_ {
    move |e| OutputError::Io {
        path: path.to_path_buf(),
        reason: e.to_string(),
    }
}

/// An output directory being written (see the module docs).
#[derive(Debug)]
pub struct OutputDir {
    dest: PathBuf,
    tmp: PathBuf,
    force: bool,
    written: Vec<PathBuf>,
    committed: bool,
}

impl OutputDir {
    /// Checks that `dest` may be written (absent, or `force`), without creating anything.
    ///
    /// # Errors
    /// [`OutputError::Exists`].
    pub fn check(dest: &Path, force: bool) -> Result<(), OutputError> {
        if dest.exists() && !force {
            return Err(OutputError::Exists(dest.to_path_buf()));
        }
        Ok(())
    }

    /// Starts writing into `dest` (through a temporary sibling directory).
    ///
    /// # Errors
    /// [`OutputError::Exists`] without `force`, or the file system's errors.
    pub fn create(dest: &Path, force: bool) -> Result<Self, OutputError> {
        Self::check(dest, force)?;
        let parent = match dest.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(io(&parent))?;
        let stem = dest
            .file_name()
            .map_or("out".into(), |s| s.to_string_lossy().into_owned());
        let tmp = parent.join(format!(".{stem}.tmp-{}", std::process::id()));
        if tmp.exists() {
            std::fs::remove_dir_all(&tmp).map_err(io(&tmp))?;
        }
        std::fs::create_dir_all(&tmp).map_err(io(&tmp))?;
        Ok(Self {
            dest: dest.to_path_buf(),
            tmp,
            force,
            written: Vec::new(),
            committed: false,
        })
    }

    /// Writes one file (`name` relative, `/`-separated subdirectories allowed).
    ///
    /// # Errors
    /// A name that leaves the directory, or the file system's errors.
    pub fn write(&self, name: &str, bytes: &[u8]) -> Result<(), OutputError> {
        let rel = Path::new(name);
        if rel.is_absolute()
            || rel
                .components()
                .any(|c| !matches!(c, std::path::Component::Normal(_)))
        {
            return Err(OutputError::BadName(name.into()));
        }
        let path = self.tmp.join(rel);
        if let Some(d) = path.parent() {
            std::fs::create_dir_all(d).map_err(io(d))?;
        }
        std::fs::write(&path, bytes).map_err(io(&path))
    }

    /// Moves the finished directory into place; returns the files written.
    ///
    /// # Errors
    /// The destination appeared meanwhile (without `force`), or the file system's errors.
    pub fn commit(mut self) -> Result<Vec<PathBuf>, OutputError> {
        let mut old = None;
        if self.dest.exists() {
            if !self.force {
                return Err(OutputError::Exists(self.dest.clone()));
            }
            let aside = self.tmp.with_extension("old");
            std::fs::rename(&self.dest, &aside).map_err(io(&self.dest))?;
            old = Some(aside);
        }
        if let Err(e) = std::fs::rename(&self.tmp, &self.dest) {
            if let Some(a) = &old {
                // put the user's previous result back
                let _ = std::fs::rename(a, &self.dest);
            }
            return Err(io(&self.dest)(e));
        }
        self.committed = true;
        if let Some(a) = old {
            std::fs::remove_dir_all(&a)
                .or_else(|_| std::fs::remove_file(&a))
                .map_err(io(&a))?;
        }
        self.written = list(&self.dest);
        Ok(std::mem::take(&mut self.written))
    }
}

fn list(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(list(&p));
            } else {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.tmp);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ambid-out-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn a_dropped_output_leaves_nothing_and_a_committed_one_has_every_file() {
        let root = tmp("drop");
        let dest = root.join("result");
        {
            let o = OutputDir::create(&dest, false).unwrap();
            o.write("a/b.txt", b"x").unwrap();
        }
        assert!(!dest.exists());
        assert_eq!(std::fs::read_dir(&root).unwrap().count(), 0);
        let o = OutputDir::create(&dest, false).unwrap();
        o.write("a/b.txt", b"x").unwrap();
        o.write("c.txt", b"y").unwrap();
        let files = o.commit().unwrap();
        assert_eq!(files.len(), 2);
        assert_eq!(std::fs::read(dest.join("c.txt")).unwrap(), b"y");
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn an_existing_destination_needs_force_and_is_then_replaced_whole() {
        let root = tmp("force");
        let dest = root.join("result");
        std::fs::create_dir_all(&dest).unwrap();
        std::fs::write(dest.join("mine.txt"), b"keep").unwrap();
        let e = OutputDir::create(&dest, false).unwrap_err();
        assert!(e.to_string().contains("--force"), "{e}");
        assert_eq!(std::fs::read(dest.join("mine.txt")).unwrap(), b"keep");
        let o = OutputDir::create(&dest, true).unwrap();
        o.write("new.txt", b"n").unwrap();
        o.commit().unwrap();
        assert!(!dest.join("mine.txt").exists());
        assert!(dest.join("new.txt").exists());
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn names_outside_the_directory_are_refused() {
        let root = tmp("names");
        let o = OutputDir::create(&root.join("r"), false).unwrap();
        for bad in ["../x", "/etc/x", "a/../../x"] {
            assert!(
                matches!(o.write(bad, b""), Err(OutputError::BadName(_))),
                "{bad}"
            );
        }
        drop(o);
        let _ = std::fs::remove_dir_all(&root);
    }
}
