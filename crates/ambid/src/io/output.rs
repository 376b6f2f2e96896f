//! Atomic output, one overwrite rule, nothing left behind.
//!
//! Every command writes its outputs as one set: each destination is checked first, every file
//! is written to a temporary sibling `.<name>.ambid-tmp-<pid>` beside its destination, and the
//! temporaries are renamed into place only when all of them were written. A failure (an error,
//! a full disk, a refused destination) removes the temporaries and any directory the set
//! created, so nothing half-written is left. [`OutputSet`] does this for files, [`OutputDir`] for
//! a whole directory (`ambid run --out DIR`).
//!
//! Rules, the same for every command:
//! - An existing destination is replaced only with `--force` ([`OutputError::Exists`] names the
//!   file and the option otherwise).
//! - A destination that is a special file (a character device or a FIFO such as `/dev/null`,
//!   `/dev/stdout`) is written in place, never replaced; it needs no `--force`. It is written
//!   when staged, before any regular file of the set is renamed into place, so a failure there
//!   (`/dev/full`) leaves no regular output either.
//! - Outputs are streamed into their temporaries ([`OutputSet::write_with`]): a long record is
//!   never held as text in memory.
//! - A directory that would be replaced with `--force` must not be `/`, the home directory, the
//!   current directory or one of its ancestors, nor contain an input file
//!   ([`OutputError::Dangerous`]): replacing a directory deletes it.
//! - Stale temporaries: a process killed while writing leaves its `.<name>.ambid-tmp-<pid>`
//!   (file or directory, and the `….old` copy of a replaced directory). The next write to the
//!   same destination removes every such entry whose process `<pid>` is no longer running
//!   (checked through `/proc/<pid>`; where `/proc` does not exist nothing is removed). Only names
//!   of exactly this pattern for that destination are touched (and the `.<name>.tmp-<pid>` of
//!   earlier ambid versions).
//!
//! Error messages name the destination and the operating system's reason, e.g.
//! `cannot write /dev/full: No space left on device (os error 28)`.

use std::path::{Path, PathBuf};

/// Why outputs could not be written (the exit code is 5, see docs/workflow.md).
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The destination exists and `force` was not given.
    #[error("{0} already exists: choose another output path, or pass --force to replace it")]
    Exists(PathBuf),
    /// The file system refused.
    #[error("cannot write {path}: {reason}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The operating system's reason.
        reason: String,
    },
    /// A relative file name that leaves the output directory.
    #[error("`{0}` is not a relative path inside the output directory")]
    BadName(String),
    /// A file destination that is a directory.
    #[error("{0} is a directory: give a file name as the output path")]
    IsDirectory(PathBuf),
    /// The same destination was given twice in one command.
    #[error(
        "{0} is given as two different outputs of this command: give each output its own path"
    )]
    Duplicate(PathBuf),
    /// Replacing this directory would delete something the user cannot want deleted.
    #[error(
        "refusing to replace {path} with --force: it is {why}, and replacing a directory deletes \
         it; choose a new output directory"
    )]
    Dangerous {
        /// The directory.
        path: PathBuf,
        /// Why (e.g. "the current directory").
        why: String,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> OutputError + '_ {
    move |e| OutputError::Io {
        path: path.to_path_buf(),
        reason: reason(&e, path),
    }
}

/// The operating system's reason, with what it means for the destination's directory.
fn reason(e: &std::io::Error, dest: &Path) -> String {
    const EROFS: i32 = 30;
    let dir = parent_of(dest);
    let unwritable = e.kind() == std::io::ErrorKind::PermissionDenied
        || e.raw_os_error() == Some(EROFS)
        || (e.kind() == std::io::ErrorKind::NotFound && dir.is_dir());
    if unwritable {
        format!("{} is not a writable directory ({e})", dir.display())
    } else if e.kind() == std::io::ErrorKind::NotFound {
        format!(
            "{} does not exist or is not a directory ({e})",
            dir.display()
        )
    } else {
        e.to_string()
    }
}

fn parent_of(dest: &Path) -> PathBuf {
    match dest.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

fn file_name(dest: &Path, fallback: &str) -> String {
    dest.file_name()
        .map_or(fallback.into(), |s| s.to_string_lossy().into_owned())
}

/// The temporary sibling of `dest` for this process: `.<name>.ambid-tmp-<pid>`.
fn temp_of(dest: &Path, fallback: &str) -> PathBuf {
    parent_of(dest).join(format!(
        ".{}{TEMP_TAG}{}",
        file_name(dest, fallback),
        std::process::id()
    ))
}

/// What separates a destination's name from the writer's process id in a temporary name.
const TEMP_TAG: &str = ".ambid-tmp-";
/// The same for temporaries of ambid versions before the rule above (directories only).
const LEGACY_TEMP_TAG: &str = ".tmp-";

/// The process id in `entry` if it is a temporary of the destination called `name`
/// (`.<name>.ambid-tmp-<pid>` or `….old`, or the legacy `.<name>.tmp-<pid>[.old]`).
fn temp_pid(entry: &str, name: &str) -> Option<u32> {
    let rest = entry.strip_prefix('.')?.strip_prefix(name)?;
    let rest = rest
        .strip_prefix(TEMP_TAG)
        .or_else(|| rest.strip_prefix(LEGACY_TEMP_TAG))?;
    let digits = rest.strip_suffix(".old").unwrap_or(rest);
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

/// Removes the temporaries of `dest` left by processes that are no longer running (see the
/// module docs). Returns the entries removed. Best effort: an entry that cannot be removed is
/// left and reported by the next write that needs its name.
pub fn clean_stale_temps(dest: &Path) -> Vec<PathBuf> {
    let proc_root = Path::new("/proc");
    if !proc_root.join("self").exists() {
        return Vec::new();
    }
    let dir = parent_of(dest);
    let name = file_name(dest, "out");
    let me = std::process::id();
    let mut removed = Vec::new();
    let Ok(rd) = std::fs::read_dir(&dir) else {
        return removed;
    };
    for e in rd.flatten() {
        let entry = e.file_name().to_string_lossy().into_owned();
        let Some(pid) = temp_pid(&entry, &name) else {
            continue;
        };
        if pid == me || proc_root.join(pid.to_string()).exists() {
            continue;
        }
        let p = e.path();
        let gone = match std::fs::symlink_metadata(&p) {
            Ok(m) if m.is_dir() => std::fs::remove_dir_all(&p).is_ok(),
            Ok(_) => std::fs::remove_file(&p).is_ok(),
            Err(_) => false,
        };
        if gone {
            removed.push(p);
        }
    }
    removed
}

/// Creates `dir` and its missing ancestors; returns the topmost directory created (to remove
/// on failure), if any.
fn create_dirs(dir: &Path) -> Result<Option<PathBuf>, OutputError> {
    if dir.is_dir() {
        return Ok(None);
    }
    let mut top = dir.to_path_buf();
    while let Some(p) = top.parent() {
        if p.as_os_str().is_empty() || p.exists() {
            break;
        }
        top = p.to_path_buf();
    }
    std::fs::create_dir_all(dir).map_err(|e| OutputError::Io {
        path: dir.to_path_buf(),
        reason: format!("cannot create the directory: {}", reason(&e, dir)),
    })?;
    Ok(Some(top))
}

fn is_special(m: &std::fs::Metadata) -> bool {
    !m.is_file() && !m.is_dir()
}

/// Refuses to replace (delete) `dest` when it is `/`, the home directory, the current directory
/// or an ancestor of it, or contains one of `inputs`.
///
/// # Errors
/// [`OutputError::Dangerous`] naming the directory and the reason.
pub fn check_replaceable(dest: &Path, inputs: &[&Path]) -> Result<(), OutputError> {
    let Ok(d) = dest.canonicalize() else {
        return Ok(()); // nothing there to delete
    };
    let refuse = |why: String| {
        Err(OutputError::Dangerous {
            path: dest.to_path_buf(),
            why,
        })
    };
    if d.parent().is_none() {
        return refuse("the root directory".into());
    }
    if let Some(home) = std::env::var_os("HOME").and_then(|h| PathBuf::from(h).canonicalize().ok())
    {
        if home == d {
            return refuse("the home directory".into());
        }
    }
    if let Ok(cwd) = std::env::current_dir().and_then(|c| c.canonicalize()) {
        if cwd == d {
            return refuse("the current directory".into());
        }
        if cwd.starts_with(&d) {
            return refuse(format!(
                "an ancestor of the current directory {}",
                cwd.display()
            ));
        }
    }
    for i in inputs {
        if let Ok(c) = i.canonicalize() {
            if c.starts_with(&d) {
                return refuse(format!("the directory of the input file {}", i.display()));
            }
        }
    }
    Ok(())
}

/// One staged file of an [`OutputSet`].
#[derive(Debug)]
struct Staged {
    dest: PathBuf,
    /// The temporary sibling, or `None` for a special file (already written in place).
    tmp: Option<PathBuf>,
}

/// A set of output files written atomically (see the module docs): [`write`](Self::write)
/// stages each file in a temporary beside its destination, [`commit`](Self::commit) renames
/// them all into place; dropping an uncommitted set removes every temporary and every directory
/// it created.
///
/// ```
/// use ambid::io::output::OutputSet;
/// let dir = std::env::temp_dir().join(format!("ambid-doc-set-{}", std::process::id()));
/// let mut set = OutputSet::new(false);
/// set.write(&dir.join("a.csv"), b"x\n1\n")?;
/// set.write(&dir.join("b.json"), b"{}")?;
/// assert!(!dir.join("a.csv").exists()); // nothing visible before the commit
/// let files = set.commit()?;
/// assert_eq!(files.len(), 2);
/// assert_eq!(std::fs::read(dir.join("a.csv"))?, b"x\n1\n");
/// // a second set to the same file needs `force`
/// assert!(OutputSet::new(false).write(&dir.join("a.csv"), b"y").is_err());
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug)]
pub struct OutputSet {
    force: bool,
    staged: Vec<Staged>,
    created: Vec<PathBuf>,
    committed: bool,
}

impl OutputSet {
    /// An empty set; `force` allows replacing existing files.
    pub fn new(force: bool) -> Self {
        Self {
            force,
            staged: Vec::new(),
            created: Vec::new(),
            committed: false,
        }
    }

    /// Checks that `dest` may be written as a file: absent, a special file (device, FIFO), or
    /// a regular file with `force`; never a directory. Creates nothing.
    ///
    /// # Errors
    /// [`OutputError::Exists`] or [`OutputError::IsDirectory`].
    pub fn check(dest: &Path, force: bool) -> Result<(), OutputError> {
        match std::fs::metadata(dest) {
            Ok(m) if m.is_dir() => Err(OutputError::IsDirectory(dest.to_path_buf())),
            Ok(m) if m.is_file() && !force => Err(OutputError::Exists(dest.to_path_buf())),
            _ => Ok(()),
        }
    }

    /// Stages `bytes` for `dest` (see the type docs). Stale temporaries of `dest` are removed.
    ///
    /// # Errors
    /// [`OutputError::Exists`] without `force`, [`OutputError::IsDirectory`],
    /// [`OutputError::Duplicate`], or the file system's errors naming `dest`.
    pub fn write(&mut self, dest: &Path, bytes: &[u8]) -> Result<(), OutputError> {
        self.write_with(dest, |w| w.write_all(bytes))
    }

    /// Stages the file `dest` whose bytes `fill` writes (streamed to the temporary through a
    /// buffer: large outputs are never held in memory). A special file (device, FIFO) is
    /// written in place at once. Errors as [`write`](Self::write).
    ///
    /// # Errors
    /// As [`write`](Self::write); an error returned by `fill` names `dest`.
    pub fn write_with<F>(&mut self, dest: &Path, fill: F) -> Result<(), OutputError>
    where
        F: FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>,
    {
        Self::check(dest, self.force)?;
        if self.staged.iter().any(|s| same_path(&s.dest, dest)) {
            return Err(OutputError::Duplicate(dest.to_path_buf()));
        }
        if std::fs::metadata(dest).is_ok_and(|m| is_special(&m)) {
            self.staged.push(Staged {
                dest: dest.to_path_buf(),
                tmp: None,
            });
            let f = std::fs::OpenOptions::new()
                .write(true)
                .open(dest)
                .map_err(io(dest))?;
            return stream(f, fill, false).map_err(io(dest));
        }
        if let Some(top) = create_dirs(&parent_of(dest))? {
            self.created.push(top);
        }
        clean_stale_temps(dest);
        let tmp = temp_of(dest, "out");
        // register before writing, so that a failed write is cleaned up too
        self.staged.push(Staged {
            dest: dest.to_path_buf(),
            tmp: Some(tmp.clone()),
        });
        let f = std::fs::File::create(&tmp).map_err(io(dest))?;
        stream(f, fill, true).map_err(io(dest))
    }

    /// Renames every staged file into place; returns the destinations.
    ///
    /// # Errors
    /// A destination that appeared meanwhile (without `force`): then nothing of the set is
    /// left (special files excepted). A rename the file system refuses (it renames within one
    /// directory, so only a concurrent change of that directory can cause it) is named with
    /// its destination; the files renamed before it stay, the others are removed.
    pub fn commit(mut self) -> Result<Vec<PathBuf>, OutputError> {
        for s in &self.staged {
            if s.tmp.is_some() {
                Self::check(&s.dest, self.force)?;
            }
        }
        let mut done = Vec::new();
        for s in &self.staged {
            if let Some(t) = &s.tmp {
                std::fs::rename(t, &s.dest).map_err(io(&s.dest))?;
            }
            done.push(s.dest.clone());
        }
        self.committed = true;
        Ok(done)
    }
}

/// Writes one file as a set of one (see [`OutputSet`]); returns `dest`.
///
/// # Errors
/// As [`OutputSet::write`] and [`OutputSet::commit`].
pub fn write_file(dest: &Path, bytes: &[u8], force: bool) -> Result<PathBuf, OutputError> {
    let mut set = OutputSet::new(force);
    set.write(dest, bytes)?;
    set.commit()?;
    Ok(dest.to_path_buf())
}

/// Whether two destinations name the same file (`x.csv` and `./x.csv`, through symbolic links
/// of their directories), whether or not the file exists yet.
fn same_path(a: &Path, b: &Path) -> bool {
    fn norm(p: &Path) -> PathBuf {
        if let Ok(c) = p.canonicalize() {
            return c;
        }
        match (parent_of(p).canonicalize(), p.file_name()) {
            (Ok(d), Some(n)) => d.join(n),
            _ => p.to_path_buf(),
        }
    }
    a == b || norm(a) == norm(b)
}

fn write_new(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    let mut f = std::fs::File::create(path)?;
    f.write_all(bytes)?;
    f.sync_all()
}

/// Streams `fill` into `f` through a buffer; `sync` flushes to the disk as well (regular files,
/// before their rename).
fn stream<F>(f: std::fs::File, fill: F, sync: bool) -> std::io::Result<()>
where
    F: FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>,
{
    use std::io::Write;
    let mut w = std::io::BufWriter::with_capacity(1 << 16, f);
    fill(&mut w)?;
    w.flush()?;
    if sync {
        w.get_ref().sync_all()?;
    }
    Ok(())
}

impl Drop for OutputSet {
    fn drop(&mut self) {
        if self.committed {
            return;
        }
        for s in &self.staged {
            if let Some(t) = &s.tmp {
                let _ = std::fs::remove_file(t);
            }
        }
        for d in self.created.iter().rev() {
            // only what this set created, and only if nothing else appeared in it
            let _ = remove_empty_dirs(d);
        }
    }
}

fn remove_empty_dirs(d: &Path) -> std::io::Result<()> {
    for e in std::fs::read_dir(d)?.flatten() {
        if e.file_type()?.is_dir() {
            remove_empty_dirs(&e.path())?;
        }
    }
    std::fs::remove_dir(d)
}

/// An output directory being written (see the module docs).
#[derive(Debug)]
pub struct OutputDir {
    dest: PathBuf,
    tmp: PathBuf,
    force: bool,
    written: Vec<PathBuf>,
    created: Option<PathBuf>,
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

    /// [`check`](Self::check), and with `force` also [`check_replaceable`] against `inputs`:
    /// the check to make before any work.
    ///
    /// # Errors
    /// [`OutputError::Exists`] or [`OutputError::Dangerous`].
    pub fn check_with_inputs(
        dest: &Path,
        force: bool,
        inputs: &[&Path],
    ) -> Result<(), OutputError> {
        Self::check(dest, force)?;
        if dest.exists() {
            if !dest.is_dir() {
                return Err(OutputError::Io {
                    path: dest.to_path_buf(),
                    reason: "it exists and is not a directory; give a directory path".into(),
                });
            }
            check_replaceable(dest, inputs)?;
        }
        Ok(())
    }

    /// Starts writing into `dest` (through a temporary sibling directory
    /// `.<name>.ambid-tmp-<pid>`; stale ones of `dest` are removed first).
    ///
    /// # Errors
    /// [`OutputError::Exists`] without `force`, [`OutputError::Dangerous`], or the file
    /// system's errors.
    pub fn create(dest: &Path, force: bool) -> Result<Self, OutputError> {
        Self::check_with_inputs(dest, force, &[])?;
        let parent = parent_of(dest);
        let created = create_dirs(&parent)?;
        clean_stale_temps(dest);
        let tmp = temp_of(dest, "out");
        let made = (|| {
            if tmp.exists() {
                std::fs::remove_dir_all(&tmp).map_err(io(&tmp))?;
            }
            std::fs::create_dir(&tmp).map_err(io(dest))
        })();
        if let Err(e) = made {
            if let Some(c) = &created {
                let _ = remove_empty_dirs(c);
            }
            return Err(e);
        }
        Ok(Self {
            dest: dest.to_path_buf(),
            tmp,
            force,
            written: Vec::new(),
            created,
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
        let shown = self.dest.join(rel);
        if let Some(d) = path.parent() {
            std::fs::create_dir_all(d).map_err(io(&shown))?;
        }
        write_new(&path, bytes).map_err(io(&shown))
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
            check_replaceable(&self.dest, &[])?;
            let aside = self
                .tmp
                .with_file_name(format!("{}.old", file_name(&self.tmp, "out")));
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
            if let Some(c) = &self.created {
                let _ = remove_empty_dirs(c);
            }
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
        // the parent directory the output created is removed too: nothing is left
        assert!(!root.exists());
        // and in an existing parent, nothing but what was there
        std::fs::create_dir_all(&root).unwrap();
        {
            let o = OutputDir::create(&dest, false).unwrap();
            o.write("a/b.txt", b"x").unwrap();
        }
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

    #[test]
    fn a_set_with_a_failing_member_leaves_nothing() {
        let root = tmp("set");
        std::fs::create_dir_all(&root).unwrap();
        let mut set = OutputSet::new(false);
        set.write(&root.join("new/a.csv"), b"a").unwrap();
        // a file where a directory is needed
        std::fs::write(root.join("f"), b"").unwrap();
        assert!(set.write(&root.join("f/b.csv"), b"b").is_err());
        drop(set);
        let left: Vec<_> = std::fs::read_dir(&root)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(left, vec![std::ffi::OsString::from("f")]);
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn temp_names_are_recognised_exactly() {
        assert_eq!(temp_pid(".r.csv.ambid-tmp-123", "r.csv"), Some(123));
        assert_eq!(temp_pid(".rep.ambid-tmp-9.old", "rep"), Some(9));
        assert_eq!(temp_pid(".rep.tmp-77", "rep"), Some(77));
        for no in [
            ".rep.ambid-tmp-",
            ".rep.ambid-tmp-12x",
            "rep.ambid-tmp-12",
            ".rep2.ambid-tmp-12",
            ".rep.ambid-tmp-1.old.old",
        ] {
            assert_eq!(temp_pid(no, "rep"), None, "{no}");
        }
    }
}
